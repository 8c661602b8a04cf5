// Fixed-capacity task-space n-vectors and n x n matrices (Eigen's fixed-maximum dynamic types):
// no allocation for any n <= kMaxAxes, for the RT path of the n-axis law and simulated plant
// (common/control/plane_fixtures.hpp, common/sim/plant_axes.hpp).
#pragma once

#include <Eigen/Core>

#include "common/core/teleop_axes.hpp"

namespace teleop {

using FixedAxisVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxAxes, 1>;
using FixedAxisMatrix =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxAxes, kMaxAxes>;

}  // namespace teleop
