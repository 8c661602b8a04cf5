// What the supervisor watches on the live system (issue 5 "Watches"), fed with the nodes'
// per-cycle telemetry: a sustained-oscillation detector on each position (the simulator's
// detector on a sliding window) and a time-domain passivity observer per side.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <utility>
#include <vector>

#include "common/scene/oscillation.hpp"

namespace teleop::supervisor {

// A sliding window of one signal sampled every period; check() looks at the last `window_s`
// and the one before it (two windows are kept).
class OscillationMonitor {
 public:
  OscillationMonitor(double period_s, double window_s, double threshold_m);
  void add(double position_m);
  [[nodiscard]] scene::Oscillation check() const;
  [[nodiscard]] bool full() const { return samples_.size() >= capacity_; }
  void clear() { samples_.clear(); }

 private:
  double period_s_;
  double window_s_;
  double threshold_m_;
  std::size_t capacity_;
  std::deque<double> samples_{};
};

// Ryu-Hannaford's observer on one port: E(n) = T sum_{k<=n} f(k) v(k), the energy that has
// flowed into the teleoperator through this port (f the force the outside applies along +x, v
// the port velocity). A negative E means the teleoperator has given out more energy than it
// received there: it is active at that port. The threshold absorbs sensor noise.
//
// It also keeps E over the last `window_s`, for the power flowing in over that window: encoder
// quantisation makes a coupled port dither by a count, which sustains a tiny steady outflow
// (about 0.25 mW in the shipped demo) that a cumulative E alone turns into an alarm after
// tens of seconds. The supervisor alarms when E is below its threshold *and* the port is
// still giving out more than a minimum power (supervisor.passivity_power_threshold_W).
class PassivityObserver {
 public:
  explicit PassivityObserver(double period_s, double window_s = 1.0)
      : period_s_(period_s),
        window_samples_(static_cast<std::size_t>(std::max(1.0, std::round(window_s / period_s)))) {}
  void add(double force_N, double velocity_m_per_s) {
    energy_J_ += period_s_ * force_N * velocity_m_per_s;
    if (energy_J_ < min_energy_J_) min_energy_J_ = energy_J_;
    history_.push_back(energy_J_);
    while (history_.size() > window_samples_ + 1) history_.pop_front();
  }
  [[nodiscard]] double energy_J() const { return energy_J_; }
  // The deepest the energy has been below zero (0 when never).
  [[nodiscard]] double min_energy_J() const { return min_energy_J_; }
  // Mean power into the port over the last window (or what has been seen of it), W; negative:
  // the port is giving energy out. 0 before two samples.
  [[nodiscard]] double recent_power_W() const {
    if (history_.size() < 2) return 0.0;
    return (history_.back() - history_.front()) /
           (static_cast<double>(history_.size() - 1) * period_s_);
  }
  void reset() {
    energy_J_ = 0.0;
    min_energy_J_ = 0.0;
    history_.clear();
  }

 private:
  double period_s_;
  std::size_t window_samples_;
  double energy_J_{0.0};
  double min_energy_J_{0.0};
  std::deque<double> history_{};
};

// The round trip the supervisor's model is built on: the largest round-trip p99 the nodes
// reported over the last `hold_ns`. It goes up at once (the safe side) and comes down only
// once the shorter round trip has held that long, so a p99 on a sample boundary does not
// flap the model (and the alarms announcing each change) at every check.
class RoundTripModel {
 public:
  explicit RoundTripModel(std::int64_t hold_ns) : hold_ns_(hold_ns) {}
  // The largest of the last `hold_ns`, `p99_ns` (measured at `now_ns`) included.
  std::int64_t add(std::int64_t now_ns, std::int64_t p99_ns) {
    while (!seen_.empty() && seen_.back().second <= p99_ns) seen_.pop_back();
    seen_.emplace_back(now_ns, p99_ns);
    while (now_ns - seen_.front().first > hold_ns_) seen_.pop_front();
    return seen_.front().second;
  }

 private:
  std::int64_t hold_ns_;
  // (time, p99), p99 strictly decreasing from the front: the front is the window's largest.
  std::deque<std::pair<std::int64_t, std::int64_t>> seen_{};
};

}  // namespace teleop::supervisor
