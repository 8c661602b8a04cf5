// The analyser against the 50-digit reference on seeded random and adversarial configurations
// (issue 7, "Numbers at the edges"). Shared by tests/unit/stability/test_campaign.cpp (a short
// CI campaign) and bench/campaign_analyser.cpp (the long one with the report table).
//
// Expected values come only from the reference (reference.hpp), extended here where the
// campaign's ranges need it, still independently of the engine:
//  - the ZOH: reference::zoh is a plain Taylor series, which loses every digit once ||A T|| is
//    large (1 g behind 10 Ns/m at 100 Hz is ||A T|| = 100: terms of e^100 cancel down to
//    e^-100). Here it runs on T / 2^s with ||A T / 2^s|| <= 1/2 and the samples are joined by
//    the ZOH's own semigroup law: phi(2h) = phi(h)^2, gamma(2h) = phi(h) gamma(h) + gamma(h).
//  - the loop polynomial per structure (bilateral with the round-trip delay z^d, the decoupled
//    union, slave or master alone) with the plants above; the block-diagram formulas are
//    reference.hpp's.
//  - a Schur-Cohn (Jury) test in 50 digits for the stiffness search: all roots inside the unit
//    circle without computing them, so a fine scan and a bisection to 1e-12 are affordable.
//    The spectral radius from the roots (Aberth-Ehrlich) checks it at the answer.
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "common/stability/analyzer.hpp"
#include "common/stability/stiffness_search.hpp"
#include "reference.hpp"

namespace teleop::campaign {

using reference::Complex;
using reference::Poly;
using reference::Real;
using stability::Side;
using stability::Structure;
using stability::Verdict;

// ---------------------------------------------------------------------------------------------
// Seeded generation: one case depends only on (seed, index), so a report line can be rerun.

class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t next() {  // splitmix64: the same numbers with every standard library
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double uniform(double lo, double hi) { return lo + (hi - lo) * uniform(); }
  double log_uniform(double lo, double hi) { return lo * std::pow(hi / lo, uniform()); }
  bool chance(double p) { return uniform() < p; }
  int integer(int lo, int hi) {  // inclusive
    return lo + static_cast<int>(next() % static_cast<std::uint64_t>(hi - lo + 1));
  }

 private:
  std::uint64_t state_;
};

enum class CaseClass {
  kRandom,
  kNearCritical,  // the human+master plant at (or within 1e-14..1e-4 of) critical damping
  kNearBoundary,  // a fixture at the reference's stability limit, within 1e-15..1e-3 of it
  kMarginal,      // a mode at z = 1 (free drift, no restoring force), or within 1e-12 of it
  kHighRate,      // 20-100 kHz
  kMassExtreme,   // every mass at 1 g or 10 kg
  kLongDelay,     // round trip of 6-10 samples
};
inline constexpr int kClassCount = 7;

inline const char* class_name(CaseClass c) {
  switch (c) {
    case CaseClass::kRandom:
      return "random";
    case CaseClass::kNearCritical:
      return "near-critical damping";
    case CaseClass::kNearBoundary:
      return "near |z| = 1 boundary";
    case CaseClass::kMarginal:
      return "marginal z = 1";
    case CaseClass::kHighRate:
      return "high rate (20-100 kHz)";
    case CaseClass::kMassExtreme:
      return "heavy/light mass";
    case CaseClass::kLongDelay:
      return "long delay (6-10)";
  }
  return "?";
}

struct Case {
  std::uint64_t seed{0};
  int index{0};
  CaseClass cls{CaseClass::kRandom};
  TeleopParams params{};
  std::string note{};
  // The maximum stable stiffness is searched on a subset (one case in four).
  bool search{false};
  Side side{Side::kSlave};
};

// The structure rule of docs/analyze.md ("Decoupled loops are analysed alone"), restated here so
// the reference picks its polynomial from the specification, not from the engine.
inline Structure expected_structure(const TeleopParams& p, bool master_wall_used,
                                    bool slave_wall_used) {
  const Gains& g = p.gains;
  const bool master_feels_slave = p.scaling.force != 0.0 && (g.kpm != 0.0 || g.kdm != 0.0);
  const bool slave_follows = g.kps != 0.0 || g.kds != 0.0;
  const bool master_actuated = master_feels_slave || g.kvm != 0.0 ||
                               p.master_fixture.stiffness_N_per_m != 0.0 || master_wall_used;
  const bool slave_in_loop = slave_follows || slave_wall_used ||
                             p.slave_fixture.stiffness_N_per_m != 0.0 || !master_actuated;
  if (master_feels_slave && slave_follows) return Structure::kBilateral;
  if (master_actuated && slave_in_loop) return Structure::kDecoupled;
  if (master_actuated) return Structure::kMasterOnly;
  return Structure::kSlaveOnly;
}

// ---------------------------------------------------------------------------------------------
// The reference loop.

// exp([[A, B], [0, 0]] T) through reference::zoh on T / 2^s and s doublings of the ZOH.
inline reference::Zoh scaled_zoh(const Real& m, const Real& b, const Real& k, const Real& t) {
  Real norm = t * std::max(Real(1), Real((abs(k) + abs(b)) / m));
  Real h = t;
  int doublings = 0;
  while (norm > Real(0.5)) {
    norm /= 2;
    h /= 2;
    ++doublings;
  }
  reference::Zoh z = reference::zoh(m, b, k, h);
  for (int n = 0; n < doublings; ++n) {
    reference::Zoh d{};
    for (int i = 0; i < 2; ++i) {
      for (int j = 0; j < 2; ++j)
        d.phi[i][j] = z.phi[i][0] * z.phi[0][j] + z.phi[i][1] * z.phi[1][j];
      d.gamma[i] = z.phi[i][0] * z.gamma[0] + z.phi[i][1] * z.gamma[1] + z.gamma[i];
    }
    z = d;
  }
  return z;
}

// Everything but the fixtures, in 50 digits: polynomial(kmvf, ksvf) is then cheap.
class RefLoop {
 public:
  RefLoop(const TeleopParams& p, Structure structure) : p_(p), structure_(structure) {
    t_ = Real(p.period_s());
    if (p.velocity_cutoff_hz > 0.0) {
      r_ = exp(-2 * boost::math::constants::pi<Real>() * Real(p.velocity_cutoff_hz) * t_);
      a_ = 1 - r_;
    }
    const HumanImpedance h =
        p.human.kind == HumanKind::kFixed ? p.human.fixed : HumanImpedance{0.0, 0.0, 0.0};
    reference::plant_tf(
        scaled_zoh(Real(p.master_device.mass_kg) + Real(h.mass_kg),
                   Real(p.master_device.damping_Ns_per_m) + Real(h.damping_Ns_per_m),
                   Real(h.stiffness_N_per_m), t_),
        nm_, dm_);
    reference::plant_tf(scaled_zoh(Real(p.slave_device.mass_kg),
                                   Real(p.slave_device.damping_Ns_per_m), Real(0), t_),
                        ns_, ds_);
  }

