// Small helpers the n-axis analysis files share (analysis_axes.cpp, plane_limit_axes.cpp).
#pragma once

#include <Eigen/Core>
#include <atomic>
#include <cstddef>
#include <optional>
#include <thread>
#include <vector>

#include "common/core/teleop_axes.hpp"
#include "common/stability/analyzer.hpp"

namespace teleop::stability::detail {

// The axis a normal lies along (exactly), -1 when it is tilted.
inline int normal_axis(const Eigen::VectorXd& normal) {
  int axis = -1;
  for (int i = 0; i < normal.size(); ++i) {
    if (normal(i) == 0.0) continue;
    if (axis >= 0) return -1;
    axis = i;
  }
  return axis;
}

// An isotropic teleoperator (masses, gains and a fixed human scalar multiples of the identity,
// equal damping on every axis, no band) whose stiff planes' normals are pairwise parallel or
// orthogonal, exactly as floating-point numbers (n == +-m componentwise or n . m == 0), written
// in the planes' own frame: an orthogonal change of coordinates leaves every matrix as it is and
// turns each plane into one along an axis, where the axes decouple (docs/architecture.md §2.9).
struct PlaneFrame {
  TeleopAxesParams params;  // the same loop, every considered plane's normal a unit axis
  // Per plane of each side: the rotated plane's stiffness over the configured one (|n|^2, the
  // eigenvalue of n n^T); a plane left out of the frame (zero stiffness) has 1 and axis 0.
  std::vector<double> master_scale;
  std::vector<double> slave_scale;
};

// Nothing when the loop is not isotropic, a considered normal is neither parallel nor
// orthogonal to another, or every considered normal already lies along an axis (the axis-by-axis
// analysis applies as it stands). Considered: planes of non-zero stiffness and `searched`.
[[nodiscard]] std::optional<PlaneFrame> in_plane_frame(
    const TeleopAxesParams& p, const PlaneFixtureParams* searched = nullptr);

// Runs f(i) for i in [0, n) on the analysis threads.
template <class F>
void parallel_for(std::size_t n, const F& f) {
  const unsigned threads = analysis_threads(n, 64);
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t i = next++; i < n; i = next++) f(i);
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();
}

}  // namespace teleop::stability::detail
