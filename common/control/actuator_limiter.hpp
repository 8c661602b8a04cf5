// Force saturation and per-sample rate limit of one actuator.
#pragma once

#include "common/control/law_params.hpp"
#include "common/core/rt_safe.hpp"

namespace teleop::control {

class ActuatorLimiter {
 public:
  struct Result {
    double force_N{0.0};
    bool saturated{false};
    bool rate_limited{false};
  };

  // Throws std::invalid_argument for a non-positive (or NaN) limit or period.
  ActuatorLimiter(const ActuatorLimits& limits, double period_s);

  // Clamps to +-max_force_N, then to within max_rate_N_per_s * T of the previous output (the
  // previous output is itself within the force limit, so the result honours both). `requested_N`
  // must be finite. RT-safe.
  TELEOP_RT [[nodiscard]] Result apply(double requested_N) noexcept;

  // The output the next rate limit starts from (a fault's 0 N, or reset()).
  TELEOP_RT void set_last_output(double force_N) noexcept { last_N_ = force_N; }
  [[nodiscard]] double last_output() const noexcept { return last_N_; }

 private:
  double max_force_N_{kNoLimit};
  double max_step_N_{kNoLimit};
  bool rate_limit_enabled_{false};
  double last_N_{0.0};
};

}  // namespace teleop::control
