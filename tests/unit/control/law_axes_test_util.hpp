// Shared pieces of the n-axis law's busy configurations (test_law_axes_rt.cpp,
// bench/bench_law_axes.cpp): coupled gain matrices, the two plane normals, limits alike on
// every axis.
#pragma once

#include <cmath>

#include "common/control/law_axes.hpp"

namespace teleop::control::test {

// n x n with `diagonal` on the diagonal and `coupling` everywhere else.
[[nodiscard]] inline AxisMatrix coupled_gain(int n, double diagonal, double coupling) {
  AxisMatrix m = AxisMatrix::Constant(n, n, coupling);
  m.diagonal().setConstant(diagonal);
  return m;
}

// (1, ..., 1) / sqrt(n): a plane tilted equally towards every axis.
[[nodiscard]] inline AxisVector tilted_normal(int n) {
  return AxisVector::Constant(n, 1.0 / std::sqrt(static_cast<double>(n)));
}

// The unit vector of axis 0.
[[nodiscard]] inline AxisVector first_axis(int n) {
  AxisVector e = AxisVector::Zero(n);
  e(0) = 1.0;
  return e;
}

[[nodiscard]] inline ActuatorLimitsAxes actuator_limits(int n, double max_force_N,
                                                        double max_rate_N_per_s) {
  return {AxisVector::Constant(n, max_force_N), AxisVector::Constant(n, max_rate_N_per_s)};
}

// The workspace box [min, max] on every axis with its velocity and force bounds.
[[nodiscard]] inline SlaveLimitsAxes slave_box(int n, double min_position_m, double max_position_m,
                                               double max_velocity_m_per_s, double max_force_N) {
  return {AxisVector::Constant(n, min_position_m), AxisVector::Constant(n, max_position_m),
          AxisVector::Constant(n, max_velocity_m_per_s), AxisVector::Constant(n, max_force_N)};
}

}  // namespace teleop::control::test
