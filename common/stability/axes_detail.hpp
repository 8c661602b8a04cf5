// Small helpers the n-axis analysis files share (analysis_axes.cpp, plane_limit_axes.cpp).
#pragma once

#include <Eigen/Core>
#include <atomic>
#include <cstddef>
#include <thread>
#include <vector>

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
