#include "supervisor/core/stability_guard.hpp"

#include <fmt/core.h>

#include <cmath>

#include "common/config/parameter_space.hpp"
#include "common/stability/analyzer.hpp"
#include "common/stability/stiffness_search.hpp"

namespace teleop::supervisor {

bool Assessment::acceptable() const {
  return verdict == stability::Verdict::kStable && min_damping_ratio >= required_damping_ratio;
}

std::optional<double> Assessment::master_margin() const {
  if (!max_master_N_per_m || *max_master_N_per_m <= 0.0) return std::nullopt;
  return 1.0 - inputs.master_fixture_N_per_m / *max_master_N_per_m;
}

std::optional<double> Assessment::slave_margin() const {
  if (!max_slave_N_per_m || *max_slave_N_per_m <= 0.0) return std::nullopt;
  return 1.0 - inputs.slave_fixture_N_per_m / *max_slave_N_per_m;
}

v1::ParameterUpdate StabilityGuard::to_update(const LiveInputs& in) const {
  v1::ParameterUpdate u;
  v1::Gains& g = *u.mutable_gains();
  g.set_kpm(in.gains.kpm);
  g.set_kps(in.gains.kps);
  g.set_kdm(in.gains.kdm);
  g.set_kds(in.gains.kds);
  g.set_kvm(in.gains.kvm);
  g.set_kvs(in.gains.kvs);
  g.set_kfm(in.gains.kfm);
  u.set_master_fixture_stiffness_n_per_m(in.master_fixture_N_per_m);
  u.set_master_fixture_position_m(configured_.master_fixture.position_m);
  u.set_slave_fixture_stiffness_n_per_m(in.slave_fixture_N_per_m);
  u.set_slave_fixture_position_m(configured_.slave_fixture.position_m);
  return u;
}

StabilityGuard::StabilityGuard(TeleopParams configured) : configured_(std::move(configured)) {}

LiveInputs StabilityGuard::configured_inputs() const {
  LiveInputs in;
  in.sample_rate_hz = configured_.sample_rate_hz;
  in.round_trip_samples = configured_.round_trip_delay_samples;
  in.gains = configured_.gains;
  in.master_fixture_N_per_m = configured_.master_fixture.stiffness_N_per_m;
  in.slave_fixture_N_per_m = configured_.slave_fixture.stiffness_N_per_m;
  return in;
}

TeleopParams StabilityGuard::params_for(const LiveInputs& in) const {
  TeleopParams p = configured_;
  p.sample_rate_hz = in.sample_rate_hz;
  p.round_trip_delay_samples = in.round_trip_samples;
  p.gains = in.gains;
  p.master_fixture.stiffness_N_per_m = in.master_fixture_N_per_m;
  p.slave_fixture.stiffness_N_per_m = in.slave_fixture_N_per_m;
  return p;
}

const Assessment& StabilityGuard::assess(const LiveInputs& in) {
  if (cached_ && cached_->inputs == in) return *cached_;
  const TeleopParams p = params_for(in);
  const stability::AnalysisResult r = stability::analyze(p);
  Assessment a;
  a.inputs = in;
  a.verdict = r.verdict;
  a.min_damping_ratio = r.min_damping_ratio;
  a.required_damping_ratio = p.analysis.required_damping_ratio;
  a.worst_human = r.worst_human;
  a.invalid_reason = r.invalid_reason;
  // The limits only where a fixture is used (skip what the scene does not need).
  if (in.master_fixture_N_per_m > 0.0) {
    const stability::StiffnessLimit l =
        stability::max_stable_stiffness(p, stability::Side::kMaster);
    a.max_master_N_per_m = l.max_stable_stiffness_N_per_m;
    a.master_crossings = stability::nearest_crossings(l, in.master_fixture_N_per_m);
  }
  if (in.slave_fixture_N_per_m > 0.0) {
    const stability::StiffnessLimit l = stability::max_stable_stiffness(p, stability::Side::kSlave);
    a.max_slave_N_per_m = l.max_stable_stiffness_N_per_m;
    a.slave_crossings = stability::nearest_crossings(l, in.slave_fixture_N_per_m);
  }
  cached_ = a;
  return *cached_;
}

Decision StabilityGuard::check(const LiveInputs& current, const ChangeRequest& change) {
  Decision d;
  d.proposed = current;
  if (change.gains) d.proposed.gains = *change.gains;
  if (change.master_fixture_N_per_m)
    d.proposed.master_fixture_N_per_m = *change.master_fixture_N_per_m;
  if (change.slave_fixture_N_per_m)
    d.proposed.slave_fixture_N_per_m = *change.slave_fixture_N_per_m;
  // The one parameter space first (the rules a node applies to the same update): nothing
  // non-finite, negative or beyond the documented ceilings reaches the analyser.
  if (const std::string why = config::check_parameter_update(to_update(d.proposed)); !why.empty()) {
    d.reason = "refused: " + why;
    d.prediction.inputs = d.proposed;
    d.prediction.required_damping_ratio = configured_.analysis.required_damping_ratio;
    d.prediction.verdict = stability::Verdict::kInvalid;
    d.prediction.invalid_reason = why;
    d.prediction.min_damping_ratio = std::nan("");
    return d;
  }
  d.prediction = assess(d.proposed);
  const Assessment& a = d.prediction;
  if (a.verdict == stability::Verdict::kInvalid) {
    d.reason = "refused: the analyser cannot evaluate the model (" + a.invalid_reason + ")";
  } else if (a.verdict == stability::Verdict::kUnstable) {
    d.reason = fmt::format(
        "refused: the analyser predicts an unstable teleoperator (minimum damping ratio {:.4f}, "
        "round trip {} samples)",
        a.min_damping_ratio, current.round_trip_samples);
  } else if (a.verdict == stability::Verdict::kUncertain) {
    d.reason =
        "refused: the analyser's verdict is uncertain (an eigenvalue within its error "
        "bound of the unit circle)";
  } else if (!(a.min_damping_ratio >= a.required_damping_ratio)) {  // NaN fails too
    d.reason =
        fmt::format("refused: predicted minimum damping ratio {:.4f} is below the required {:.4f}",
                    a.min_damping_ratio, a.required_damping_ratio);
  } else if (const std::string why = path_refusal(current, d.proposed); !why.empty()) {
    d.reason = "refused: " + why;
  } else {
    d.accepted = true;
    d.reason = fmt::format("accepted: predicted minimum damping ratio {:.4f} (required {:.4f})",
                           a.min_damping_ratio, a.required_damping_ratio);
  }
  return d;
}

// A change ramps from what is in force to what is asked (docs/stability-limits.md). A
// fixture's ramp is checked exactly: the limit L is the first stiffness at which any mode
// leaves the admissible region, so [0, L] is admissible and nothing above L is reachable
// without crossing L. A ramp is accepted when it ends at or below L and starts there too. A
// target above L, or a start in a stable window above L, is refused even when the end point
// alone is stable; so is a fixture ramp where no stiffness from 0 up is admissible with the
// other settings (L does not exist). When what is in force is itself not admissible (the
// guard's own lowering after the round trip grew), the ramp is a rescue into the region and
// only its end point, checked before, counts. Gains, and two fixtures changing together,
// enter the loop jointly: that ramp is analysed at kGainRampPoints - 1 evenly spaced
// intermediate points, a resolution and not a proof.
std::string StabilityGuard::path_refusal(const LiveInputs& from, const LiveInputs& to) {
  const double required = configured_.analysis.required_damping_ratio;
  auto admissible = [&](const LiveInputs& in) {
    const stability::AnalysisResult r = stability::analyze(params_for(in));
    return r.verdict == stability::Verdict::kStable && r.min_damping_ratio >= required;
  };
  if (!admissible(from)) return {};
  int fixtures_changing = 0;
  for (const bool slave : {false, true}) {
    const double a = slave ? from.slave_fixture_N_per_m : from.master_fixture_N_per_m;
    const double b = slave ? to.slave_fixture_N_per_m : to.master_fixture_N_per_m;
    if (a == b) continue;
    ++fixtures_changing;
    if (!(std::max(a, b) > 0.0)) continue;
    const stability::StiffnessLimit l = stability::max_stable_stiffness(
        params_for(to), slave ? stability::Side::kSlave : stability::Side::kMaster);
    const char* name = slave ? "slave" : "master";
    if (!l.max_stable_stiffness_N_per_m) {
      if (l.reason.rfind("meets the requirement for every stiffness", 0) == 0) continue;
      return fmt::format(
          "the {} fixture's ramp from {:g} to {:g} N/m cannot be shown admissible: {}", name, a, b,
          l.reason);
    }
    const double limit = *l.max_stable_stiffness_N_per_m;
    if (b > limit) {
      return fmt::format(
          "the {} fixture's ramp from {:g} to {:g} N/m passes {:g} N/m, where a mode leaves the "
          "admissible region (every stiffness up to there is admissible)",
          name, a, b, limit);
    }
    if (a > limit) {
      return fmt::format(
          "the {} fixture's ramp from {:g} to {:g} N/m passes {:g} N/m: {:g} N/m lies in a stable "
          "window above an unstable one",
          name, a, b, limit, a);
    }
  }
  if (from.gains == to.gains && fixtures_changing < 2) return {};
  for (int i = 1; i < kGainRampPoints; ++i) {
    const double f = static_cast<double>(i) / kGainRampPoints;
    auto mix = [f](double x, double y) { return x + f * (y - x); };
    LiveInputs mid = to;
    mid.gains.kpm = mix(from.gains.kpm, to.gains.kpm);
    mid.gains.kps = mix(from.gains.kps, to.gains.kps);
    mid.gains.kdm = mix(from.gains.kdm, to.gains.kdm);
    mid.gains.kds = mix(from.gains.kds, to.gains.kds);
    mid.gains.kvm = mix(from.gains.kvm, to.gains.kvm);
    mid.gains.kvs = mix(from.gains.kvs, to.gains.kvs);
    mid.gains.kfm = mix(from.gains.kfm, to.gains.kfm);
    mid.master_fixture_N_per_m = mix(from.master_fixture_N_per_m, to.master_fixture_N_per_m);
    mid.slave_fixture_N_per_m = mix(from.slave_fixture_N_per_m, to.slave_fixture_N_per_m);
    const stability::AnalysisResult r = stability::analyze(params_for(mid));
    if (!(r.verdict == stability::Verdict::kStable && r.min_damping_ratio >= required)) {
      return fmt::format(
          "the ramp to the new values is {} {:.0f} % of the way (minimum damping ratio {:.4f})",
          stability::to_string(r.verdict), 100.0 * f, r.min_damping_ratio);
    }
  }
  return {};
}

double StabilityGuard::lowered_stiffness(const LiveInputs& current, bool slave_side,
                                         double fraction) {
  const Assessment& a = assess(current);
  const double now = slave_side ? current.slave_fixture_N_per_m : current.master_fixture_N_per_m;
  double target = fraction * now;
  const std::optional<double> max = slave_side ? a.max_slave_N_per_m : a.max_master_N_per_m;
  if (max) target = std::min(target, fraction * *max);
  return std::max(0.0, target);
}

}  // namespace teleop::supervisor
