// Several task-space axes in the configuration (issue 18 "Configuration";
// docs/configuration.md "Several axes"): SystemConfig.axes = n in [1, 6], mass matrices, per-axis
// damping and friction, the devices' kinematics (Cartesian or the five-bar linkage), fixture
// planes, gain matrices and a human band per axis, read into TeleopAxesParams
// (common/core/teleop_axes.hpp). Every rule on these fields lives in axes_config.cpp, and
// validate() (config_loader.hpp) applies it to every file and every `--set`, so a tool that
// reads the n-axis fields never sees an unchecked one. Setup code only: allocates, throws.
//
// n = 1 without any n-axis field is today's teleoperator exactly:
// to_axes_params(c) == to_axes(to_teleop_params(c)), plus the simulated device's Coulomb
// friction (coulomb_friction_N), which TeleopParams does not carry.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/kinematics/five_bar.hpp"

namespace teleop::config {

// The smallest transmission-angle |sin| allowed at a five-bar's home pose when the file gives
// none (FiveBar.min_singularity_distance): 0.2, about 11.5 degrees from a singular pose.
inline constexpr double kDefaultMinSingularityDistance = 0.2;

// Two matrices whose mirrored elements differ by more than this, relative to the largest
// |element|, are refused as not symmetric; within it they are symmetrised ((A + A^T) / 2), so
// a matrix computed elsewhere and printed to 17 digits still loads.
inline constexpr double kSymmetryTolerance = 1e-9;

// How one device's encoders map to its task axes.
struct KinematicsConfig {
  enum class Kind { kCartesian, kFiveBar };
  Kind kind{Kind::kCartesian};
  // kFiveBar only: the linkage, the joint angles at home (where task-space x = 0), the end
  // point there in the base frame, and how far home is from a singularity (and the least
  // allowed).
  kinematics::FiveBarGeometry five_bar{};
  Eigen::Vector2d home_joint_rad{Eigen::Vector2d::Zero()};
  Eigen::Vector2d home_end_m{Eigen::Vector2d::Zero()};
  double home_singularity_distance{1.0};
  double min_singularity_distance{kDefaultMinSingularityDistance};
};

// One channel's actuator of a USB device (Device.torque_constant_N_m_per_A or
// force_constant_N_per_A, and amplifier_A_per_count): the DAC value is u = tau / (K_T K_amp).
struct ActuatorGains {
  double torque_constant_per_A{0.0};  // K_T: N m/A on a five-bar joint, N/A on a Cartesian axis
  double amplifier_A_per_count{0.0};  // K_amp
};

// The n-axis teleoperator and what TeleopAxesParams does not hold: each side's kinematics and
// its USB actuators (n entries, or none: the paddle's DAC step on every channel).
struct AxesConfig {
  TeleopAxesParams teleop{};
  KinematicsConfig master_kinematics{};
  KinematicsConfig slave_kinematics{};
  std::vector<ActuatorGains> master_actuators{};
  std::vector<ActuatorGains> slave_actuators{};
};

// v / |v| (a plane's normal, a push's direction), exact also for subnormal elements; empty when
// v is zero or not finite.
[[nodiscard]] Eigen::VectorXd unit_direction(const Eigen::VectorXd& v);

// SystemConfig.axes, 1 when absent (not validated: see validate()).
[[nodiscard]] int configured_axes(const teleop::v1::SystemConfig& config) noexcept;

// Validates, then requires what the analysis needs (sample_rate_hz, both devices, gains, as
// to_teleop_params does) and builds the n-axis teleoperator: scalars hold on every axis, a
// per-axis list is a diagonal, normals are unit. Throws ConfigError naming each field.
[[nodiscard]] AxesConfig to_axes_config(const LoadedConfig& config);
[[nodiscard]] TeleopAxesParams to_axes_params(const LoadedConfig& config);

// The gains of a live n-axis change (ParameterUpdate.gains) by the configuration's rules for
// `gains` (each a scalar on every axis, its diagonal or its n x n matrix, symmetric positive
// semidefinite, within the scalar's ceiling along every direction). Empty `why` when
// acceptable, else one line per problem, each naming the field (gains.kps_matrix: ...).
[[nodiscard]] GainsAxes gains_axes_of(const teleop::v1::Gains& gains, int n, std::string& why);

}  // namespace teleop::config
