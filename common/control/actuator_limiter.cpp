#include "common/control/actuator_limiter.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace teleop::control {

ActuatorLimiter::ActuatorLimiter(const ActuatorLimits& limits, double period_s)
    : max_force_N_(limits.max_force_N) {
  if (!(limits.max_force_N > 0.0)) {
    throw std::invalid_argument("ActuatorLimits.max_force_N must be > 0 (infinity: no limit)");
  }
  if (!(limits.max_rate_N_per_s > 0.0)) {
    throw std::invalid_argument("ActuatorLimits.max_rate_N_per_s must be > 0 (infinity: no limit)");
  }
  if (!std::isfinite(period_s) || period_s <= 0.0) {
    throw std::invalid_argument("ActuatorLimiter: period_s must be finite and > 0");
  }
  rate_limit_enabled_ = std::isfinite(limits.max_rate_N_per_s);
  max_step_N_ = limits.max_rate_N_per_s * period_s;
}

ActuatorLimiter::Result ActuatorLimiter::apply(double requested_N) noexcept {
  Result out;
  out.force_N = std::clamp(requested_N, -max_force_N_, max_force_N_);
  out.saturated = out.force_N != requested_N;
  if (rate_limit_enabled_) {
    const double limited = std::clamp(out.force_N, last_N_ - max_step_N_, last_N_ + max_step_N_);
    out.rate_limited = limited != out.force_N;
    out.force_N = limited;
  }
  last_N_ = out.force_N;
  return out;
}

}  // namespace teleop::control
