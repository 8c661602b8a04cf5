#include "common/control/force_loop_controller.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace teleop::control {
namespace {

[[nodiscard]] std::size_t checked_window(int samples) {
  if (samples < 1) throw std::invalid_argument("average_samples must be >= 1");
  return static_cast<std::size_t>(samples);
}

[[nodiscard]] const ForceLoopSettings& validated(const ForceLoopSettings& s) {
  auto fail = [](const char* field, const char* what) {
    throw std::invalid_argument(std::string("ForceLoopSettings.") + field + ": " + what);
  };
  if (!std::isfinite(s.period_s) || s.period_s <= 0.0) fail("period_s", "must be finite and > 0");
  if (!std::isfinite(s.kp)) fail("kp", "must be finite");
  if (!std::isfinite(s.ki)) fail("ki", "must be finite");
  if (s.average_samples < 1) fail("average_samples", "must be >= 1");
  if (!(s.limits.max_force_N > 0.0)) fail("limits.max_force_N", "must be > 0 (infinity: none)");
  if (!(s.limits.max_rate_N_per_s > 0.0)) {
    fail("limits.max_rate_N_per_s", "must be > 0 (infinity: none)");
  }
  return s;
}

}  // namespace

MovingAverage::MovingAverage(int samples) : buffer_(checked_window(samples), 0.0) {}

void MovingAverage::add(double value) noexcept {
  // Neumaier: the rounding of every addition is kept in compensation_.
  const double t = sum_ + value;
  compensation_ += std::abs(sum_) >= std::abs(value) ? (sum_ - t) + value : (value - t) + sum_;
  sum_ = t;
}

double MovingAverage::push(double sample) noexcept {
  const double leaving = buffer_[next_];
  buffer_[next_] = sample;
  next_ = next_ + 1 == buffer_.size() ? 0 : next_ + 1;
  if (count_ < window()) {
    ++count_;
    add(sample);
  } else if (next_ == 0) {
    // Once per pass: start again from the samples themselves, so nothing can drift.
    sum_ = 0.0;
    compensation_ = 0.0;
    for (const double x : buffer_) add(x);
  } else {
    add(sample);
    add(-leaving);
  }
  return mean();
}

double MovingAverage::mean() const noexcept {
  return count_ == 0 ? 0.0 : (sum_ + compensation_) / static_cast<double>(count_);
}

void MovingAverage::clear() noexcept {
  std::fill(buffer_.begin(), buffer_.end(), 0.0);
  next_ = 0;
  count_ = 0;
  sum_ = 0.0;
  compensation_ = 0.0;
}

ForceLoopSettings from_force_loop_params(const ForceLoopParams& params) {
  ForceLoopSettings out;
  out.period_s = params.sample_rate_hz > 0.0 ? 1.0 / params.sample_rate_hz : 0.0;
  out.kp = params.kp;
  out.ki = params.ki;
  out.average_samples = params.sensor_average_samples;
  return out;
}

ForceLoopController::ForceLoopController(const ForceLoopSettings& settings)
    : settings_(validated(settings)),
      average_(settings.average_samples),
      limiter_(settings.limits, settings.period_s) {}

ForceLoopCommand ForceLoopController::step(double desired_force_N, double sensed_force_N) noexcept {
  ForceLoopCommand out;
  if (!faulted_ && std::isfinite(desired_force_N) && std::isfinite(sensed_force_N)) {
    const double average_N = average_.push(sensed_force_N);
    const double error_N = desired_force_N - average_N;
    const double feedforward_N = desired_force_N + settings_.kp * error_N;
    double integral_Ns = integral_Ns_;
    double requested_N = feedforward_N;
    if (settings_.ki != 0.0) {
      integral_Ns += settings_.period_s * error_N;
      requested_N = feedforward_N + settings_.ki * integral_Ns;
      const double limit_N = settings_.limits.max_force_N;
      const bool beyond = std::abs(requested_N) > limit_N;
      const bool winding = (settings_.ki * error_N > 0.0) == (requested_N > 0.0);
      if (beyond && winding && error_N != 0.0) {
        integral_Ns = integral_Ns_;
        requested_N = feedforward_N + settings_.ki * integral_Ns;
      }
    }
    if (std::isfinite(requested_N)) {
      integral_Ns_ = integral_Ns;
      const ActuatorLimiter::Result limited = limiter_.apply(requested_N);
      out.force_N = limited.force_N;
      out.desired_force_N = desired_force_N;
      out.average_force_N = average_N;
      out.integral_Ns = integral_Ns_;
      out.saturated = limited.saturated;
      out.rate_limited = limited.rate_limited;
      return out;
    }
  }
  faulted_ = true;
  limiter_.set_last_output(0.0);
  out.input_fault = true;
  return out;
}

void ForceLoopController::reset() noexcept {
  average_.clear();
  limiter_.set_last_output(0.0);
  integral_Ns_ = 0.0;
  faulted_ = false;
}

VirtualEnvironmentRenderer::VirtualEnvironmentRenderer(const ForceLoopSettings& settings,
                                                       double velocity_cutoff_hz,
                                                       const VirtualSpringDamper& environment)
    : estimator_(settings.period_s, velocity_cutoff_hz),
      environment_(environment),
      loop_(settings) {
  if (!std::isfinite(environment.stiffness_N_per_m) ||
      !std::isfinite(environment.damping_Ns_per_m) || !std::isfinite(environment.position_m)) {
    throw std::invalid_argument("VirtualSpringDamper: every field must be finite");
  }
}

ForceLoopCommand VirtualEnvironmentRenderer::step(double position_m,
                                                  double sensed_force_N) noexcept {
  // A non-finite position must not reach the estimator; the loop latches on the NaN it gets.
  if (!std::isfinite(position_m) || loop_.faulted()) {
    return loop_.step(std::numeric_limits<double>::quiet_NaN(), sensed_force_N);
  }
  const double v = estimator_.step(position_m);
  return loop_.step(environment_.force_N(position_m, v), sensed_force_N);
}

void VirtualEnvironmentRenderer::reset() noexcept {
  estimator_.reset();
  loop_.reset();
}

}  // namespace teleop::control