  [[nodiscard]] Structure structure() const { return structure_; }

  // Characteristic polynomial of the closed loop at these fixture stiffnesses (ascending).
  [[nodiscard]] Poly polynomial(double kmvf, double ksvf) const {
    using reference::add;
    using reference::mul;
    const Gains& g = p_.gains;
    const Poly zr = {-r_, Real(1)};
    const Poly z1 = {Real(-1), Real(1)};
    const Real at = a_ / t_;
    const Real beta(p_.scaling.force);
    const Real alpha(p_.scaling.position);
    const Poly pmm = add(mul({beta * g.kpm + kmvf}, zr), mul({at * (beta * g.kdm + g.kvm)}, z1));
    const Poly qss = add(mul({Real(g.kps) + ksvf}, zr), mul({at * (Real(g.kds) + g.kvs)}, z1));
    const Poly master = add(mul(dm_, zr), mul(nm_, pmm));
    const Poly slave = add(mul(ds_, zr), mul(ns_, qss));
    switch (structure_) {
      case Structure::kSlaveOnly:
        return slave;
      case Structure::kMasterOnly:
        return master;
      case Structure::kDecoupled:
        return mul(master, slave);
      case Structure::kBilateral:
        break;
    }
    const Poly pms = add(mul({beta / alpha * g.kpm}, zr), mul({beta / alpha * at * g.kdm}, z1));
    const Poly qsm = add(mul({alpha * g.kps}, zr), mul({alpha * at * g.kds}, z1));
    const Poly right = reference::shift(slave, p_.round_trip_delay_samples);
    return add(mul(master, right), mul(mul(nm_, pms), mul(ns_, qsm)), Real(-1));
  }

  // The same without the velocity filter's pole of a side that has no velocity term: the
  // filter then sees nothing, and the block diagram's factor (z - r) (z itself without a
  // filter) is not a mode of the loop.
  [[nodiscard]] Poly reduced_polynomial(double kmvf, double ksvf) const {
    Poly p = polynomial(kmvf, ksvf);
    const Gains& g = p_.gains;
    const bool master_in = structure_ != Structure::kSlaveOnly;
    const bool slave_in = structure_ != Structure::kMasterOnly;
    const bool master_velocity = g.kvm != 0.0 || (p_.scaling.force != 0.0 && g.kdm != 0.0);
    const bool slave_velocity = g.kvs != 0.0 || g.kds != 0.0;
    if (master_in && !master_velocity) p = deflate(p, r_);
    if (slave_in && !slave_velocity) p = deflate(p, r_);
    return p;
  }

  // p(z) / (z - root) by synthetic division (the remainder is p(root), zero here).
  static Poly deflate(const Poly& p, const Real& root) {
    if (p.size() < 2) return p;
    Poly q(p.size() - 1);
    Real carry = p.back();
    for (std::size_t i = p.size() - 1; i-- > 0;) {
      q[i] = carry;
      carry = p[i] + carry * root;
    }
    return q;
  }

