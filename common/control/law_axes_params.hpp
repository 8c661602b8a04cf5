// Parameters of the n-axis control core (issue 18 "Law"; docs/architecture.md §2.3 "n axes"):
// the three-channel law with gain matrices and plane fixtures, per-axis actuator limits and the
// slave's workspace box. The vector form of law_params.hpp: `to_law_axes(LawParams)` is the
// one-axis law as n = 1. Plain data in fixed-capacity storage (retune() copies gains and planes
// on the RT thread); validate() is setup code and may throw.
#pragma once

#include "common/control/law_params.hpp"
#include "common/control/plane_fixtures.hpp"
#include "common/core/teleop_axes.hpp"

namespace teleop::control {

// Eqs. 8-9's gains as n x n matrices: kp* N/m, kd*/kv* N s/m, kfm dimensionless.
struct LawGainsAxes {
  AxisMatrix kpm{};
  AxisMatrix kps{};
  AxisMatrix kdm{};
  AxisMatrix kds{};
  AxisMatrix kvm{};
  AxisMatrix kvs{};
  AxisMatrix kfm{};
};

// One actuator per task axis. Infinite means no limit.
struct ActuatorLimitsAxes {
  AxisVector max_force_N{};       // |F_i| <= max_force_N[i]
  AxisVector max_rate_N_per_s{};  // |F_i(k) - F_i(k-1)| <= max_rate_N_per_s[i] * T
};

// The slave's workspace as a box in slave task coordinates, and its speed and force per axis.
struct SlaveLimitsAxes {
  AxisVector min_position_m{};
  AxisVector max_position_m{};
  AxisVector max_velocity_m_per_s{};  // on each axis's filtered velocity
  AxisVector max_force_N{};
};

struct LawAxesParams {
  int axes{1};
  double period_s{0.0};
  LawGainsAxes gains{};
  Scaling scaling{};  // alpha and beta, the same on every axis
  PlaneSet master_planes{};
  PlaneSet slave_planes{};
  double velocity_cutoff_hz{0.0};  // 0: plain backward difference, every axis
  ActuatorLimitsAxes master_actuator{};
  ActuatorLimitsAxes slave_actuator{};
  SlaveLimitsAxes slave_limits{};
  double clutch_fade_s{0.02};  // as LawParams::clutch_fade_s
};

// n-vectors and n x n matrices of `axes` entries (setup helpers).
[[nodiscard]] ActuatorLimitsAxes no_actuator_limits(int axes);
[[nodiscard]] SlaveLimitsAxes no_slave_limits(int axes);

// The law the n-axis stability engine analyses for `params`: same period, gain matrices,
// scaling, planes and velocity filter; every limit infinite, default clutch fade. Throws
// std::invalid_argument naming the field when a size exceeds the fixed capacity (6 axes, 8
// planes) or disagrees with `axes`.
[[nodiscard]] LawAxesParams from_teleop_axes_params(const TeleopAxesParams& params);

// The one-axis law as n = 1: 1 x 1 gains, one plane per side with normal (+1) at the
// fixture's position (kept when its stiffness is 0), the limits as 1-vectors.
[[nodiscard]] LawAxesParams to_law_axes(const LawParams& params);

// Throws std::invalid_argument naming the first offending field, e.g.
// "LawAxesParams.gains.kpm[1][2]: must be finite" or
// "LawAxesParams.master_planes[0].normal: must have unit length" (within 1e-9). Gains need
// only be finite, as in validate(LawParams).
void validate(const LawAxesParams& params);

}  // namespace teleop::control
