// The five-bar linkage (issue 18 "Devices"): forward kinematics against the symmetric pose by
// hand and against the two circle constraints; the Jacobian against central differences of the
// forward kinematics; J^T F against the statics of the two distal links (two-force members);
// inverse against forward; the singularity distance against the law of cosines of the three
// triangles; nothing from the code under test.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/kinematics/five_bar.hpp"

namespace teleop::kinematics {
namespace {

constexpr double kPi = std::numbers::pi;

// Planar five-bar proportions of a desktop haptic device: 10 cm between the motors, 10 cm
// proximal and 15 cm distal links (the paper gives no lengths; the config will).
FiveBarGeometry symmetric() {
  FiveBarGeometry g;
  g.base_separation_m = 0.10;
  g.proximal_m[0] = g.proximal_m[1] = 0.10;
  g.distal_m[0] = g.distal_m[1] = 0.15;
  return g;
}

FiveBarGeometry uneven() {
  FiveBarGeometry g;
  g.base_separation_m = 0.06;
  g.proximal_m[0] = 0.09;
  g.proximal_m[1] = 0.11;
  g.distal_m[0] = 0.16;
  g.distal_m[1] = 0.14;
  return g;
}

Eigen::Vector2d base(const FiveBarGeometry& g, int i) {
  return {i == 0 ? -g.base_separation_m / 2 : g.base_separation_m / 2, 0.0};
}

TEST(FiveBar, SymmetricPoseByHand) {
  const FiveBarGeometry g = symmetric();
  // q1 = 120 deg, q2 = 60 deg: elbows at (-(s/2 + a cos 60), a sin 60) and the mirror image, so
  // the end point is on the y axis at a sin 60 + sqrt(b^2 - (s/2 + a cos 60)^2).
  const auto pose = forward(g, {2 * kPi / 3, kPi / 3});
  ASSERT_TRUE(pose.has_value());
  const double half = 0.05 + 0.10 * 0.5;
  const double y = 0.10 * std::sqrt(3.0) / 2 + std::sqrt(0.15 * 0.15 - half * half);
  EXPECT_NEAR(pose->end_m.x(), 0.0, 1e-15);
  EXPECT_NEAR(pose->end_m.y(), y, 1e-15);
  EXPECT_NEAR(pose->elbow_m[0].x(), -half, 1e-15);
  EXPECT_NEAR(pose->elbow_m[1].x(), half, 1e-15);
  // By symmetry a common rotation rate of the two motors in opposite senses moves the end
  // point straight up or down: J (1, -1) has no x component.
  const Eigen::Vector2d v = pose->jacobian_m_per_rad * Eigen::Vector2d(1.0, -1.0);
  EXPECT_NEAR(v.x(), 0.0, 1e-15);
}

TEST(FiveBar, EndPointMeetsBothDistalLinksOnTheWorkingSide) {
  for (const FiveBarGeometry& g : {symmetric(), uneven()}) {
    for (double q1 = 1.4; q1 <= 2.8; q1 += 0.1) {
      for (double q2 = 0.3; q2 <= 1.7; q2 += 0.1) {
        const auto pose = forward(g, {q1, q2});
        if (!pose) continue;
        for (int i = 0; i < 2; ++i) {
          EXPECT_NEAR((pose->end_m - pose->elbow_m[i]).norm(), g.distal_m[i], 1e-14);
          EXPECT_NEAR((pose->elbow_m[i] - base(g, i)).norm(), g.proximal_m[i], 1e-14);
        }
        const Eigen::Vector2d b12 = pose->elbow_m[1] - pose->elbow_m[0];
        const Eigen::Vector2d b1p = pose->end_m - pose->elbow_m[0];
        EXPECT_GT(b12.x() * b1p.y() - b12.y() * b1p.x(), 0.0);  // left of B1 -> B2
      }
    }
  }
}

TEST(FiveBar, JacobianMatchesCentralDifferencesOfTheForwardKinematics) {
  int checked = 0;
  for (const FiveBarGeometry& g : {symmetric(), uneven()}) {
    for (double q1 = 1.5; q1 <= 2.7; q1 += 0.15) {
      for (double q2 = 0.4; q2 <= 1.6; q2 += 0.15) {
        const auto pose = forward(g, {q1, q2});
        if (!pose || pose->singularity_distance < 0.1) continue;
        const double h = 1e-6;
        for (int j = 0; j < 2; ++j) {
          Eigen::Vector2d dq = Eigen::Vector2d::Zero();
          dq[j] = h;
          const auto plus = forward(g, Eigen::Vector2d(q1, q2) + dq);
          const auto minus = forward(g, Eigen::Vector2d(q1, q2) - dq);
          ASSERT_TRUE(plus && minus);
          const Eigen::Vector2d fd = (plus->end_m - minus->end_m) / (2 * h);
          // Central differences: error ~ h^2 |P'''| ~ 1e-12 m/rad, rounding ~ 1e-16 / h.
          EXPECT_NEAR((fd - pose->jacobian_m_per_rad.col(j)).norm(), 0.0, 1e-8)
              << "q = " << q1 << ", " << q2 << ", column " << j;
        }
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 100);
}

TEST(FiveBar, JointTorquesAreTheStaticsOfTheTwoForceDistalLinks) {
  // A force F on the end point splits along the two distal links (pin-jointed at both ends,
  // they carry only axial force): F = c1 u1 + c2 u2. Link i presses on its elbow with c_i u_i,
  // whose moment about the motor axis A_i is the torque F produces at joint i, the generalised
  // force of virtual work, J^T F.
  const FiveBarGeometry g = uneven();
  const Eigen::Vector2d forces[] = {{1.0, 0.0}, {0.0, 1.0}, {-0.7, 2.3}};
  for (const Eigen::Vector2d& q :
       {Eigen::Vector2d(2.0, 1.0), Eigen::Vector2d(2.4, 0.7), Eigen::Vector2d(1.7, 1.3)}) {
    const auto pose = forward(g, q);
    ASSERT_TRUE(pose.has_value());
    Eigen::Matrix2d u;
    for (int i = 0; i < 2; ++i) u.col(i) = (pose->end_m - pose->elbow_m[i]) / g.distal_m[i];
    for (const Eigen::Vector2d& f : forces) {
      const Eigen::Vector2d c = u.fullPivLu().solve(f);
      const Eigen::Vector2d tau = joint_torques_Nm(*pose, f);
      for (int i = 0; i < 2; ++i) {
        const Eigen::Vector2d r = pose->elbow_m[i] - base(g, i);
        const Eigen::Vector2d push = c[i] * u.col(i);
        EXPECT_NEAR(tau[i], r.x() * push.y() - r.y() * push.x(), 1e-12);
      }
    }
  }
}

TEST(FiveBar, InverseKinematicsUndoesTheForward) {
  int checked = 0;
  for (const FiveBarGeometry& g : {symmetric(), uneven()}) {
    for (double q1 = 1.5; q1 <= 2.7; q1 += 0.2) {
      for (double q2 = 0.4; q2 <= 1.6; q2 += 0.2) {
        const auto pose = forward(g, {q1, q2});
        if (!pose || pose->singularity_distance < 0.05) continue;
        const auto q = inverse(g, pose->end_m);
        ASSERT_TRUE(q.has_value()) << q1 << ", " << q2;
        EXPECT_NEAR((*q)[0], q1, 1e-9);
        EXPECT_NEAR((*q)[1], q2, 1e-9);
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 40);
  // Out of reach of the first arm (beyond a1 + b1 from A1): no joint angles.
  EXPECT_FALSE(inverse(symmetric(), {-0.05, 0.2501}).has_value());
}

// |sin| of a triangle's angle opposite side `opposite`, from its three sides.
double sin_angle(double side1, double side2, double opposite) {
  const double c = (side1 * side1 + side2 * side2 - opposite * opposite) / (2 * side1 * side2);
  return std::sqrt(std::max(0.0, 1.0 - c * c));
}

TEST(FiveBar, SingularityDistanceIsTheSmallestTransmissionAngleSine) {
  for (const FiveBarGeometry& g : {symmetric(), uneven()}) {
    for (const Eigen::Vector2d& q :
         {Eigen::Vector2d(2.0, 1.0), Eigen::Vector2d(2.6, 0.5), Eigen::Vector2d(1.6, 1.5)}) {
      const auto pose = forward(g, q);
      ASSERT_TRUE(pose.has_value());
      // Triangles: B1 P B2 (angle at P between the distal links), A_i B_i P (angle at B_i).
      const double between = (pose->elbow_m[1] - pose->elbow_m[0]).norm();
      double expected = sin_angle(g.distal_m[0], g.distal_m[1], between);
      for (int i = 0; i < 2; ++i) {
        const double reach = (pose->end_m - base(g, i)).norm();
        expected = std::min(expected, sin_angle(g.proximal_m[i], g.distal_m[i], reach));
      }
      EXPECT_NEAR(pose->singularity_distance, expected, 1e-12);
    }
  }
  // Elbows b1 + b2 apart: the distal links in line, no assembly; a hair closer, distance ~ 0.
  const FiveBarGeometry g = symmetric();
  // Symmetric q1 = pi - q2: elbow separation s + 2 a cos q2 = 0.30 at cos q2 = 1.
  EXPECT_FALSE(forward(g, {kPi, 0.0}).has_value());
  const auto near = forward(g, {kPi - 0.01, 0.01});
  ASSERT_TRUE(near.has_value());
  EXPECT_LT(near->singularity_distance, 0.05);
}

TEST(FiveBar, GeometryCheckNamesWhatIsWrong) {
  EXPECT_STREQ(check(symmetric()), "");
  FiveBarGeometry g = symmetric();
  g.distal_m[1] = 0.0;
  EXPECT_STREQ(check(g), "distal link lengths must be positive");
  g = symmetric();
  g.proximal_m[0] = std::nan("");
  EXPECT_STREQ(check(g), "every length must be finite");
  g = symmetric();
  g.base_separation_m = -0.01;
  EXPECT_STREQ(check(g), "base_separation_m must not be negative");
}

}  // namespace
}  // namespace teleop::kinematics
