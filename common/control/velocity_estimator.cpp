#include "common/control/velocity_estimator.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace teleop::control {

VelocityEstimator::VelocityEstimator(double period_s, double cutoff_hz) {
  if (!std::isfinite(period_s) || period_s <= 0.0) {
    throw std::invalid_argument("VelocityEstimator: period_s must be finite and > 0");
  }
  if (!std::isfinite(cutoff_hz) || cutoff_hz < 0.0) {
    throw std::invalid_argument("VelocityEstimator: cutoff_hz must be finite and >= 0");
  }
  period_s_ = period_s;
  filtered_enabled_ = cutoff_hz > 0.0;
  // expm1 keeps the digits of a small gain (low cutoff or short period).
  gain_ = filtered_enabled_ ? -std::expm1(-2.0 * std::numbers::pi * cutoff_hz * period_s) : 1.0;
}

double VelocityEstimator::step(double position_m) noexcept {
  if (!primed_) {
    primed_ = true;
    last_position_m_ = position_m;
    raw_ = 0.0;
    filtered_ = 0.0;
    return filtered_;
  }
  raw_ = (position_m - last_position_m_) / period_s_;
  last_position_m_ = position_m;
  filtered_ = filtered_enabled_ ? filtered_ + gain_ * (raw_ - filtered_) : raw_;
  return filtered_;
}

void VelocityEstimator::reset(double position_m) noexcept {
  primed_ = true;
  last_position_m_ = position_m;
  raw_ = 0.0;
  filtered_ = 0.0;
}

void VelocityEstimator::reset() noexcept {
  primed_ = false;
  raw_ = 0.0;
  filtered_ = 0.0;
}

}  // namespace teleop::control
