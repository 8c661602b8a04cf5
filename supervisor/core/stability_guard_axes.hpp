// The supervisor's guard for an n-axis teleoperator (issue 18 "Everything above the law"): a
// proposed change of gains or fixture planes is analysed with the n-axis worst-case analysis
// (analyze_axes, worst case over the human band of every axis) before it is applied, and every
// plane in use is reported against its exact stiffness limit (plane_stiffness_limit), so the
// console can say "slave plane 1: 40 % of its limit". The decisions are worded as the one-axis
// StabilityGuard's ("refused: ..." / "accepted: ..."), naming the plane or gain that decides.
//
// Not on the real-time path: it analyses (tens of microseconds to milliseconds) and allocates.
#pragma once

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "common/core/teleop_axes.hpp"
#include "common/stability/analysis_axes.hpp"
#include "common/stability/human_grid.hpp"
#include "common/stability/stiffness_search.hpp"
#include "common/stability/verdict.hpp"

namespace teleop::supervisor {

// One plane in use (non-zero stiffness) against its exact limit, the other planes held at
// theirs.
struct PlaneMargin {
  stability::Side side{stability::Side::kMaster};
  std::size_t plane{0};  // index into the side's planes
  double stiffness_N_per_m{0.0};
  std::optional<double> max_stable_N_per_m{};  // empty: no finite limit (reason says why)
  std::string reason{};
  bool uncertain{false};  // the limit stands on a crossing within the numerical error
  // stiffness / limit, and 1 - that (as Assessment::master_margin); empty without a limit.
  [[nodiscard]] std::optional<double> fraction_of_limit() const;
  [[nodiscard]] std::optional<double> margin() const;
  // "slave plane 1: 40 % of its limit (1200 of 3000 N/m)", or "... no finite limit (why)".
  [[nodiscard]] std::string describe() const;
};

struct AxesAssessment {
  stability::Verdict verdict{stability::Verdict::kInvalid};
  double min_damping_ratio{0.0};                      // NaN when invalid
  double required_damping_ratio{0.0};                 // the guard's margin
  std::vector<stability::HumanSample> worst_human{};  // per axis; empty when it does not matter
  std::vector<PlaneMargin> planes{};                  // master's planes in use, then slave's
  std::optional<std::size_t> limiting_plane{};        // index into planes: the largest fraction
  std::string invalid_reason{};  // why the verdict is invalid, naming the field
  // Stable and every mode meets the required damping ratio (NaN never does).
  [[nodiscard]] bool acceptable() const;
};

struct AxesGuardOptions {
  // The damping ratio a change must keep; empty: the current configuration's
  // analysis.required_damping_ratio (a proposal cannot lower its own bar).
  std::optional<double> required_damping_ratio{};
  stability::AxesAnalysisOptions analysis{};  // plane_limits is always set by the guard
};

struct AxesDecision {
  bool accepted{false};
  std::string reason{};
  std::vector<std::string> changed{};  // the fields that differ, e.g. "gains.kps[0,0]"
  AxesAssessment prediction{};
};

// The analysis of `params` with every plane's limit. Never throws for a bad configuration:
// invalid, with the reason. `required_damping_ratio` as in AxesGuardOptions.
[[nodiscard]] AxesAssessment assess_axes(const TeleopAxesParams& params,
                                         double required_damping_ratio,
                                         const stability::AxesAnalysisOptions& options = {});

// Empty when every numeric field of `params` is finite and within the one parameter space's
// range (common/config/parameter_space.hpp: the same ceilings as the n-axis configuration
// fields, far below what overflows the model), else the first problem, naming the field.
[[nodiscard]] std::string check_axes_ranges(const TeleopAxesParams& params);

// Predicts `proposed` in place of `current`. Refused, with the reason: a proposal with a
// different number of axes or planes, a different sample rate, devices, plane normals or
// offsets, round trip or human (what a parameter change cannot alter live), any non-finite or
// out-of-range value; a verdict that is invalid, unstable or uncertain; a worst-case minimum
// damping ratio below the required one; a ramp from `current` that leaves the admissible
// region, as StabilityGuard::path_refusal decides for one axis (a plane's ramp exactly against
// its limit, gains at intermediate points; none when `current` is itself not admissible: the
// change is then a rescue). The reason names the plane above its limit, else the gains that
// changed, else the plane closest to its limit.
[[nodiscard]] AxesDecision assess_axes_change(const TeleopAxesParams& current,
                                              const TeleopAxesParams& proposed,
                                              const AxesGuardOptions& options = {});

}  // namespace teleop::supervisor