 private:
  TeleopParams p_;
  Structure structure_;
  Real t_{0};
  Real r_{0};
  Real a_{1};
  Poly nm_{}, dm_{}, ns_{}, ds_{};
};

// True when every root of p lies strictly inside the unit circle (Schur-Cohn-Jury reduction:
// |c_0| < |c_n|, then (c_n p(z) - c_0 z^n p(1/z)) / z, which keeps the count inside).
inline bool schur_stable(Poly p) {
  while (p.size() > 1 && p.back() == 0) p.pop_back();
  while (p.size() > 1) {
    const std::size_t n = p.size() - 1;
    const Real c0 = p.front();
    const Real cn = p.back();
    if (abs(c0) >= abs(cn)) return false;
    Poly q(n);
    for (std::size_t j = 0; j < n; ++j) q[j] = cn * p[j + 1] - c0 * p[n - 1 - j];
    p = std::move(q);
  }
  return true;
}

struct RefRoot {
  std::complex<double> z{};
  double abs_z{0.0};
  double margin{0.0};   // 1 - |z|, formed in 50 digits
  double zeta{1.0};     // -ln|z| / |ln z|, formed in 50 digits
  double log_abs{0.0};  // |ln z| (for the damping ratio's sensitivity)
  bool zero{false};     // |z| < 1e-30: a factor z of the polynomial (structural)
};

struct RefSpectrum {
  std::vector<RefRoot> roots{};
  double spectral_radius{0.0};
  double min_damping_ratio{2.0};  // over the non-zero roots
  double radius_margin{1.0};      // 1 - spectral radius, formed in 50 digits
};

inline RefSpectrum analyse_roots(const std::vector<Complex>& roots) {
  RefSpectrum out;
  Real worst_margin(1);
  for (const Complex& c : roots) {
    RefRoot r;
    const Real mag = abs(c);
    r.z = reference::to_double(c);
    r.abs_z = static_cast<double>(mag);
    r.margin = static_cast<double>(Real(1) - mag);
    r.zero = mag < Real("1e-30");
    if (!r.zero) {
      const Real re = log(mag);
      const Real im = atan2(c.imag(), c.real());
      const Real norm = sqrt(re * re + im * im);
      r.zeta = norm == 0 ? 0.0 : static_cast<double>(-re / norm);
      r.log_abs = static_cast<double>(norm);
      out.min_damping_ratio = std::min(out.min_damping_ratio, r.zeta);
    }
    if (Real(1) - mag < worst_margin) worst_margin = Real(1) - mag;
    out.spectral_radius = std::max(out.spectral_radius, r.abs_z);
    out.roots.push_back(r);
  }
  out.radius_margin = static_cast<double>(worst_margin);
  return out;
}

inline RefSpectrum reference_spectrum(const RefLoop& loop, double kmvf, double ksvf) {
  return analyse_roots(reference::roots(loop.reduced_polynomial(kmvf, ksvf)));
}

// The largest K with every fixture stiffness in [start, K] stable by the reference: a
// geometric scan finer than the engine's (x1.2), then bisection to `rel_tol`.
struct RefLimit {
  enum class Kind { kLimit, kUnstableAtZero, kMarginalThroughout, kNoneBelowCap } kind{};
  bool marginal_at_zero{false};  // a root at z = 1 at K = 0; the limit is over (0, K]
  double pass{0.0};              // stable
  double fail{0.0};              // unstable, pass < fail <= pass (1 + rel_tol)
};

inline RefLimit reference_limit(const RefLoop& loop, Side side, double other, double start,
                                double growth, double rel_tol, double cap) {
  auto poly = [&](double k) {
    return side == Side::kMaster ? loop.reduced_polynomial(k, other)
                                 : loop.reduced_polynomial(other, k);
  };
  RefLimit out;
  const RefSpectrum at_zero = analyse_roots(reference::roots(poly(0.0)));
  if (at_zero.radius_margin < -1e-25) {
    out.kind = RefLimit::Kind::kUnstableAtZero;
    return out;
  }
  if (at_zero.radius_margin <= 1e-25) {
    out.marginal_at_zero = true;
    const RefSpectrum at_start = analyse_roots(reference::roots(poly(start)));
    if (at_start.radius_margin <= 1e-25) {
      out.kind = RefLimit::Kind::kMarginalThroughout;
      return out;
    }
  }
  double pass = 0.0;
  double fail = -1.0;
  for (double k = start; k < cap; k *= growth) {
    if (!schur_stable(poly(k))) {
      fail = k;
      break;
    }
    pass = k;
  }
  if (fail < 0.0) {
    if (schur_stable(poly(cap))) {
      out.kind = RefLimit::Kind::kNoneBelowCap;
      out.pass = cap;
      return out;
    }
    fail = cap;
  }
  while (fail - pass > rel_tol * fail) {
    const double mid = 0.5 * (pass + fail);
    if (mid <= pass || mid >= fail) break;
    (schur_stable(poly(mid)) ? pass : fail) = mid;
  }
  out.kind = RefLimit::Kind::kLimit;
  out.pass = pass;
  out.fail = fail;
  return out;
}

// ---------------------------------------------------------------------------------------------
// Case generation.

// A teleoperator with every parameter drawn over the campaign's ranges. The gains are drawn
// relative to the loop's own scales (m / T^2 for stiffness, m / T for damping) so that stable,
// unstable and marginal loops all occur at every rate and mass.
inline TeleopParams random_params(Rng& rng, double rate_lo, double rate_hi, int delay_lo,
                                  int delay_hi) {
  TeleopParams p;
  p.sample_rate_hz = rng.log_uniform(rate_lo, rate_hi);
  const double t = p.period_s();
  auto device = [&] {
    const double m = rng.log_uniform(1e-3, 10.0);
    const double b = rng.chance(0.1) ? 0.0 : m * rng.log_uniform(0.1, 1000.0);
    return DeviceParams{m, b};
  };
  p.master_device = device();
  p.slave_device = device();
  if (rng.chance(0.8)) {
    p.human.kind = HumanKind::kFixed;
    p.human.fixed = {rng.log_uniform(1e-3, 1.0), rng.log_uniform(0.01, 50.0),
                     rng.log_uniform(1.0, 1e4)};
  } else {
    p.human.kind = HumanKind::kNone;
  }
  const double m_master = p.master_device.mass_kg + p.human.fixed.mass_kg;
  const double m_slave = p.slave_device.mass_kg;
  auto stiffness = [&](double m) {
    return std::min(1e6, m / (t * t) * std::pow(10.0, rng.uniform(-7.0, 0.5)));
  };
  auto damping = [&](double m) { return m / t * std::pow(10.0, rng.uniform(-4.0, 0.3)); };
  Gains& g = p.gains;
  g.kpm = stiffness(m_master);
  g.kps = stiffness(m_slave);
  if (rng.chance(0.5)) {
    g.kdm = damping(m_master);
    g.kds = damping(m_slave);
  } else {  // symmetric gains: the shared-memory realisation and its third structural zero
    g.kdm = g.kds = damping(std::min(m_master, m_slave));
    g.kpm = g.kps;
  }
  if (rng.chance(0.5)) g.kvm = damping(m_master) * 0.3;
  if (rng.chance(0.5)) g.kvs = damping(m_slave) * 0.3;
  if (rng.chance(0.15)) g.kdm = 0.0;  // a position-only channel: no filter state on that side
  if (rng.chance(0.15)) g.kds = 0.0;
  g.kfm = rng.chance(0.3) ? rng.uniform(0.0, 2.0) : 0.0;  // does not enter the spectrum
  p.scaling = rng.chance(0.3) ? Scaling{1.0, 1.0}
                              : Scaling{rng.log_uniform(0.2, 5.0), rng.log_uniform(0.2, 5.0)};
  // Mostly bilateral; the decoupled structures of docs/analyze.md one in ten each.
  const int structure = rng.integer(0, 9);
  if (structure == 0) {  // master unactuated: the slave alone
    g.kpm = g.kdm = g.kvm = 0.0;
  } else if (structure == 1) {  // the slave does not follow: the master alone
    g.kps = g.kds = 0.0;
  } else if (structure == 2) {  // no force feedback
    if (rng.chance(0.5)) {
      p.scaling.force = 0.0;
    } else {
      g.kpm = g.kdm = 0.0;
    }
  }
  auto fixture = [&](double m) {
    return rng.chance(0.4) ? 0.0
                           : std::min(1e6, m / (t * t) * std::pow(10.0, rng.uniform(-8.0, 0.0)));
  };
  p.master_fixture.stiffness_N_per_m = fixture(m_master);
  p.slave_fixture.stiffness_N_per_m = fixture(m_slave);
  p.master_fixture.position_m = rng.uniform(-0.01, 0.01);  // does not enter the spectrum
  if (rng.chance(0.5)) {
    p.velocity_cutoff_hz = rng.log_uniform(1.0, 0.45 * p.sample_rate_hz);
  }
  p.round_trip_delay_samples = rng.integer(delay_lo, delay_hi);
  p.analysis.stiffness_tolerance_N_per_m = 1e-4;
  return p;
}

inline Structure structure_of(const TeleopParams& p) { return expected_structure(p, false, false); }

// The stiffness the reference puts on the unit circle for one fixture, or nothing.
inline std::optional<std::pair<double, double>> boundary_stiffness(const TeleopParams& p,
                                                                   Side side) {
  const bool master = side == Side::kMaster;
  const RefLoop loop(p, expected_structure(p, master, !master));
  const double other =
      master ? p.slave_fixture.stiffness_N_per_m : p.master_fixture.stiffness_N_per_m;
  const RefLimit l = reference_limit(loop, side, other, 1e-3, 1.5, 1e-16, 1e6);
  if (l.kind != RefLimit::Kind::kLimit) return std::nullopt;
  return std::pair{l.pass, l.fail};
}

inline Case make_case(std::uint64_t seed, int index) {
  Case c;
  c.seed = seed;
  c.index = index;
  Rng rng(seed * 0x100000001B3ULL + static_cast<std::uint64_t>(index) * 0x9E3779B97F4A7C15ULL);
  // Random twice as often as each adversarial class.
  const int slot = index % (kClassCount + 1);
  c.cls = slot <= 1 ? CaseClass::kRandom : static_cast<CaseClass>(slot - 1);
  c.search = rng.chance(0.25);
  c.side = rng.chance(0.5) ? Side::kMaster : Side::kSlave;
  switch (c.cls) {
    case CaseClass::kRandom:
      c.params = random_params(rng, 100.0, 1e5, 0, 10);
      break;
    case CaseClass::kHighRate:
      c.params = random_params(rng, 2e4, 1e5, 0, 10);
      break;
    case CaseClass::kLongDelay:
      c.params = random_params(rng, 100.0, 1e5, 6, 10);
      c.params.scaling.force = std::max(c.params.scaling.force, 0.2);
      c.params.gains.kpm = std::max(c.params.gains.kpm, 1e-3);  // the delay enters: bilateral
      c.params.gains.kps = std::max(c.params.gains.kps, 1e-3);
      break;
    case CaseClass::kMassExtreme: {
      // Every mass moved to an end of the range; gains, damping and fixtures follow the mass
      // so the loop stays near its stability scale.
      c.params = random_params(rng, 100.0, 1e5, 0, 10);
      TeleopParams& p = c.params;
      auto extreme = [&] { return rng.chance(0.5) ? 1e-3 : 10.0; };
      const double old_master = p.master_device.mass_kg + p.human.fixed.mass_kg;
      const double sm = extreme() / p.slave_device.mass_kg;
      const double md = extreme() / p.master_device.mass_kg;
      p.slave_device.mass_kg *= sm;
      p.slave_device.damping_Ns_per_m *= sm;
      p.master_device.mass_kg *= md;
      p.master_device.damping_Ns_per_m *= md;
      if (p.human.kind == HumanKind::kFixed) p.human.fixed.mass_kg = rng.chance(0.5) ? 1e-3 : 1.0;
      const double mm = (p.master_device.mass_kg + p.human.fixed.mass_kg) / old_master;
      p.gains.kps = std::min(1e6, p.gains.kps * sm);
      p.gains.kds *= sm;
      p.gains.kvs *= sm;
      p.gains.kpm = std::min(1e6, p.gains.kpm * mm);
      p.gains.kdm *= mm;
      p.gains.kvm *= mm;
      p.master_fixture.stiffness_N_per_m = std::min(1e6, p.master_fixture.stiffness_N_per_m * mm);
      p.slave_fixture.stiffness_N_per_m = std::min(1e6, p.slave_fixture.stiffness_N_per_m * sm);
      break;
    }
    case CaseClass::kNearCritical: {
      c.params = random_params(rng, 100.0, 1e5, 0, 10);
      TeleopParams& p = c.params;
      const int which = rng.integer(0, 3);
      const double eps =
          which == 0 ? 0.0 : (which == 1 ? 1.0 : -1.0) * std::pow(10.0, rng.uniform(-14.0, -4.0));
      char note[160];
      if (rng.chance(0.75)) {
        // The ZOH's hard case: the human+master plant's poles (nearly) coincide.
        p.human.kind = HumanKind::kFixed;
        const double m = p.master_device.mass_kg + p.human.fixed.mass_kg;
        const double b = p.master_device.damping_Ns_per_m + p.human.fixed.damping_Ns_per_m;
        p.human.fixed.stiffness_N_per_m = b * b / (4.0 * m) * (1.0 + eps);
        std::snprintf(note, sizeof note, "human+master plant at critical damping x (1 %+.3g)", eps);
      } else {
        // The eigen-solver's hard case: the slave alone on its wall at (continuous) critical
        // damping, slow against the rate, so a nearly defective pair sits close to z = 1.
        Gains& g = p.gains;
        g.kpm = g.kdm = g.kvm = g.kps = 0.0;
        p.master_fixture.stiffness_N_per_m = 0.0;
        const double m = p.slave_device.mass_kg;
        const double b = 2.0 * m / p.period_s() * std::pow(10.0, rng.uniform(-7.0, -2.0));
        p.slave_device.damping_Ns_per_m = b * rng.uniform(0.0, 1.0);
        g.kvs = b - p.slave_device.damping_Ns_per_m;
        g.kds = 0.0;
        p.slave_fixture.stiffness_N_per_m = b * b / (4.0 * m) * (1.0 + eps);
        std::snprintf(note, sizeof note,
                      "slave alone on its wall at critical damping x (1 %+.3g), bT/2m %.3g", eps,
                      b * p.period_s() / (2.0 * m));
      }
      c.note = note;
      break;
    }
    case CaseClass::kMarginal: {
      c.params = random_params(rng, 100.0, 1e5, 0, 10);
      TeleopParams& p = c.params;
      p.human.kind = HumanKind::kNone;
      p.master_fixture.stiffness_N_per_m = 0.0;
      p.slave_fixture.stiffness_N_per_m = 0.0;
      const int variant = rng.integer(0, 4);
      if (variant == 0) {
        c.note = "bilateral drift at z = 1";
        if (p.gains.kps == 0.0) p.gains.kps = 1.0;
        if (p.gains.kpm == 0.0) p.gains.kpm = 1.0;
        p.scaling.force = std::max(p.scaling.force, 0.2);
      } else if (variant == 1) {
        c.note = "bilateral drift, no damping anywhere: double root at z = 1";
        p.scaling.force = std::max(p.scaling.force, 0.2);
        if (p.gains.kps == 0.0) p.gains.kps = 1.0;
        if (p.gains.kpm == 0.0) p.gains.kpm = 1.0;
        p.master_device.damping_Ns_per_m = p.slave_device.damping_Ns_per_m = 0.0;
        p.gains.kvm = p.gains.kvs = 0.0;
      } else if (variant == 2) {
        c.note = "slave alone, free (no position gain, no fixture)";
        p.gains.kpm = p.gains.kdm = p.gains.kvm = 0.0;
        p.gains.kps = 0.0;
        if (p.gains.kds == 0.0 && p.gains.kvs == 0.0) p.gains.kds = 1e-3;
      } else if (variant == 3) {
        c.note = "master alone with no human, free";
        p.gains.kps = p.gains.kds = 0.0;
        p.gains.kpm = 0.0;
        if (p.gains.kvm == 0.0) p.gains.kvm = p.master_device.mass_kg / p.period_s() * 1e-2;
      } else {
        const double k = std::pow(10.0, rng.uniform(-12.0, -4.0));
        char note[96];
        std::snprintf(note, sizeof note, "bilateral drift held by a slave fixture of %.3g N/m", k);
        c.note = note;
        if (p.gains.kps == 0.0) p.gains.kps = 1.0;
        if (p.gains.kpm == 0.0) p.gains.kpm = 1.0;
        p.scaling.force = std::max(p.scaling.force, 0.2);
        p.slave_fixture.stiffness_N_per_m = k;
      }
      break;
    }
    case CaseClass::kNearBoundary: {
      // Redraw until the reference finds a finite limit on the chosen side.
      for (int attempt = 0;; ++attempt) {
        c.params = random_params(rng, 100.0, 1e5, 0, 10);
        const bool master = c.side == Side::kMaster;
        (master ? c.params.master_fixture : c.params.slave_fixture).stiffness_N_per_m = 0.0;
        const auto k = boundary_stiffness(c.params, c.side);
        if (!k && attempt < 50) continue;
        double stiffness = 0.0;
        if (k) {
          const int which = rng.integer(0, 3);
          if (which == 0) {
            stiffness = k->first;
          } else if (which == 1) {
            stiffness = k->second;
          } else {
            const double delta = std::pow(10.0, rng.uniform(-15.0, -3.0));
            stiffness = k->first * (which == 2 ? 1.0 - delta : 1.0 + delta);
          }
        }
        (master ? c.params.master_fixture : c.params.slave_fixture).stiffness_N_per_m = stiffness;
        c.note = std::string(master ? "master" : "slave") + " fixture near the reference's limit";
        break;
      }
      break;
    }
  }
  return c;
}

// Every parameter that enters the spectrum, with all digits, to rerun or write up a case.
inline std::string describe(const Case& c) {
  const TeleopParams& p = c.params;
  char buf[1024];
  std::snprintf(buf, sizeof buf,
                "seed %llu case %d (%s%s%s): rate %.17g Hz, master {%.17g kg, %.17g Ns/m}, "
                "slave {%.17g kg, %.17g Ns/m}, human %s{%.17g kg, %.17g Ns/m, %.17g N/m}, "
                "gains kpm %.17g kps %.17g kdm %.17g kds %.17g kvm %.17g kvs %.17g, "
                "alpha %.17g beta %.17g, fixtures master %.17g slave %.17g N/m, "
                "cutoff %.17g Hz, delay %d",
                static_cast<unsigned long long>(c.seed), c.index, class_name(c.cls),
                c.note.empty() ? "" : ": ", c.note.c_str(), p.sample_rate_hz,
                p.master_device.mass_kg, p.master_device.damping_Ns_per_m, p.slave_device.mass_kg,
                p.slave_device.damping_Ns_per_m, p.human.kind == HumanKind::kFixed ? "" : "none ",
                p.human.fixed.mass_kg, p.human.fixed.damping_Ns_per_m,
                p.human.fixed.stiffness_N_per_m, p.gains.kpm, p.gains.kps, p.gains.kdm, p.gains.kds,
                p.gains.kvm, p.gains.kvs, p.scaling.position, p.scaling.force,
                p.master_fixture.stiffness_N_per_m, p.slave_fixture.stiffness_N_per_m,
                p.velocity_cutoff_hz, p.round_trip_delay_samples);
  return buf;
}

// ---------------------------------------------------------------------------------------------
// Comparing one case.

struct ModeComparison {
  std::complex<double> engine{};
  std::complex<double> ref{};
  double error_bound{0.0};  // the engine's
  double dz{0.0};
  double dzeta{0.0};
  double zeta_bound{std::numeric_limits<double>::infinity()};  // first order, from error_bound
  bool zeta_resolved{false};  // the bound on zeta is below 0.1: the comparison is meaningful
};

enum class VerdictCheck {
  kAgreeOutside,      // outside the bound, engine decided and right
  kUncertainOutside,  // outside the bound but engine uncertain (allowed within 2x the bound)
  kWrongOutside,      // outside the bound, engine decided and wrong: a defect
  kUncertainInside,   // within the bound, engine uncertain: as required
  kAgreeInside,       // within the bound, engine decided and right
  kWrongInside,       // within the bound, engine decided and wrong: a defect
};

inline const char* to_string(VerdictCheck v) {
  switch (v) {
    case VerdictCheck::kAgreeOutside:
      return "agree (outside bound)";
    case VerdictCheck::kUncertainOutside:
      return "uncertain (outside bound)";
    case VerdictCheck::kWrongOutside:
      return "WRONG (outside bound)";
    case VerdictCheck::kUncertainInside:
      return "uncertain (within bound)";
    case VerdictCheck::kAgreeInside:
      return "agree (within bound)";
    case VerdictCheck::kWrongInside:
      return "WRONG (within bound)";
  }
  return "?";
}

inline bool is_defect(VerdictCheck v) {
  return v == VerdictCheck::kWrongOutside || v == VerdictCheck::kWrongInside;
}

struct CaseResult {
  Structure engine_structure{};
  Structure expected{};
  stability::AnalysisResult engine{};
  Verdict fast_verdict{};  // the eigenvalue-only path the stiffness search and band sweep use
  RefSpectrum ref{};
  std::vector<ModeComparison> modes{};
  bool count_mismatch{false};     // the engine has more modes than the reference has roots
  double leftover_root_abs{0.0};  // largest reference root not matched (structural), |z|
  double max_dz{0.0};
  double max_dz_over_bound{0.0};
  double max_dz_outer{0.0};  // over modes with |z| >= 0.5 (those a verdict can hinge on)
  double max_dzeta{0.0};     // over resolved modes
  double max_dzeta_over_bound{0.0};
  double dzeta_min{0.0};  // |engine min zeta - reference min zeta|, when every mode resolves
  bool min_zeta_resolved{false};
  double dzeta_min_bound{0.0};  // the largest per-mode zeta bound: a minimum moves no more
  // The reference's verdict: stable (-1 margin sign), unstable, or on the circle (marginal).
  Verdict ref_verdict{};
  bool ref_marginal{false};
  bool outside_bound{false};
  VerdictCheck check{};
  bool fast_outside_bound{false};
  // Farther from the circle than twice the engine's bounds: an `uncertain` there would be
  // more cautious than the bounds justify (the engine's z may sit one bound off, not two).
  bool outside_twice_bound{false};
  VerdictCheck fast_check{};
  bool ref_self_check_failed{false};  // Schur-Cohn and the roots disagree: a reference problem
  double engine_us{0.0};
  double reference_us{0.0};
};

// Pairs every engine mode with a distinct reference root, closest pairs first.
inline std::vector<std::pair<std::size_t, std::size_t>> match(
    const std::vector<std::complex<double>>& engine, const std::vector<RefRoot>& ref) {
  struct Pair {
    double d;
    std::size_t i, j;
  };
  std::vector<Pair> pairs;
  for (std::size_t i = 0; i < engine.size(); ++i)
    for (std::size_t j = 0; j < ref.size(); ++j)
      pairs.push_back({std::abs(engine[i] - ref[j].z), i, j});
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) { return a.d < b.d; });
  std::vector<bool> used_i(engine.size(), false), used_j(ref.size(), false);
  std::vector<std::pair<std::size_t, std::size_t>> out;
  for (const Pair& p : pairs) {
    if (used_i[p.i] || used_j[p.j]) continue;
    used_i[p.i] = used_j[p.j] = true;
    out.emplace_back(p.i, p.j);
  }
  return out;
}

