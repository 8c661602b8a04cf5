// The engine's model against the independent transfer-function reference, and the structural facts
// of docs/architecture.md §2.5-2.7 (decoupling, structural zeros, alpha drops out, marginal modes).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "common/stability/analyzer.hpp"
#include "common/stability/stiffness_search.hpp"
#include "reference.hpp"

namespace teleop::stability {
namespace {

TeleopParams bilateral(double rate_hz) {
  TeleopParams p;
  p.sample_rate_hz = rate_hz;
  p.master_device = {0.040, 0.41};
  p.slave_device = {0.036, 0.49};
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {0.010, 2.0, 300.0};
  return p;
}

reference::LoopSpec spec_of(const TeleopParams& p) {
  reference::LoopSpec s;
  s.t = p.period_s();
  s.mm = p.master_device.mass_kg;
  s.bm = p.master_device.damping_Ns_per_m;
  s.ms = p.slave_device.mass_kg;
  s.bs = p.slave_device.damping_Ns_per_m;
  s.mh = p.human.fixed.mass_kg;
  s.bh = p.human.fixed.damping_Ns_per_m;
  s.kh = p.human.fixed.stiffness_N_per_m;
  s.kpm = p.gains.kpm;
  s.kps = p.gains.kps;
  s.kdm = p.gains.kdm;
  s.kds = p.gains.kds;
  s.kvm = p.gains.kvm;
  s.kvs = p.gains.kvs;
  s.alpha = p.scaling.position;
  s.beta = p.scaling.force;
  s.kmvf = p.master_fixture.stiffness_N_per_m;
  s.ksvf = p.slave_fixture.stiffness_N_per_m;
  s.cutoff_hz = p.velocity_cutoff_hz;
  s.delay = p.round_trip_delay_samples;
  return s;
}

// Every non-structural eigenvalue matches a distinct non-zero reference root within `rel`
// (relative to |z|), and the counts agree.
void expect_same_spectrum(const Spectrum& got, const std::vector<reference::Complex>& want,
                          double rel, const std::string& what) {
  std::vector<std::complex<double>> ref;
  for (const auto& c : want) {
    const auto d = reference::to_double(c);
    if (std::abs(d) > 1e-30) ref.push_back(d);
  }
  std::vector<std::complex<double>> mine;
  for (const Mode& m : got.modes)
    if (!m.structural) mine.push_back(m.z);
  ASSERT_EQ(mine.size(), ref.size()) << what;
  std::vector<bool> used(ref.size(), false);
  for (const auto& z : mine) {
    std::size_t best = 0;
    double best_d = 1e300;
    for (std::size_t j = 0; j < ref.size(); ++j) {
      const double d = std::abs(z - ref[j]);
      if (!used[j] && d < best_d) {
        best_d = d;
        best = j;
      }
    }
    used[best] = true;
    EXPECT_LE(best_d, rel * std::abs(ref[best])) << what << " z=" << z << " ref=" << ref[best];
  }
}

TEST(Structure, RandomLoopsMatchTheTransferFunctionReference) {
  std::mt19937 rng(20261121);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto log_uniform = [&](double lo, double hi) { return lo * std::pow(hi / lo, u(rng)); };
  for (int trial = 0; trial < 60; ++trial) {
    TeleopParams p = bilateral(log_uniform(200.0, 20000.0));
    p.master_device = {log_uniform(0.005, 2.0), log_uniform(0.01, 5.0)};
    p.slave_device = {log_uniform(0.005, 2.0), log_uniform(0.01, 5.0)};
    p.human.fixed = {log_uniform(0.001, 0.5), log_uniform(0.1, 10.0), log_uniform(10.0, 2000.0)};
    p.gains = {log_uniform(10.0, 3000.0),
               log_uniform(10.0, 3000.0),
               log_uniform(0.1, 10.0),
               log_uniform(0.1, 10.0),
               u(rng) < 0.5 ? 0.0 : log_uniform(0.1, 3.0),
               u(rng) < 0.5 ? 0.0 : log_uniform(0.1, 3.0),
               0.0};
    p.scaling = {log_uniform(0.2, 5.0), log_uniform(0.2, 5.0)};
    p.master_fixture.stiffness_N_per_m = u(rng) < 0.5 ? 0.0 : log_uniform(10.0, 1e4);
    p.slave_fixture.stiffness_N_per_m = log_uniform(10.0, 1e4);
    p.velocity_cutoff_hz = u(rng) < 0.5 ? 0.0 : log_uniform(20.0, 0.4 * p.sample_rate_hz);
    p.round_trip_delay_samples = static_cast<int>(u(rng) * 4.0);
    const LoopEvaluator ev(p);
    ASSERT_EQ(ev.model().structure(), Structure::kBilateral);
    const Spectrum got =
        ev.spectrum(0, p.master_fixture.stiffness_N_per_m, p.slave_fixture.stiffness_N_per_m, true);
    const auto want = reference::roots(reference::bilateral_polynomial(spec_of(p)));
    // The counts agree too: 6 + d modes (docs/architecture.md §2.7: the filtered differentiator is
    // first order like the plain one), as many as the reference polynomial's degree.
    expect_same_spectrum(got, want, 1e-8, "trial " + std::to_string(trial));
  }
}

TEST(Structure, DecoupledLoopsMatchTheReference) {
  // No force feedback (K_pm = K_dm = 0, or beta = 0): the loop is block triangular and its
  // spectrum is the union of the master+human block and the slave block; with a slave that
  // does not follow, the master, its human and its wall stand alone (Fig. 14).
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto log_uniform = [&](double lo, double hi) { return lo * std::pow(hi / lo, u(rng)); };
  for (int trial = 0; trial < 45; ++trial) {
    TeleopParams p = bilateral(log_uniform(200.0, 5000.0));
    p.human.fixed = {log_uniform(0.001, 0.5), log_uniform(0.1, 10.0), log_uniform(10.0, 2000.0)};
    p.gains = {log_uniform(10.0, 3000.0),
               log_uniform(10.0, 3000.0),
               log_uniform(0.1, 10.0),
               log_uniform(0.1, 10.0),
               log_uniform(0.1, 3.0),
               log_uniform(0.1, 3.0),
               0.0};
    p.master_fixture.stiffness_N_per_m = log_uniform(10.0, 3000.0);
    p.slave_fixture.stiffness_N_per_m = log_uniform(10.0, 3000.0);
    p.velocity_cutoff_hz = u(rng) < 0.5 ? 0.0 : log_uniform(20.0, 0.4 * p.sample_rate_hz);
    p.round_trip_delay_samples = static_cast<int>(u(rng) * 3.0);
    const int kind = trial % 3;
    if (kind == 0) {
      p.gains.kpm = p.gains.kdm = 0.0;
    } else if (kind == 1) {
      p.scaling.force = 0.0;
    } else {
      p.gains.kps = p.gains.kds = 0.0;
      p.slave_fixture.stiffness_N_per_m = 0.0;
    }
    const LoopEvaluator ev(p);
    const Spectrum got =
        ev.spectrum(0, p.master_fixture.stiffness_N_per_m, p.slave_fixture.stiffness_N_per_m, true);
    const std::string what = "decoupled trial " + std::to_string(trial);
    if (kind == 2) {
      EXPECT_EQ(ev.model().structure(), Structure::kMasterOnly) << what;
      expect_same_spectrum(got, reference::roots(reference::master_polynomial(spec_of(p))), 1e-8,
                           what);
    } else {
      EXPECT_EQ(ev.model().structure(), Structure::kDecoupled) << what;
      expect_same_spectrum(got, reference::roots(reference::bilateral_polynomial(spec_of(p))), 1e-8,
                           what);
    }
  }
}

TEST(Structure, EigenvaluesAt10MicrosecondsAndStiffWallWithin1e9) {
  TeleopParams p = bilateral(100000.0);
  p.slave_fixture.stiffness_N_per_m = 1e5;
  p.master_fixture.stiffness_N_per_m = 1e5;
  const LoopEvaluator ev(p);
  const Spectrum got = ev.spectrum(0, 1e5, 1e5, true);
  const auto want = reference::roots(reference::bilateral_polynomial(spec_of(p)));
  expect_same_spectrum(got, want, 1e-9, "T=10us");
  // s = ln(z)/T loses digits near z = 1; check it too, against the reference's own log.
  for (const Mode& m : got.modes) {
    if (m.structural) continue;
    double best = 1e300;
    for (const auto& c : want) {
      if (abs(c) == 0) continue;
      const reference::Real mag = abs(c);
      const double re = static_cast<double>(log(mag)) / p.period_s();
      const double im = static_cast<double>(atan2(c.imag(), c.real())) / p.period_s();
      best = std::min(best, std::abs(m.s - std::complex<double>(re, im)) / std::abs(m.s));
    }
    EXPECT_LE(best, 1e-9) << m.s;
  }
}

TEST(Structure, PositionScaleDropsOutForceScaleDoesNot) {
  // docs/architecture.md §2.7: alpha only rescales slave coordinates; beta changes the loop gain.
  TeleopParams p = bilateral(1000.0);
  p.slave_fixture.stiffness_N_per_m = 2000.0;
  p.velocity_cutoff_hz = 200.0;
  auto radius = [](const TeleopParams& q) { return analyze(q).spectral_radius; };
  TeleopParams scaled = p;
  scaled.scaling.position = 3.7;
  EXPECT_NEAR(radius(scaled), radius(p), 1e-12);
  scaled.scaling.force = 0.3;
  EXPECT_GT(std::abs(radius(scaled) - radius(p)), 1e-4);
}

TEST(Structure, SymmetricGainsWithoutFilterHaveThreeStructuralZeros) {
  // The paper: "two of them are identically equal to zero"; with K_pm = K_ps, K_dm = K_ds the
  // two backward-difference memories coincide and a third zero appears. They never set the
  // minimum damping ratio or the spectral radius.
  TeleopParams p = bilateral(500.0);
  p.slave_fixture.stiffness_N_per_m = 500.0;
  const AnalysisResult r = analyze(p);
  int structural = 0;
  for (const Mode& m : r.spectrum.modes) structural += m.structural ? 1 : 0;
  EXPECT_EQ(structural, 3);
  const auto want = reference::roots(reference::bilateral_polynomial(spec_of(p)));
  int zero_roots = 0;
  double min_zeta = 2.0;
  for (const auto& c : want) {
    const auto z = reference::to_double(c);
    if (std::abs(z) < 1e-30) {
      ++zero_roots;
      continue;
    }
    const std::complex<double> s = std::log(z) / p.period_s();
    min_zeta = std::min(min_zeta, -s.real() / std::abs(s));
  }
  EXPECT_EQ(zero_roots, 1);  // the reference polynomial has the third zero as a factor z
  EXPECT_NEAR(r.min_damping_ratio, min_zeta, 1e-9);
}

TEST(Structure, MasterUnactuatedAnalysesTheSlaveAloneWithoutAHuman) {
  TeleopParams p = bilateral(500.0);
  p.gains = {0.0, 1000.0, 0.0, 6.0, 0.0, 0.0, 0.0};
  p.human.kind = HumanKind::kBand;
  p.human.band = default_human_band();
  const AnalysisResult r = analyze(p);
  EXPECT_EQ(r.structure, Structure::kSlaveOnly);
  EXPECT_EQ(r.humans_evaluated, 0u);
  EXPECT_FALSE(r.worst_human.has_value());
}

TEST(Structure, NoHumanNoFixtureBilateralHasAMarginalDriftMode) {
  // Nothing holds the pair in place: both move together at z = 1 exactly (physics), which is
  // within numerical error of the unit circle, hence uncertain, not stable.
  TeleopParams p = bilateral(1000.0);
  p.human.kind = HumanKind::kNone;
  EXPECT_EQ(analyze(p).verdict, Verdict::kUncertain);
  // Any wall removes it.
  p.slave_fixture.stiffness_N_per_m = 100.0;
  EXPECT_EQ(analyze(p).verdict, Verdict::kStable);
}

TEST(Structure, UnstableWithoutAnyFixtureHasNoLimitAndSaysWhy) {
  // K_p = 20000 N/m at 250 Hz: the coupling alone is unstable (reference polynomial agrees).
  TeleopParams p = bilateral(250.0);
  p.gains = {20000.0, 20000.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  ASSERT_GT(
      reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
      1.0);
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  EXPECT_FALSE(l.max_stable_stiffness_N_per_m.has_value());
  EXPECT_NE(l.reason.find("unstable with no fixture"), std::string::npos) << l.reason;
}

TEST(Structure, RequiredDampingRatioLowersTheLimitToWhereZetaReachesIt) {
  TeleopParams p = bilateral(1000.0);
  const double free = max_stable_stiffness(p, Side::kSlave).max_stable_stiffness_N_per_m.value();
  p.analysis.required_damping_ratio = 0.05;
  const double k = max_stable_stiffness(p, Side::kSlave).max_stable_stiffness_N_per_m.value();
  EXPECT_LT(k, free);
  auto min_zeta_at = [&](double stiffness) {
    TeleopParams q = p;
    q.slave_fixture.stiffness_N_per_m = stiffness;
    double zeta = 2.0;
    for (const auto& c : reference::roots(reference::bilateral_polynomial(spec_of(q)))) {
      const auto z = reference::to_double(c);
      if (std::abs(z) < 1e-30) continue;
      const std::complex<double> s = std::log(z) / q.period_s();
      zeta = std::min(zeta, -s.real() / std::abs(s));
    }
    return zeta;
  };
  EXPECT_GE(min_zeta_at(k), 0.05);
  EXPECT_LT(min_zeta_at(k + 2.0), 0.05);
}

TEST(Structure, EveryStiffnessBelowTheLimitIsStableForEveryHuman) {
  // A loop where some humans have an unstable window of slave stiffness far below the limit
  // of the human that is worst at K = 0 (found by review): the limit must sit below the
  // window, and the reference must find every human stable at and under it.
  TeleopParams p = bilateral(1965.6531595361166);
  p.master_device = {0.035168908321713058, 0.27413738179978181};
  p.slave_device = {0.093385542338318667, 0.10405426286668194};
  p.gains = {875.68246002050751,
             315.39271075939166,
             0.66813178485707292,
             8.5794694258662147,
             0.0,
             0.84658348620484158,
             0.0};
  p.human.kind = HumanKind::kBand;
  p.human.band = default_human_band();
  p.human.band.points_per_axis = 2;
  const double limit = max_stable_stiffness(p, Side::kSlave).max_stable_stiffness_N_per_m.value();
  bool window_seen = false;
  for (const double k : {limit / 8.0, limit / 2.0, limit, 2000.0}) {
    for (const auto& h : human_samples(p.human)) {
      TeleopParams q = p;
      q.human.kind = HumanKind::kFixed;
      q.human.fixed = h.impedance;
      q.slave_fixture.stiffness_N_per_m = k;
      const double radius =
          reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(q))));
      if (k <= limit) {
        EXPECT_LT(radius, 1.0) << "K=" << k << " m_h=" << h.impedance.mass_kg;
      } else {
        window_seen = window_seen || radius > 1.0;
      }
    }
  }
  EXPECT_TRUE(window_seen) << "the reference finds no unstable human at 2000 N/m";
  EXPECT_LT(limit, 2000.0);
}

