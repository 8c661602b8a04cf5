// Backward-difference velocity, optionally through the first-order low-pass of
// docs/architecture.md §2.4.
#pragma once

#include "common/core/rt_safe.hpp"

namespace teleop::control {

class VelocityEstimator {
 public:
  // cutoff_hz = 0: no filter. Throws std::invalid_argument for a non-positive or non-finite
  // period or a negative or non-finite cutoff.
  VelocityEstimator(double period_s, double cutoff_hz);

  // v(k) = (x(k) - x(k-1)) / T; v_f(k) = v_f(k-1) + a (v(k) - v_f(k-1)), a = 1 - e^{-2 pi fc T}.
  // The first sample after construction or reset() only primes x(k-1) and returns 0.
  // Returns the filtered velocity. RT-safe. Inputs must be finite (callers check).
  TELEOP_RT [[nodiscard]] double step(double position_m) noexcept;

  // At rest at `position_m`: x(k-1) = position_m, v_f = 0.
  TELEOP_RT void reset(double position_m) noexcept;
  // At rest wherever the next sample is.
  TELEOP_RT void reset() noexcept;

  [[nodiscard]] double velocity_m_per_s() const noexcept { return filtered_; }
  [[nodiscard]] double raw_velocity_m_per_s() const noexcept { return raw_; }
  // The filter's gain a (1 when there is no filter).
  [[nodiscard]] double smoothing() const noexcept { return gain_; }

 private:
  double period_s_{0.0};
  double gain_{1.0};
  bool filtered_enabled_{false};
  bool primed_{false};
  double last_position_m_{0.0};
  double raw_{0.0};
  double filtered_{0.0};
};

}  // namespace teleop::control