// The verdict against the reference with the engine's per-mode bounds: outside the bound when
// some reference root is farther outside the circle than its engine mode's bound (decidedly
// unstable), or every root farther inside than its bound (decidedly stable).
inline VerdictCheck check_verdict(Verdict engine, const std::vector<double>& margins,
                                  const std::vector<double>& bounds, Verdict ref_verdict,
                                  bool ref_marginal, bool& outside) {
  bool decided_unstable = false;
  bool decided_stable = true;
  for (std::size_t i = 0; i < margins.size(); ++i) {
    if (-margins[i] > bounds[i]) decided_unstable = true;
    if (!(margins[i] > bounds[i])) decided_stable = false;
  }
  outside = decided_unstable || decided_stable;
  if (engine == Verdict::kUncertain) {
    return outside ? VerdictCheck::kUncertainOutside : VerdictCheck::kUncertainInside;
  }
  const bool right = !ref_marginal && engine == ref_verdict;
  if (outside) return right ? VerdictCheck::kAgreeOutside : VerdictCheck::kWrongOutside;
  return right ? VerdictCheck::kAgreeInside : VerdictCheck::kWrongInside;
}

// Matches an engine spectrum against the reference's roots and checks the verdict with the
// engine's per-mode bounds; `details` (optional) receives the per-mode errors.
// `bound_scale` widens the bounds (2: "farther than twice the bound").
inline VerdictCheck compare_spectra(const stability::Spectrum& sp, const RefSpectrum& ref,
                                    bool& outside, CaseResult* details = nullptr,
                                    double bound_scale = 1.0) {
  const bool ref_marginal = std::abs(ref.radius_margin) <= 1e-25;
  const Verdict ref_verdict = ref.radius_margin > 0.0 ? Verdict::kStable : Verdict::kUnstable;
  std::vector<std::complex<double>> zs;
  std::vector<double> bounds;
  for (const stability::Mode& m : sp.modes) {
    if (m.structural) continue;
    zs.push_back(m.z);
    bounds.push_back(m.error);
  }
  const auto pairs = match(zs, ref.roots);
  std::vector<double> margins(zs.size(), 0.0);
  std::vector<double> matched_bounds(zs.size(), 0.0);
  std::vector<bool> used(ref.roots.size(), false);
  double max_zeta_bound = 0.0;
  for (const auto& [i, j] : pairs) {
    used[j] = true;
    const RefRoot& r = ref.roots[j];
    margins[i] = r.margin;
    matched_bounds[i] = bound_scale * bounds[i];
    if (details == nullptr) continue;
    CaseResult& out = *details;
    ModeComparison mc;
    mc.engine = zs[i];
    mc.ref = r.z;
    mc.error_bound = bounds[i];
    mc.dz = std::abs(zs[i] - r.z);
    // |d zeta| <= |d(ln z)| / |ln z| <= |dz| / (|z| |ln z|) to first order; twice that here.
    if (!r.zero && r.log_abs > 0.0) {
      mc.zeta_bound = 2.0 * bounds[i] / (r.abs_z * r.log_abs);
      mc.zeta_resolved = mc.zeta_bound < 0.1;
      mc.dzeta = std::abs(stability::damping_ratio(zs[i]) - r.zeta);
    }
    max_zeta_bound = std::max(max_zeta_bound, mc.zeta_resolved ? mc.zeta_bound : 1e300);
    out.max_dz = std::max(out.max_dz, mc.dz);
    if (r.abs_z >= 0.5) out.max_dz_outer = std::max(out.max_dz_outer, mc.dz);
    out.max_dz_over_bound = std::max(out.max_dz_over_bound, mc.dz / mc.error_bound);
    if (mc.zeta_resolved) {
      out.max_dzeta = std::max(out.max_dzeta, mc.dzeta);
      out.max_dzeta_over_bound = std::max(out.max_dzeta_over_bound, mc.dzeta / mc.zeta_bound);
    }
    out.modes.push_back(mc);
  }
  if (details != nullptr) {
    CaseResult& out = *details;
    out.count_mismatch = pairs.size() < zs.size();
    for (std::size_t j = 0; j < used.size(); ++j)
      if (!used[j]) out.leftover_root_abs = std::max(out.leftover_root_abs, ref.roots[j].abs_z);
    out.min_zeta_resolved = max_zeta_bound < 0.1 && !zs.empty();
    out.dzeta_min_bound = max_zeta_bound;
    out.dzeta_min = std::abs(sp.min_damping_ratio - ref.min_damping_ratio);
  }
  return check_verdict(sp.verdict, margins, matched_bounds, ref_verdict, ref_marginal, outside);
}

