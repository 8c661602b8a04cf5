// The closed force loop of Vlachos & Papadopoulos (docs/architecture.md §2.8):
//
//   F_in = F_des + K_p (F_des - F_avg) + K_i I,   I(k) = I(k-1) + T (F_des - F_avg)(k)
//
// F_avg is the mean of the last N force-sensor samples (N = 50 in the paper; fewer while the
// first N arrive). Usable as the inner loop of a master (F_des = the law's F_am, sensed = the
// handle's load cell, same sign convention) or on its own on a device rendering a virtual
// spring-damper (VirtualEnvironmentRenderer).
#pragma once

#include <vector>

#include "common/control/actuator_limiter.hpp"
#include "common/control/law_params.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/core/rt_safe.hpp"
#include "common/core/teleop_params.hpp"

namespace teleop::control {

// Mean of the last N samples. Storage is sized at construction; push() never allocates.
class MovingAverage {
 public:
  // Throws std::invalid_argument unless samples >= 1.
  explicit MovingAverage(int samples);

  // Adds a sample (finite: callers check) and returns the mean of the last min(count, N).
  // RT-safe.
  TELEOP_RT double push(double sample) noexcept;
  TELEOP_RT [[nodiscard]] double mean() const noexcept;
  [[nodiscard]] int window() const noexcept { return static_cast<int>(buffer_.size()); }
  [[nodiscard]] int count() const noexcept { return count_; }
  // Forgets every sample (no deallocation). RT-safe.
  TELEOP_RT void clear() noexcept;

 private:
  TELEOP_RT void add(double value) noexcept;

  std::vector<double> buffer_;
  std::size_t next_{0};
  int count_{0};
  // Compensated running sum, re-summed from the buffer once per pass: no drift.
  double sum_{0.0};
  double compensation_{0.0};
};

struct ForceLoopSettings {
  double period_s{0.0};
  double kp{0.0};
  double ki{0.0};  // 1/s
  int average_samples{50};
  ActuatorLimits limits{};
};

// Period, gains and averaging window of a ForceLoopParams; no actuator limits.
[[nodiscard]] ForceLoopSettings from_force_loop_params(const ForceLoopParams& params);

struct ForceLoopCommand {
  double force_N{0.0};          // F_in to the actuator (after limits)
  double desired_force_N{0.0};  // F_des
  double average_force_N{0.0};  // F_avg
  double integral_Ns{0.0};      // I
  bool saturated{false};
  bool rate_limited{false};
  bool input_fault{false};  // non-finite input: 0 N, latched until reset()
};

class ForceLoopController {
 public:
  // Throws std::invalid_argument naming the field.
  explicit ForceLoopController(const ForceLoopSettings& settings);

  // One sample. Saturation to +-limits.max_force_N, then the rate limit. Anti-windup: the
  // integral does not take a sample's error when the unlimited output is beyond the force
  // limit and that error would push it further. Non-finite input or output: 0 N,
  // input_fault, latched until reset(). RT-safe.
  TELEOP_RT [[nodiscard]] ForceLoopCommand step(double desired_force_N,
                                                double sensed_force_N) noexcept;

  // Clears the average, the integral and the fault latch. RT-safe.
  TELEOP_RT void reset() noexcept;

  [[nodiscard]] bool faulted() const noexcept { return faulted_; }
  [[nodiscard]] const ForceLoopSettings& settings() const noexcept { return settings_; }

 private:
  ForceLoopSettings settings_{};
  MovingAverage average_;
  ActuatorLimiter limiter_;
  double integral_Ns_{0.0};
  bool faulted_{false};
};

// A virtual spring-damper wall at position_m, acting for penetration x_e = x - p > 0:
// F_des = K_v x_e + B_v v (the paper's G_v = K_v + B_v s; it pulls when leaving faster than
// K_v x_e / B_v, as the linear model does), else 0. The force the device applies against
// the user, positive out of the wall.
struct VirtualSpringDamper {
  double stiffness_N_per_m{0.0};
  double damping_Ns_per_m{0.0};
  double position_m{0.0};

  // RT-safe.
  TELEOP_RT [[nodiscard]] double force_N(double position, double velocity_m_per_s) const noexcept {
    const double penetration_m = position - position_m;
    if (!(penetration_m > 0.0)) return 0.0;
    return stiffness_N_per_m * penetration_m + damping_Ns_per_m * velocity_m_per_s;
  }
};

// A force-controlled haptic device on its own: velocity estimate, virtual environment,
// force loop.
class VirtualEnvironmentRenderer {
 public:
  // Throws std::invalid_argument naming the field.
  VirtualEnvironmentRenderer(const ForceLoopSettings& settings, double velocity_cutoff_hz,
                             const VirtualSpringDamper& environment);

  // One sample: device position and force-sensor reading. Non-finite input: 0 N, latched.
  // RT-safe.
  TELEOP_RT [[nodiscard]] ForceLoopCommand step(double position_m, double sensed_force_N) noexcept;
  TELEOP_RT void reset() noexcept;
  [[nodiscard]] double velocity_m_per_s() const noexcept { return estimator_.velocity_m_per_s(); }

 private:
  VelocityEstimator estimator_;
  VirtualSpringDamper environment_{};
  ForceLoopController loop_;
};

}  // namespace teleop::control
