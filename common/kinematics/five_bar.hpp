// The planar five-bar linkage of the Vlachos-Papadopoulos device (issue 18, "Devices"): two
// actuated joints on a fixed base, a proximal link on each, two distal links meeting at the
// end point. Closed-form forward and inverse kinematics, the Jacobian and how far the linkage
// is from a singularity; docs/kinematics.md derives each formula.
//
// Frame: x along the base from the first actuated joint A1 = (-s/2, 0) to the second
// A2 = (+s/2, 0), y up; joint angles q_i from +x, counter-clockwise. Elbows
// B_i = A_i + a_i (cos q_i, sin q_i); the end point P is where the circles of radius b_i about
// B_i meet, on the left of B1 -> B2 (the working mode with P above the elbows when the
// linkage opens upwards).
#pragma once

#include <Eigen/Core>
#include <optional>

#include "common/core/rt_safe.hpp"

namespace teleop::kinematics {

struct FiveBarGeometry {
  double base_separation_m{0.0};   // |A2 - A1|, may be 0 (both joints on one axis)
  double proximal_m[2]{0.0, 0.0};  // a_1, a_2
  double distal_m[2]{0.0, 0.0};    // b_1, b_2
};

// What is wrong with a geometry (the empty string when nothing is): every length finite, the
// links positive, the separation not negative.
[[nodiscard]] const char* check(const FiveBarGeometry& g) noexcept;

struct FiveBarPose {
  Eigen::Vector2d end_m{Eigen::Vector2d::Zero()};
  Eigen::Vector2d elbow_m[2]{Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};
  // dP/dq (m/rad): column i is the end point's velocity per unit rate of joint i.
  Eigen::Matrix2d jacobian_m_per_rad{Eigen::Matrix2d::Zero()};
  // How far from a singularity, in [0, 1]: the smallest |sin| of the three transmission
  // angles, between the two distal links (0: they are aligned, a parallel singularity where
  // the end point is not held) and between each proximal link and its distal link (0: a
  // serial singularity where the end point cannot move along that distal link).
  double singularity_distance{0.0};
};

// The pose at joint angles q (rad); nullopt when the distal links cannot meet (the elbows
// further apart than b_1 + b_2, or closer than |b_1 - b_2|) or meet only tangentially.
TELEOP_RT [[nodiscard]] std::optional<FiveBarPose> forward(const FiveBarGeometry& g,
                                                           const Eigen::Vector2d& q_rad) noexcept;

// Joint angles that put the end point at p (the working mode of `forward`: each elbow on the
// outer side, away from the other joint); nullopt when p is out of reach of either arm.
TELEOP_RT [[nodiscard]] std::optional<Eigen::Vector2d> inverse(const FiveBarGeometry& g,
                                                               const Eigen::Vector2d& p_m) noexcept;

// The joint torques (N m) that hold a force F (N) applied by the end point: tau = J^T F.
TELEOP_RT [[nodiscard]] inline Eigen::Vector2d joint_torques_Nm(
    const FiveBarPose& pose, const Eigen::Vector2d& force_N) noexcept {
  return pose.jacobian_m_per_rad.transpose() * force_N;
}

}  // namespace teleop::kinematics
