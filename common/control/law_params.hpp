// Parameters of the control core (docs/architecture.md §2.3): the three-channel law with its
// fixtures, the actuator limits of each side and the slave's workspace limits. Plain data;
// validate() is setup code and may throw.
#pragma once

#include <limits>

#include "common/core/teleop_params.hpp"

namespace teleop::control {

inline constexpr double kNoLimit = std::numeric_limits<double>::infinity();

// What one actuator (amplifier + motor) may be asked for. Infinite means no limit.
struct ActuatorLimits {
  double max_force_N{kNoLimit};       // |F| <= max_force_N (saturation)
  double max_rate_N_per_s{kNoLimit};  // |F(k) - F(k-1)| <= max_rate_N_per_s * T
};

// The slave's workspace, in slave coordinates. Infinite means no limit.
struct SlaveLimits {
  double min_position_m{-kNoLimit};
  double max_position_m{kNoLimit};
  double max_velocity_m_per_s{kNoLimit};  // on the slave's own filtered velocity
  double max_force_N{kNoLimit};           // the most the slave may push its environment with
};

struct LawParams {
  double period_s{0.0};
  Gains gains{};
  Scaling scaling{};
  FixtureParams master_fixture{};
  FixtureParams slave_fixture{};
  double velocity_cutoff_hz{0.0};  // 0: plain backward difference
  ActuatorLimits master_actuator{};
  ActuatorLimits slave_actuator{};
  SlaveLimits slave_limits{};
  // Clutch (and link) transitions fade the coupling in or out linearly over this time so that
  // no force steps (0: switch within one sample).
  double clutch_fade_s{0.02};
};

// The law the stability engine analyses for `params`: same period, gains, scaling, fixtures
// and velocity filter; every limit infinite, default clutch fade.
[[nodiscard]] LawParams from_teleop_params(const TeleopParams& params);

// Throws std::invalid_argument naming the first offending field.
void validate(const LawParams& params);

}  // namespace teleop::control
