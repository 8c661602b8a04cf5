// The simulated n-axis haptic device (issue 18, "Devices" and "Simulation"; docs/plant-axes.md
// "The n-axis device"): SimDevice (sim_device.hpp) for n = 1..6 task-space axes on the exact
// n-axis plant sim::PlantAxes, with joint encoders quantised in joint space through the
// device's kinematics, a load cell and an amplifier per task axis, the human on the master side
// and contact planes on the slave side.
//
// Kinematics. The plant's state is the handle's task-space position x (and velocity); the joints
// are what the encoders see:
//  - kCartesian: one joint per task axis, a capstan of metres_per_radian: q_i = x_i / r_i.
//  - kFiveBar: axes 0 and 1 are the end point of the planar five-bar (kinematics/five_bar.hpp)
//    relative to five_bar_home_m, their joints the two actuated angles q = IK(home + x); any
//    further axes are Cartesian as above.
// Each joint angle is quantised by its encoder (counts_per_rev * transmission_ratio counts per
// joint revolution, origin at the centre of a count, as sim::Encoder) and the sample's position
// is the forward kinematics of the quantised angles: on a five-bar one count of joint i moves
// the reading by about |J e_i| * 2 pi / counts, J the linkage's Jacobian at the pose.
//
// Forces. The command is a task-space force applied as is to the task-space plant. A real
// five-bar would drive its joints with tau = J^T F, and by virtual work (tau^T dq = F^T J dq =
// F^T dx) the handle then feels exactly F, so the mapping needs no simulation; the plant's mass
// matrix M is the task-space mass at the working pose, held constant (its dependence on the pose
// is not modelled). The amplifier clips each task axis to +-max_force_N (kAmplifierSaturated);
// a command with a non-finite entry, or with the wrong number of entries, is refused as a whole
// (0 N held, kCommandRejected in the next sample), as SimDevice.
//
// Human (master side): an n-axis impedance M_h, B_h, K_h about a set point x_h pushing with a
// profile along a unit direction d: F_h = d f(t) - M_h x'' - B_h x' - K_h (x - x_h), i.e. the
// plant's exogenous force F_h* = d f(t) + K_h x_h. With hold_scene_until_engaged the profile's
// clock stands at 0 with no push (f = 0, the hand still holding its set point) until
// on_engaged(). The load cell reads F_h on the master, and on the slave the force the device
// puts on the planes, -PlantAxesOutput::environment_force_N. The one-axis operator's yielding
// after a coupling ends (SimDeviceConfig::operator_yield_per_s) is not modelled here.
//
// E-stop: set_estop(true) gives 0 N on every axis and flags kFault, as does an inactive device
// (without the flag). The period is the configured one: PlantAxes has its propagators for that
// period only, and tick() with another period is refused (kInvalidArgument).
#pragma once

#include <Eigen/Core>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/core/rt_safe.hpp"
#include "common/device/haptic_device_axes.hpp"
#include "common/kinematics/five_bar.hpp"
#include "common/sim/human.hpp"
#include "common/sim/plant_axes.hpp"
#include "common/sim/sensors.hpp"

namespace teleop::device {

enum class DeviceKinematics { kCartesian, kFiveBar };

// The human holding the master's handle.
struct SimHumanAxes {
  HumanImpedanceAxes impedance{};  // M_h, B_h, K_h: n x n (empty: zero)
  Eigen::VectorXd set_point_m{};   // x_h, n entries (empty: the origin)
  Eigen::VectorXd direction{};     // d, n entries, unit length
  sim::ForceProfile profile{};     // f(t) along d (N)
  sim::ProfileSampling sampling{sim::ProfileSampling::kZeroOrderHold};
};

struct SimDeviceAxesConfig {
  std::chrono::nanoseconds period{std::chrono::milliseconds{1}};
  // Device (M, B, C; n from M) and the slave's environment (plant.planes). plant.human is
  // replaced by human->impedance when a human is set.
  sim::PlantAxesParams plant{};
  std::optional<SimHumanAxes> human{};
  DeviceKinematics kinematics{DeviceKinematics::kCartesian};
  kinematics::FiveBarGeometry five_bar{};     // kFiveBar only
  Eigen::Vector2d five_bar_home_m{0.0, 0.0};  // kFiveBar: end point where x_0 = x_1 = 0
  // One per joint (n entries; empty: sim::EncoderParams{} for every joint). On the five-bar's
  // two joints metres_per_radian is not used.
  std::vector<sim::EncoderParams> encoders{};
  // false: SampleAxes::position_m is the true task position (no encoder, no kinematics).
  bool quantize_position{true};
  sim::LoadCellParams load_cell{};   // every axis; axis i's noise seeded with seed + i
  sim::AmplifierParams amplifier{};  // every axis
  std::uint64_t seed{1};
  Eigen::VectorXd initial_position_m{};        // n entries (empty: the origin)
  Eigen::VectorXd initial_velocity_m_per_s{};  // n entries (empty: at rest)
  bool hold_scene_until_engaged{false};

