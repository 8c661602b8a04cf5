#include "common/kinematics/five_bar.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

namespace teleop::kinematics {

namespace {

Eigen::Vector2d base_joint(const FiveBarGeometry& g, int i) noexcept {
  return {i == 0 ? -0.5 * g.base_separation_m : 0.5 * g.base_separation_m, 0.0};
}

// 2-D cross product (z component).
double cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) noexcept {
  return a.x() * b.y() - a.y() * b.x();
}

// |sin| of the angle between two non-zero vectors.
double sin_between(const Eigen::Vector2d& a, const Eigen::Vector2d& b) noexcept {
  return std::abs(cross(a, b)) / (a.norm() * b.norm());
}

// The point at distance r0 from c0 and r1 from c1 on the left of c0 -> c1 (sign +1) or on its
// right (-1); nullopt when the circles do not meet in two points.
std::optional<Eigen::Vector2d> circles(const Eigen::Vector2d& c0, double r0,
                                       const Eigen::Vector2d& c1, double r1, double sign) noexcept {
  const Eigen::Vector2d v = c1 - c0;
  const double d = v.norm();
  if (!(d > 0.0) || d >= r0 + r1 || d <= std::abs(r0 - r1)) return std::nullopt;
  const double along = (r0 * r0 - r1 * r1 + d * d) / (2.0 * d);
  const double h = std::sqrt(std::max(0.0, r0 * r0 - along * along));
  const Eigen::Vector2d u = v / d;
  const Eigen::Vector2d left(-u.y(), u.x());
  return c0 + along * u + sign * h * left;
}

}  // namespace

const char* check(const FiveBarGeometry& g) noexcept {
  const double all[] = {g.base_separation_m, g.proximal_m[0], g.proximal_m[1], g.distal_m[0],
                        g.distal_m[1]};
  for (const double v : all) {
    if (!std::isfinite(v)) return "every length must be finite";
  }
  if (g.base_separation_m < 0.0) return "base_separation_m must not be negative";
  for (int i = 0; i < 2; ++i) {
    if (!(g.proximal_m[i] > 0.0)) return "proximal link lengths must be positive";
    if (!(g.distal_m[i] > 0.0)) return "distal link lengths must be positive";
  }
  return "";
}

std::optional<FiveBarPose> forward(const FiveBarGeometry& g,
                                   const Eigen::Vector2d& q_rad) noexcept {
  FiveBarPose pose;
  Eigen::Vector2d elbow_rate[2];  // dB_i/dq_i
  for (int i = 0; i < 2; ++i) {
    const double a = g.proximal_m[i];
    const Eigen::Vector2d dir(std::cos(q_rad[i]), std::sin(q_rad[i]));
    pose.elbow_m[i] = base_joint(g, i) + a * dir;
    elbow_rate[i] = a * Eigen::Vector2d(-dir.y(), dir.x());
  }
  const auto p = circles(pose.elbow_m[0], g.distal_m[0], pose.elbow_m[1], g.distal_m[1], 1.0);
  if (!p) return std::nullopt;
  pose.end_m = *p;
  // |P - B_i|^2 = b_i^2, differentiated: (P - B_i)^T (dP - dB_i) = 0, so
  // [ (P - B_1)^T ; (P - B_2)^T ] dP = diag((P - B_i)^T dB_i/dq_i) dq.
  const Eigen::Vector2d d0 = pose.end_m - pose.elbow_m[0];
  const Eigen::Vector2d d1 = pose.end_m - pose.elbow_m[1];
  Eigen::Matrix2d a;
  a.row(0) = d0.transpose();
  a.row(1) = d1.transpose();
  const double det = a.determinant();
  if (!(std::abs(det) > 0.0)) return std::nullopt;
  Eigen::Matrix2d b = Eigen::Matrix2d::Zero();
  b(0, 0) = d0.dot(elbow_rate[0]);
  b(1, 1) = d1.dot(elbow_rate[1]);
  pose.jacobian_m_per_rad = a.inverse() * b;
  const Eigen::Vector2d r0 = pose.elbow_m[0] - base_joint(g, 0);
  const Eigen::Vector2d r1 = pose.elbow_m[1] - base_joint(g, 1);
  pose.singularity_distance =
      std::min({sin_between(d0, d1), sin_between(r0, d0), sin_between(r1, d1)});
  return pose;
}

std::optional<Eigen::Vector2d> inverse(const FiveBarGeometry& g,
                                       const Eigen::Vector2d& p_m) noexcept {
  Eigen::Vector2d q;
  for (int i = 0; i < 2; ++i) {
    const Eigen::Vector2d a = base_joint(g, i);
    // The elbow: at a_i from A_i and b_i from P; on the outer side (left of P -> A_1 for the
    // first arm, right of P -> A_2 for the second), the mode `forward` assembles.
    const auto elbow = circles(p_m, g.distal_m[i], a, g.proximal_m[i], i == 0 ? -1.0 : 1.0);
    if (!elbow) return std::nullopt;
    const Eigen::Vector2d r = *elbow - a;
    q[i] = std::atan2(r.y(), r.x());
  }
  return q;
}

}  // namespace teleop::kinematics