inline CaseResult run_case(const Case& c) {
  CaseResult out;
  const TeleopParams& p = c.params;
  const double kmvf = p.master_fixture.stiffness_N_per_m;
  const double ksvf = p.slave_fixture.stiffness_N_per_m;

  const auto t0 = std::chrono::steady_clock::now();
  out.engine = stability::analyze(p);
  const auto t1 = std::chrono::steady_clock::now();
  out.engine_structure = out.engine.structure;
  out.expected = structure_of(p);
  const stability::LoopEvaluator ev(p);
  const stability::Spectrum fast = ev.spectrum(0, kmvf, ksvf, false);
  out.fast_verdict = fast.verdict;

  const auto t2 = std::chrono::steady_clock::now();
  const RefLoop loop(p, out.expected);
  out.ref = reference_spectrum(loop, kmvf, ksvf);
  const auto t3 = std::chrono::steady_clock::now();
  out.engine_us = std::chrono::duration<double, std::micro>(t1 - t0).count();
  out.reference_us = std::chrono::duration<double, std::micro>(t3 - t2).count();
  // The reference checks itself: Schur-Cohn against its roots, away from the circle.
  if (std::abs(out.ref.radius_margin) > 1e-20) {
    out.ref_self_check_failed =
        schur_stable(loop.reduced_polynomial(kmvf, ksvf)) != (out.ref.radius_margin > 0.0);
  }
  out.ref_marginal = std::abs(out.ref.radius_margin) <= 1e-25;
  out.ref_verdict = out.ref.radius_margin > 0.0 ? Verdict::kStable : Verdict::kUnstable;

  // With one human, analyze()'s verdict is its spectrum's.
  out.check = compare_spectra(out.engine.spectrum, out.ref, out.outside_bound, &out);
  out.fast_check = compare_spectra(fast, out.ref, out.fast_outside_bound);
  compare_spectra(out.engine.spectrum, out.ref, out.outside_twice_bound, nullptr, 2.0);
  return out;
}

