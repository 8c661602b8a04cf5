#include "supervisor/core/monitors_axes.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace teleop::supervisor {

namespace {

void check_axes(int axes, const char* who) {
  if (axes < 1 || axes > kMaxAxes) {
    throw std::invalid_argument(std::string(who) + ": axes must be 1 to " +
                                std::to_string(kMaxAxes) + ", got " + std::to_string(axes));
  }
}

// Detected before undetected, then the larger amplitude.
bool worse(const scene::Oscillation& a, const scene::Oscillation& b) {
  if (a.detected != b.detected) return a.detected;
  return a.amplitude_m > b.amplitude_m;
}

}  // namespace

OscillationMonitorAxes::OscillationMonitorAxes(int axes, double period_s, double window_s,
                                               double threshold_m) {
  check_axes(axes, "oscillation monitor");
  monitors_.reserve(static_cast<std::size_t>(axes));
  for (int i = 0; i < axes; ++i) monitors_.emplace_back(period_s, window_s, threshold_m);
}

void OscillationMonitorAxes::add(std::span<const double> position_m) {
  if (position_m.size() != monitors_.size()) {
    throw std::invalid_argument("oscillation monitor: position_m has " +
                                std::to_string(position_m.size()) + " entries, expected " +
                                std::to_string(monitors_.size()));
  }
  for (std::size_t i = 0; i < monitors_.size(); ++i) monitors_[i].add(position_m[i]);
}

OscillationAxes OscillationMonitorAxes::check() const {
  OscillationAxes out;
  out.per_axis.reserve(monitors_.size());
  for (const OscillationMonitor& m : monitors_) out.per_axis.push_back(m.check());
  out.worst_axis = 0;
  for (std::size_t i = 1; i < out.per_axis.size(); ++i) {
    if (worse(out.per_axis[i], out.per_axis[static_cast<std::size_t>(out.worst_axis)])) {
      out.worst_axis = static_cast<int>(i);
    }
  }
  out.worst = out.per_axis[static_cast<std::size_t>(out.worst_axis)];
  return out;
}

void OscillationMonitorAxes::clear() {
  for (OscillationMonitor& m : monitors_) m.clear();
}

PassivityObserverAxes::PassivityObserverAxes(int axes, double period_s, double window_s)
    : axes_(axes), period_s_(period_s) {
  check_axes(axes, "passivity observer");
  if (!std::isfinite(period_s) || !(period_s > 0.0)) {
    throw std::invalid_argument("passivity observer: period_s must be positive and finite");
  }
  if (!std::isfinite(window_s) || !(window_s > 0.0) || !(window_s / period_s <= 1e8)) {
    throw std::invalid_argument(
        "passivity observer: window_s must be positive and finite, at most 1e8 periods");
  }
  // PassivityObserver's window: round(window / period) samples, at least one, and the energy
  // before them.
  const auto window_samples =
      static_cast<std::size_t>(std::max(1.0, std::round(window_s / period_s)));
  history_.assign(window_samples + 1, 0.0);
}

bool PassivityObserverAxes::add(std::span<const double> force_N,
                                std::span<const double> velocity_m_per_s) noexcept {
  const auto n = static_cast<std::size_t>(axes_);
  if (force_N.size() != n || velocity_m_per_s.size() != n) return false;
  // (T f_i) v_i summed over the axes: with one axis exactly PassivityObserver's T * f * v.
  double step_J = period_s_ * force_N[0] * velocity_m_per_s[0];
  for (std::size_t i = 1; i < n; ++i) step_J += period_s_ * force_N[i] * velocity_m_per_s[i];
  energy_J_ += step_J;
  if (energy_J_ < min_energy_J_) min_energy_J_ = energy_J_;
  const std::size_t capacity = history_.size();
  if (count_ < capacity) {
    history_[(head_ + count_) % capacity] = energy_J_;
    ++count_;
  } else {
    history_[head_] = energy_J_;
    head_ = (head_ + 1) % capacity;
  }
  return true;
}

double PassivityObserverAxes::recent_power_W() const noexcept {
  if (count_ < 2) return 0.0;
  const double oldest = history_[head_];
  const double newest = history_[(head_ + count_ - 1) % history_.size()];
  return (newest - oldest) / (static_cast<double>(count_ - 1) * period_s_);
}

void PassivityObserverAxes::reset() noexcept {
  energy_J_ = 0.0;
  min_energy_J_ = 0.0;
  head_ = 0;
  count_ = 0;
}

}  // namespace teleop::supervisor
