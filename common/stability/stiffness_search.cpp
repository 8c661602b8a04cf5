#include "common/stability/stiffness_search.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "common/stability/analyzer.hpp"

namespace teleop::stability {

namespace {

struct Searcher {
  const LoopEvaluator& ev;
  Side side;
  double other_stiffness;
  double required;
  long evaluations{0};

  [[nodiscard]] double kmvf(double k) const { return side == Side::kMaster ? k : other_stiffness; }
  [[nodiscard]] double ksvf(double k) const { return side == Side::kSlave ? k : other_stiffness; }

  bool passes(std::size_t human, double k) {
    ++evaluations;
    const Spectrum s = ev.spectrum(human, kmvf(k), ksvf(k), false);
    return s.verdict == Verdict::kStable && s.min_damping_ratio >= required;
  }
  BandResult band(double k) const { return ev.sweep(kmvf(k), ksvf(k)); }
};

std::string describe_failure(const BandResult& r, double required, Side side, double other) {
  const char* name = side == Side::kMaster ? "master" : "slave";
  const std::string with_other =
      other == 0.0 ? std::string("no fixture at all")
                   : fmt::format("no {} fixture (the {} fixture at {:g} N/m as configured)", name,
                                 side == Side::kMaster ? "slave" : "master", other);
  if (r.verdict == Verdict::kUnstable) {
    return fmt::format("unstable with {} (minimum damping ratio {:.4g})", with_other,
                       r.min_damping_ratio);
  }
  if (r.verdict == Verdict::kUncertain) {
    return fmt::format(
        "marginal with {}: an eigenvalue lies on the unit circle within the "
        "numerical error",
        with_other);
  }
  return fmt::format(
      "with {} the minimum damping ratio {:.4g} is already below the required {:.4g}", with_other,
      r.min_damping_ratio, required);
}

}  // namespace

double master_passivity_limit(const TeleopParams& p) {
  const double beta = p.scaling.force;
  const double virtual_damping = std::abs(beta * p.gains.kdm + p.gains.kvm);
  const double limit = 2.0 * (p.master_device.damping_Ns_per_m - virtual_damping) / p.period_s() -
                       beta * p.gains.kpm;
  return std::max(0.0, limit);
}

StiffnessLimit max_stable_stiffness(const TeleopParams& params, Side side,
                                    const SearchOptions& options) {
  const LoopEvaluator ev(params, side == Side::kMaster);
  const double other = side == Side::kMaster ? params.slave_fixture.stiffness_N_per_m
                                             : params.master_fixture.stiffness_N_per_m;
  const double required = params.analysis.required_damping_ratio;
  const double tol = params.analysis.stiffness_tolerance_N_per_m;
  Searcher s{ev, side, other, required};
  StiffnessLimit out;
  if (side == Side::kMaster) out.passivity_limit_N_per_m = master_passivity_limit(params);

  // The lower end. With no restoring force at all (no human spring, no coupling) a free
  // mass has a rigid-body mode at z = 1: marginal at K = 0 exactly, so start just above it.
  BandResult lo_band = s.band(0.0);
  ++out.band_verifications;
  double k_lo = 0.0;
  if (!meets_requirement(lo_band, required)) {
    const BandResult tiny = s.band(tol);
    ++out.band_verifications;
    if (lo_band.verdict != Verdict::kUnstable && meets_requirement(tiny, required)) {
      k_lo = tol;
      out.reason = "marginal rigid-body mode at zero stiffness; limit taken over (0, K]";
      lo_band = tiny;
    } else {
      out.reason = describe_failure(lo_band, required, side, other);
      if (ev.human_matters()) out.worst_human = ev.human(lo_band.worst_index);
      out.evaluations = s.evaluations;
      return out;
    }
  }

  std::size_t human = lo_band.worst_index;
  double ceiling = options.max_stiffness_N_per_m;  // known to fail for some human (or the cap)
  bool ceiling_fails = false;
  for (std::size_t round = 0; round <= ev.human_count(); ++round) {
    // Geometric scan from the known-good lower end for this human.
    double pass = k_lo;
    double fail = -1.0;
    double k = std::max(k_lo, tol);
    while (true) {
      if (k >= ceiling) {
        if (ceiling_fails || !s.passes(human, ceiling)) fail = ceiling;
        break;
      }
      if (!s.passes(human, k)) {
        fail = k;
        break;
      }
      pass = k;
      k *= options.growth;
    }
    if (fail < 0.0) {
      // This human meets the requirement up to the cap; the band decides.
      const BandResult at_cap = s.band(ceiling);
      ++out.band_verifications;
      if (meets_requirement(at_cap, required)) {
        out.reason = fmt::format("meets the requirement for every stiffness up to {:g} N/m",
                                 options.max_stiffness_N_per_m);
        out.evaluations = s.evaluations;
        return out;
      }
      human = at_cap.worst_index;
      ceiling_fails = true;
      continue;
    }
    while (fail - pass > tol) {
      const double mid = 0.5 * (pass + fail);
      if (s.passes(human, mid)) {
        pass = mid;
      } else {
        fail = mid;
      }
    }
    const BandResult check = s.band(pass);
    ++out.band_verifications;
    if (meets_requirement(check, required)) {
      out.max_stable_stiffness_N_per_m = pass;
      if (ev.human_matters()) out.worst_human = ev.human(human);
      out.evaluations = s.evaluations;
      return out;
    }
    // Another human fails below this human's limit: search again on that one, under `pass`.
    human = check.worst_index;
    ceiling = pass;
    ceiling_fails = true;
  }
  out.reason = "the search did not converge over the human band";
  out.evaluations = s.evaluations;
  return out;
}

}  // namespace teleop::stability