// The maximum stable stiffness: the engine's search against the reference's.
struct LimitResult {
  stability::StiffnessLimit engine{};
  RefLimit ref{};
  bool both_finite{false};
  double rel_error{0.0};  // (engine - reference) / reference
  double abs_error{0.0};  // engine - reference, N/m
  double tol{0.0};        // the engine's stiffness tolerance, N/m
  // The reference's radius margin (1 - rho) at the engine's limit and one tolerance above it.
  double ref_margin_at_engine{0.0};
  double ref_margin_above_engine{0.0};
  // Finite on one side only. Justified when the engine found its lower end (K = 0, or the
  // tolerance after a marginal K = 0) uncertain and the reference is indeed within the
  // engine's error bound there.
  bool kind_mismatch{false};
  bool kind_mismatch_justified{false};
  // The reference is unstable at the engine's limit, and outside the engine's error bound.
  bool engine_stable_where_ref_unstable{false};
  VerdictCheck at_engine_check{VerdictCheck::kAgreeOutside};
  // The reference is stable at the engine's limit but finds an unstable window below it: the
  // engine's x1.2 scan stepped over it (a limit docs/stability-limits.md states).
  bool window_missed{false};
  // The reference is stable one tolerance above the engine's limit by more than twice the
  // engine's error bounds there.
  bool stopped_early{false};
  double engine_ms{0.0};
  double reference_ms{0.0};
};

