// The supervisor's analysis of the running teleoperator (issue 5): the configured model with
// what the nodes really run now — the measured sample rate, the measured round trip rounded up
// to whole samples, the gains and fixtures in force — its verdict, minimum damping ratio,
// worst human and the largest stable fixture stiffness on each side; and the guard that
// predicts a parameter change before it is applied.
#pragma once

#include <optional>
#include <string>

#include "common/core/teleop_params.hpp"
#include "common/stability/human_grid.hpp"
#include "common/stability/stiffness_search.hpp"
#include "common/stability/verdict.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {

// What the running system changes in the configured model.
struct LiveInputs {
  double sample_rate_hz{0.0};
  int round_trip_samples{0};
  Gains gains{};
  double master_fixture_N_per_m{0.0};
  double slave_fixture_N_per_m{0.0};

  [[nodiscard]] bool operator==(const LiveInputs& o) const {
    const Gains& a = gains;
    const Gains& b = o.gains;
    return sample_rate_hz == o.sample_rate_hz && round_trip_samples == o.round_trip_samples &&
           a.kpm == b.kpm && a.kps == b.kps && a.kdm == b.kdm && a.kds == b.kds && a.kvm == b.kvm &&
           a.kvs == b.kvs && a.kfm == b.kfm && master_fixture_N_per_m == o.master_fixture_N_per_m &&
           slave_fixture_N_per_m == o.slave_fixture_N_per_m;
  }
};

struct Assessment {
  LiveInputs inputs{};
  stability::Verdict verdict{stability::Verdict::kStable};
  double min_damping_ratio{1.0};
  double required_damping_ratio{0.0};
  std::optional<stability::HumanSample> worst_human{};
  std::optional<double> max_master_N_per_m{};
  std::optional<double> max_slave_N_per_m{};
  // The nearest stiffness below and above the fixture in force at which some human's mode
  // meets the admissible boundary (docs/stability-limits.md), per side.
  stability::NearestCrossings master_crossings{};
  stability::NearestCrossings slave_crossings{};
  // Why the verdict is invalid (a non-finite model), empty otherwise.
  std::string invalid_reason{};
  // True when the verdict is stable and every mode meets the required damping ratio.
  [[nodiscard]] bool acceptable() const;
  // 1 - configured / maximum (empty without a finite maximum or a fixture).
  [[nodiscard]] std::optional<double> master_margin() const;
  [[nodiscard]] std::optional<double> slave_margin() const;
};

struct ChangeRequest {
  std::optional<Gains> gains{};
  std::optional<double> master_fixture_N_per_m{};
  std::optional<double> slave_fixture_N_per_m{};
};

struct Decision {
  bool accepted{false};
  std::string reason{};
  LiveInputs proposed{};
  Assessment prediction{};
};

class StabilityGuard {
 public:
  // The configured teleoperator (to_teleop_params of the file the nodes run).
  explicit StabilityGuard(TeleopParams configured);

  // The configured inputs: the file's rate, gains and fixtures, its round trip.
  [[nodiscard]] LiveInputs configured_inputs() const;

  // Analysis with these inputs (cached: the same inputs are not analysed again).
  [[nodiscard]] const Assessment& assess(const LiveInputs& inputs);

  // Predicts `change` on top of `current`: accepted only when the prediction is stable, not
  // uncertain, and meets the required damping ratio; the reason says why not, with numbers.
  [[nodiscard]] Decision check(const LiveInputs& current, const ChangeRequest& change);

  // The fixture stiffness to fall back to on `side` when the system misbehaves: `fraction` of
  // the stiffness in force, never above `fraction` of the predicted maximum.
  [[nodiscard]] double lowered_stiffness(const LiveInputs& current, bool slave_side,
                                         double fraction);

  [[nodiscard]] TeleopParams params_for(const LiveInputs& inputs) const;

  // Why the ramp from `from` to `to` may leave the admissible region (empty when it cannot):
  // fixtures exactly, gains at kGainRampPoints - 1 intermediate points.
  [[nodiscard]] std::string path_refusal(const LiveInputs& from, const LiveInputs& to);
  static constexpr int kGainRampPoints = 16;

  // The inputs as the ParameterUpdate a node would be sent (fixture positions configured),
  // for config::check_parameter_update.
  [[nodiscard]] v1::ParameterUpdate to_update(const LiveInputs& inputs) const;

 private:
  TeleopParams configured_;
  std::optional<Assessment> cached_{};
};

}  // namespace teleop::supervisor
