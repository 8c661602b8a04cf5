#include "common/stability/stiffness_search.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "common/stability/analyzer.hpp"

namespace teleop::stability {

namespace {

struct Searcher {
  const SideSearch& search;
  long evaluations{0};

  bool passes(std::size_t human, double k) {
    ++evaluations;
    const Spectrum s = search.ev.spectrum(human, search.master_k(k), search.slave_k(k), false);
    return s.verdict == Verdict::kStable && s.min_damping_ratio >= search.required;
  }
};

}  // namespace

SideSearch::SideSearch(const TeleopParams& p, Side s)
    : params(p),
      side(s),
      ev(p, s == Side::kMaster, s == Side::kSlave),
      other_N_per_m(s == Side::kMaster ? p.slave_fixture.stiffness_N_per_m
                                       : p.master_fixture.stiffness_N_per_m),
      required(p.analysis.required_damping_ratio),
      tolerance_N_per_m(p.analysis.stiffness_tolerance_N_per_m) {}

StiffnessLimit SideSearch::start_limit() const {
  StiffnessLimit out;
  out.other_fixture_N_per_m = other_N_per_m;
  if (side != Side::kMaster) return out;
  out.passivity_limit_N_per_m = master_passivity_limit(params);
  if (!out.passivity_limit_N_per_m) {
    out.passivity_reason =
        "not passive at any stiffness: the master's virtual damping |beta kdm + kvm| is not "
        "below its device damping b";
  }
  return out;
}

std::string lower_end_failure(const BandResult& r, double required, Side side, double other) {
  const char* name = side == Side::kMaster ? "master" : "slave";
  const std::string with_other =
      other == 0.0 ? std::string("no fixture at all")
                   : fmt::format("no {} fixture (the {} fixture at {:g} N/m as configured)", name,
                                 side == Side::kMaster ? "slave" : "master", other);
  if (r.verdict == Verdict::kInvalid) {
    return fmt::format("invalid model with {}: {}", with_other, r.invalid_reason);
  }
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

std::optional<LowerEnd> find_lower_end(const std::function<BandResult(double)>& band,
                                       const SideSearch& search, StiffnessLimit& out) {
  const double required = search.required;
  // With no restoring force at all (no human spring, no coupling) a free mass has a
  // rigid-body mode at z = 1: marginal at K = 0 exactly, so start just above it.
  const BandResult at_zero = band(0.0);
  if (meets_requirement(at_zero, required)) return LowerEnd{0.0, at_zero};
  if (at_zero.verdict == Verdict::kUncertain) {
    const BandResult tiny = band(search.tolerance_N_per_m);
    if (meets_requirement(tiny, required)) {
      out.reason = "marginal rigid-body mode at zero stiffness; limit taken over (0, K]";
      return LowerEnd{search.tolerance_N_per_m, tiny};
    }
  }
  out.reason = lower_end_failure(at_zero, required, search.side, search.other_N_per_m);
  out.invalid = at_zero.verdict == Verdict::kInvalid;
  if (search.ev.human_matters()) {
    out.worst_human = search.ev.human(at_zero.failing_index.value_or(0));
  }
  return std::nullopt;
}

std::optional<double> master_passivity_limit(const TeleopParams& p) {
  const double beta = p.scaling.force;
  const double virtual_damping = std::abs(beta * p.gains.kdm + p.gains.kvm);
  const double b = p.master_device.damping_Ns_per_m;
  if (b <= virtual_damping) return std::nullopt;  // not passive at any stiffness
  return std::max(0.0, 2.0 * (b - virtual_damping) / p.period_s() - beta * p.gains.kpm);
}

StiffnessLimit max_stable_stiffness_scan(const TeleopParams& params, Side side,
                                         const SearchOptions& options) {
  const SideSearch search(params, side);
  const LoopEvaluator& ev = search.ev;
  const double required = search.required;
  const double tol = search.tolerance_N_per_m;
  Searcher s{search};
  StiffnessLimit out = search.start_limit();
  auto finish = [&]() -> StiffnessLimit& {
    out.evaluations = s.evaluations;
    return out;
  };
  auto band = [&](double k) {
    ++out.band_verifications;
    return search.band(k);
  };

  const std::optional<LowerEnd> lower = find_lower_end(band, search, out);
  if (!lower) return finish();
  const double k_lo = lower->stiffness_N_per_m;
  const BandResult& lo_band = lower->band;

  std::size_t human = lo_band.worst_index;
  double ceiling = options.max_stiffness_N_per_m;  // known to fail for `human` (or the cap)
  bool ceiling_fails = false;
  // Each round either returns or moves the ceiling down to a stiffness where some human fails.
  for (int round = 0; round < 64; ++round) {
    // Geometric scan from the known-good lower end for this human.
    double pass = k_lo;
    double fail = -1.0;
    for (double k = std::max(k_lo, tol);; k *= options.growth) {
      if (k >= ceiling) {
        if (ceiling_fails || !s.passes(human, ceiling)) fail = ceiling;
        break;
      }
      if (!s.passes(human, k)) {
        fail = k;
        break;
      }
      pass = k;
    }
    if (fail < 0.0) {
      // This human meets the requirement up to the cap; the band decides.
      const BandResult at_cap = band(ceiling);
      if (meets_requirement(at_cap, required)) {
        out.reason = fmt::format("meets the requirement for every stiffness up to {:g} N/m",
                                 options.max_stiffness_N_per_m);
        return finish();
      }
      human = at_cap.failing_index.value_or(at_cap.worst_index);
      ceiling_fails = true;
      continue;
    }
    // Bisection to the tolerance, or until the midpoint no longer moves in floating point.
    while (fail - pass > tol) {
      const double mid = 0.5 * (pass + fail);
      if (mid <= pass || mid >= fail) break;
      if (s.passes(human, mid)) {
        pass = mid;
      } else {
        fail = mid;
      }
    }
    // Verify over the whole band: at the answer and at halvings below it, so that another
    // human's unstable window under this human's limit is not missed.
    std::optional<std::pair<double, std::size_t>> failure;
    for (double k = pass; k > k_lo && k >= pass / 128.0; k *= 0.5) {
      const BandResult check = band(k);
      if (!meets_requirement(check, required)) {
        failure = std::pair{k, check.failing_index.value_or(check.worst_index)};
        break;
      }
    }
    if (!failure) {
      out.max_stable_stiffness_N_per_m = pass;
      if (ev.human_matters()) out.worst_human = ev.human(human);
      return finish();
    }
    // Another human fails there: search again on that one, under that stiffness.
    human = failure->second;
    ceiling = failure->first;
    ceiling_fails = true;
  }
  out.reason = "the search did not converge over the human band";
  return finish();
}

}  // namespace teleop::stability
