// The teleoperator with n task-space axes (issue 18; docs/architecture.md §2): the vector form of
// teleop_params.hpp. One axis (n = 1) is today's teleoperator exactly: `to_axes` embeds a
// TeleopParams. Plain data, no protobuf, no I/O: the configuration loader fills it, the n-axis
// stability engine, law and simulator read it.
//
// Conventions: task-space positions x (m, n-vector) and forces F (N, n-vector) at the handle;
// matrices n x n in SI units (kg, N s/m, N/m). A matrix of gains defaults to a diagonal.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "common/core/teleop_params.hpp"

namespace teleop {

inline constexpr int kMaxAxes = 6;
// Fixture planes a side may have (the law holds them in fixed storage: control::kMaxPlanes).
inline constexpr int kMaxPlanesPerSide = 8;

// A device as felt at the handle in task space: M v' + B v + C sgn(v) = F (Vlachos-Papadopoulos
// eqs. 5-6 with the kinematics folded into M). B and C are diagonal (per task axis).
struct DeviceAxesParams {
  Eigen::MatrixXd mass_kg{};           // n x n, symmetric positive definite
  Eigen::VectorXd damping_Ns_per_m{};  // n, the diagonal of B, >= 0
  Eigen::VectorXd coulomb_N{};         // n, the diagonal of C, >= 0 (the simulator's friction)
};

// A forbidden region bounded by a plane: inside where normal^T x > offset_m, and there the
// fixture pushes F = -stiffness (normal^T x - offset_m) normal; outside nothing. `normal` has
// unit length. The one-axis FixtureParams is the plane normal = (+1), offset = position_m.
struct PlaneFixtureParams {
  Eigen::VectorXd normal{};  // n, |normal| = 1
  double offset_m{0.0};
  double stiffness_N_per_m{0.0};
};

// The three-channel law's gains as n x n matrices (eqs. 8-9 in task space): kp* N/m, kd*/kv*
// N s/m, kfm dimensionless.
struct GainsAxes {
  Eigen::MatrixXd kpm{};
  Eigen::MatrixXd kps{};
  Eigen::MatrixXd kdm{};
  Eigen::MatrixXd kds{};
  Eigen::MatrixXd kvm{};
  Eigen::MatrixXd kvs{};
  Eigen::MatrixXd kfm{};
};

// The human as an n-axis impedance: fixed matrices, or a band per axis (each axis's mass,
// damping and stiffness bounded against grip force as in the one-axis HumanBand; the axes are
// independent and the worst case is taken over every axis's band).
struct HumanImpedanceAxes {
  Eigen::MatrixXd mass_kg{};
  Eigen::MatrixXd damping_Ns_per_m{};
  Eigen::MatrixXd stiffness_N_per_m{};
};

struct HumanModelAxes {
  HumanKind kind{HumanKind::kBand};
  HumanImpedanceAxes fixed{};
  std::vector<HumanBand> band_per_axis{};  // n entries when kind is kBand
};

struct TeleopAxesParams {
  int axes{1};
  double sample_rate_hz{0.0};
  DeviceAxesParams master_device{};
  DeviceAxesParams slave_device{};
  std::vector<PlaneFixtureParams> master_planes{};
  std::vector<PlaneFixtureParams> slave_planes{};
  GainsAxes gains{};
  Scaling scaling{};               // alpha (position) and beta (force), scalars on every axis
  double velocity_cutoff_hz{0.0};  // 0: plain backward difference, on every axis
  int round_trip_delay_samples{0};
  HumanModelAxes human{};
  AnalysisSettings analysis{};

  [[nodiscard]] double period_s() const { return 1.0 / sample_rate_hz; }
};

// The one-axis teleoperator as n = 1: 1 x 1 matrices, one plane per side with normal (+1) at
// the fixture's position (kept even when its stiffness is 0, as the one-axis fixture is).
[[nodiscard]] TeleopAxesParams to_axes(const TeleopParams& p);

}  // namespace teleop