  [[nodiscard]] int axes() const noexcept { return plant.axes(); }
};

// Ground truth for logging and tests (never available from a real device).
struct SimTruthAxes {
  double time_s{0.0};
  sim::PlantAxesState state{};
  sim::PlantAxesOutput output{};
  AxisVector applied_force_N{};   // after the amplifier, over the last period
  AxisVector human_push_N{};      // F_h* at the start of the last period (zero without a human)
  AxisVector joint_angles_rad{};  // the quantised joint angles of the last sample
};

class SimDeviceAxes final : public HapticDeviceAxes {
 public:
  explicit SimDeviceAxes(SimDeviceAxesConfig config);

  // Builds plant, sensors and human from the configuration (errors name the field), resets time
  // to 0, the state to the initial one and the noise to the seed.
  Status configure() override;
  // Enables the amplifier and publishes a sample of the current state.
  Status activate() override;
  // Disables the amplifier (0 N); the physics keeps running under tick().
  Status deactivate() override;
  [[nodiscard]] int axes() const noexcept override { return config_.axes(); }
  TELEOP_RT Status read(SampleAxes& sample) noexcept override;
  TELEOP_RT Status write(const CommandAxes& command) noexcept override;
  // One period of physics with the held command, then a new sample. Needs configure() and the
  // configured period.
  TELEOP_RT Status tick(std::chrono::nanoseconds period) noexcept override;
  TELEOP_RT void on_engaged() noexcept override;

  // The simulated e-stop button: while engaged the actuator gives 0 N and samples carry kFault.
  void set_estop(bool engaged) noexcept { estop_ = engaged; }

  [[nodiscard]] SimTruthAxes truth() const noexcept;
  [[nodiscard]] const SimDeviceAxesConfig& config() const noexcept { return config_; }
  // Valid after configure().
  [[nodiscard]] const sim::PlantAxes& plant() const { return *plant_; }

 private:
  enum class Stage { kUnconfigured, kInactive, kActive };

  void validate() const;
  TELEOP_RT void take_sample(std::uint32_t flags) noexcept;
  // The sensed task position of x (quantised through the kinematics); false when the five-bar
  // cannot reach x or its quantised angles do not assemble.
  TELEOP_RT [[nodiscard]] bool sense(const AxisVector& x, AxisVector& sensed) noexcept;

  SimDeviceAxesConfig config_;
  int n_{0};
  Stage stage_{Stage::kUnconfigured};
  std::optional<sim::PlantAxes> plant_{};
  std::optional<sim::Human> human_{};  // the push profile f(t)
  std::vector<sim::Encoder> encoders_{};
  std::vector<sim::LoadCell> load_cells_{};
  std::optional<sim::Amplifier> amplifier_{};
  std::chrono::nanoseconds time_{0};
  bool scene_started_{false};
  std::chrono::nanoseconds scene_origin_{0};
  AxisVector direction_{};
  AxisVector hold_N_{};  // K_h x_h
  AxisVector command_N_{};
  bool saturated_{false};
  bool command_rejected_{false};
  bool estop_{false};
  AxisVector applied_N_{};
  AxisVector push_N_{};
  AxisVector slope_N_per_s_{};
  AxisVector joints_rad_{};
  SampleAxes sample_{};
  std::string error_{};
};

}  // namespace teleop::device
