#include "supervisor/core/monitors.hpp"

#include <cmath>
#include <stdexcept>

namespace teleop::supervisor {

namespace {

// Two windows of samples, checked before the conversion: a zero or non-finite period or window
// (or a window of more than 1e8 periods) is refused, never cast to a size (undefined behaviour
// for an infinite quotient).
std::size_t two_windows(double period_s, double window_s) {
  const double samples = 2.0 * window_s / period_s;
  if (!(period_s > 0.0) || !(window_s > 0.0) || !std::isfinite(samples) || samples > 1e8) {
    throw std::invalid_argument(
        "oscillation monitor: period and window must be > 0 and finite, the window at most 5e7 "
        "periods");
  }
  return static_cast<std::size_t>(std::ceil(samples));
}

}  // namespace

OscillationMonitor::OscillationMonitor(double period_s, double window_s, double threshold_m)
    : period_s_(period_s),
      window_s_(window_s),
      threshold_m_(threshold_m),
      capacity_(two_windows(period_s, window_s)) {}

void OscillationMonitor::add(double position_m) {
  samples_.push_back(position_m);
  while (samples_.size() > capacity_) samples_.pop_front();
}

scene::Oscillation OscillationMonitor::check() const {
  const std::vector<double> x(samples_.begin(), samples_.end());
  return scene::detect_oscillation(x, period_s_, window_s_, threshold_m_);
}

}  // namespace teleop::supervisor
