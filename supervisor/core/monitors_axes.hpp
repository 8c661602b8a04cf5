// The supervisor's live monitors for n task-space axes (issue 18 "Everything above the law"):
// the one-axis OscillationMonitor on every axis, and Ryu-Hannaford's passivity observer on the
// vector port (the energy T sum f(k) . v(k), the dot product over the axes).
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "common/core/rt_safe.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/scene/oscillation.hpp"
#include "supervisor/core/monitors.hpp"

namespace teleop::supervisor {

struct OscillationAxes {
  // The worst axis: a detected oscillation before any undetected one, then the largest
  // amplitude (the lowest index among equals); -1 only in a default-constructed result.
  int worst_axis{-1};
  scene::Oscillation worst{};
  std::vector<scene::Oscillation> per_axis{};  // one per axis
  [[nodiscard]] bool detected() const { return worst.detected; }
};

// One OscillationMonitor per task axis, each fed with that axis's position. What is watched is
// every axis on its own, never the norm |x| of the position about its mean: a device circling
// at a constant radius (two axes in quadrature, a buzz in the plane of a fixture) has a constant
// norm, and a detector on the norm sees nothing however large the circle is.
class OscillationMonitorAxes {
 public:
  // Throws std::invalid_argument naming the field: axes outside 1..kMaxAxes, and whatever
  // OscillationMonitor refuses (period_s, window_s).
  OscillationMonitorAxes(int axes, double period_s, double window_s, double threshold_m);

  // One sample of the position, one entry per axis (std::invalid_argument otherwise).
  void add(std::span<const double> position_m);
  [[nodiscard]] OscillationAxes check() const;

  [[nodiscard]] int axes() const { return static_cast<int>(monitors_.size()); }
  [[nodiscard]] bool full() const { return monitors_.front().full(); }
  void clear();

 private:
  std::vector<OscillationMonitor> monitors_{};
};

// Ryu-Hannaford's observer on an n-axis port: E(n) = T sum_{k<=n} f(k) . v(k), the energy that
// has flowed into the teleoperator through the port (f the force vector the outside applies, v
// the port's velocity vector, both in the same task-space coordinates; f . v is the power and
// does not depend on the coordinates). As PassivityObserver (monitors.hpp, whose numbers it
// gives bit for bit with one axis) it keeps the deepest E and the power over the last
// `window_s`. The window lives in storage sized at construction: add() allocates nothing.
class PassivityObserverAxes {
 public:
  // Throws std::invalid_argument naming the field: axes outside 1..kMaxAxes, a period or
  // window that is not positive and finite.
  PassivityObserverAxes(int axes, double period_s, double window_s = 1.0);

  // One sample; both spans have axes() entries. Returns false (and ignores the sample) when a
  // size differs. Allocates nothing, never throws (tests/unit/supervisor/test_monitors_axes_rt).
  TELEOP_RT bool add(std::span<const double> force_N,
                     std::span<const double> velocity_m_per_s) noexcept;

  [[nodiscard]] int axes() const { return axes_; }
  [[nodiscard]] double energy_J() const { return energy_J_; }
  // The deepest the energy has been below zero (0 when never).
  [[nodiscard]] double min_energy_J() const { return min_energy_J_; }
  // Mean power into the port over the last window (or what has been seen of it), W; negative:
  // the port is giving energy out. 0 before two samples.
  TELEOP_RT [[nodiscard]] double recent_power_W() const noexcept;
  TELEOP_RT void reset() noexcept;

 private:
  int axes_;
  double period_s_;
  double energy_J_{0.0};
  double min_energy_J_{0.0};
  // The last window_samples + 1 energies, oldest at head_ once full.
  std::vector<double> history_{};
  std::size_t head_{0};
  std::size_t count_{0};
};

}  // namespace teleop::supervisor