inline LimitResult run_limit(const Case& c, double growth = 1.02, double rel_tol = 1e-12) {
  LimitResult out;
  const TeleopParams& p = c.params;
  const bool master = c.side == Side::kMaster;
  const double other =
      master ? p.slave_fixture.stiffness_N_per_m : p.master_fixture.stiffness_N_per_m;
  const double tol = p.analysis.stiffness_tolerance_N_per_m;
  out.tol = tol;
  const double cap = stability::SearchOptions{}.max_stiffness_N_per_m;
  const auto t0 = std::chrono::steady_clock::now();
  out.engine = stability::max_stable_stiffness(p, c.side);
  const auto t1 = std::chrono::steady_clock::now();
  const RefLoop loop(p, expected_structure(p, master, !master));
  out.ref = reference_limit(loop, c.side, other, tol, growth, rel_tol, cap);
  const auto t2 = std::chrono::steady_clock::now();
  out.engine_ms = std::chrono::duration<double, std::milli>(t1 - t0).count();
  out.reference_ms = std::chrono::duration<double, std::milli>(t2 - t1).count();

  auto km = [&](double k) { return master ? k : other; };
  auto ks = [&](double k) { return master ? other : k; };
  auto margin = [&](double k) { return reference_spectrum(loop, km(k), ks(k)).radius_margin; };
  const bool engine_finite = out.engine.max_stable_stiffness_N_per_m.has_value();
  const bool ref_finite = out.ref.kind == RefLimit::Kind::kLimit;
  out.both_finite = engine_finite && ref_finite;
  out.kind_mismatch = engine_finite != ref_finite;
  if (out.kind_mismatch) {
    const stability::LoopEvaluator ev(p, master, !master);
    for (const double k : {0.0, tol}) {
      bool outside = false;
      const stability::Spectrum sp = ev.spectrum(0, km(k), ks(k), true);
      compare_spectra(sp, reference_spectrum(loop, km(k), ks(k)), outside);
      if (!outside) out.kind_mismatch_justified = true;
    }
  }
  if (engine_finite) {
    const double k = *out.engine.max_stable_stiffness_N_per_m;
    out.ref_margin_at_engine = margin(k);
    out.ref_margin_above_engine = margin(k + tol);
    if (out.ref_margin_at_engine <= 0.0) {
      // The search took K as stable (eigenvalue-only path): wrong unless within its bound.
      const stability::LoopEvaluator ev(p, master, !master);
      bool outside = false;
      out.at_engine_check = compare_spectra(ev.spectrum(0, km(k), ks(k), false),
                                            reference_spectrum(loop, km(k), ks(k)), outside);
      out.engine_stable_where_ref_unstable = is_defect(out.at_engine_check);
    } else {
      out.window_missed = ref_finite && k > out.ref.fail * (1.0 + 1e-9);
    }
    // One tolerance above its limit the engine found a failure (it stopped there); it stopped
    // early if the reference is stable there by more than twice the engine's bounds.
    const stability::LoopEvaluator ev(p, master, !master);
    const stability::Spectrum above = ev.spectrum(0, km(k + tol), ks(k + tol), false);
    if (above.verdict != Verdict::kStable && !out.window_missed) {
      bool outside = false;
      compare_spectra(above, reference_spectrum(loop, km(k + tol), ks(k + tol)), outside, nullptr,
                      2.0);
      out.stopped_early = outside && out.ref_margin_above_engine > 0.0;
    }
  }
  if (out.both_finite) {
    out.abs_error = *out.engine.max_stable_stiffness_N_per_m - out.ref.pass;
    out.rel_error = out.abs_error / out.ref.pass;
  }
  return out;
}

}  // namespace teleop::campaign