TEST(Structure, BandWorstCaseIsTheMinimumOverItsHumans) {
  TeleopParams p = bilateral(500.0);
  p.slave_fixture.stiffness_N_per_m = 1500.0;
  p.human.kind = HumanKind::kBand;
  p.human.band = default_human_band();
  p.human.band.points_per_axis = 2;
  const AnalysisResult band = analyze(p);
  ASSERT_TRUE(band.worst_human.has_value());
  EXPECT_EQ(band.humans_evaluated, 7u * 8u);
  // Brute force with the reference polynomial over the same 56 humans.
  double min_zeta = 2.0;
  HumanImpedance worst{};
  for (const double f : p.human.band.force_levels_N) {
    for (const double m : {0.003, 0.012}) {
      for (const double b : {0.6 + 0.08 * f, 2.0 + 0.25 * f}) {
        for (const double k : {50.0 + 10.0 * f, 100.0 + 45.0 * f}) {
          TeleopParams q = p;
          q.human.kind = HumanKind::kFixed;
          q.human.fixed = {m, b, k};
          for (const auto& c : reference::roots(reference::bilateral_polynomial(spec_of(q)))) {
            const auto z = reference::to_double(c);
            if (std::abs(z) < 1e-30) continue;
            const std::complex<double> s = std::log(z) / q.period_s();
            const double zeta = -s.real() / std::abs(s);
            if (zeta < min_zeta) {
              min_zeta = zeta;
              worst = q.human.fixed;
            }
          }
        }
      }
    }
  }
  EXPECT_NEAR(band.min_damping_ratio, min_zeta, 1e-9);
  EXPECT_DOUBLE_EQ(band.worst_human->impedance.mass_kg, worst.mass_kg);
  EXPECT_DOUBLE_EQ(band.worst_human->impedance.damping_Ns_per_m, worst.damping_Ns_per_m);
  EXPECT_DOUBLE_EQ(band.worst_human->impedance.stiffness_N_per_m, worst.stiffness_N_per_m);
}

}  // namespace
}  // namespace teleop::stability
