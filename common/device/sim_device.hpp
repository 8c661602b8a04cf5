// The simulated haptic device (docs/architecture.md §1.4: simulation is the default device): the
// plant, its sensors and actuator, and the human (master side) or environment (slave side) in the
// same physics step.
//
// Time is the device's own: advance(period) steps the physics one control period with the last
// written command and takes the next sample. The lockstep simulator calls it once per period; a
// real-time node calls it from its device thread at the loop rate. Sensors are sampled at the end
// of each period (the left limit, before the next command applies); read() returns that sample.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

#include "common/core/rt_safe.hpp"
#include "common/device/haptic_device.hpp"
#include "common/sim/human.hpp"
#include "common/sim/plant.hpp"
#include "common/sim/sensors.hpp"

namespace teleop::device {

struct SimDeviceConfig {
  std::chrono::nanoseconds period{std::chrono::milliseconds{1}};
  // The haptic-paddle slave of Abbott-Okamura §4.1 (with its Delrin cap) in free space.
  sim::PlantParams plant{DeviceParams{0.036, 0.49}};
  // Master side: the human holding the handle. Its impedance replaces plant.human, and the load
  // cell measures the human's force F_h; without a human it measures the environment force F_e.
  std::optional<sim::HumanParams> human{};
  sim::EncoderParams encoder{};
  // false: Sample::position_m is the true position (the analyser's assumptions, no encoder).
  bool quantize_position{true};
  sim::LoadCellParams load_cell{};
  sim::AmplifierParams amplifier{};
  std::uint64_t seed{1};
  double initial_position_m{0.0};
  // A live node's device: the scene's clock (the human's push, a malicious user's schedule)
  // stands at 0 with no push until on_engaged(); the lockstep simulator starts it at once.
  bool hold_scene_until_engaged{false};
  // The e-stop button pressed over [press, release) of scene time (release absent: held).
  std::optional<double> estop_press_at_s{};
  std::optional<double> estop_release_at_s{};
  // The operator once a coupling has ended (on_disengaged(); only live nodes call it). A real
  // operator feels the teleoperator let go, and while it aligns follows the guiding force; a
  // hand's push (1.5 N in the demo) is far above the centring force, which is capped so it can
  // never overpower a hand (0.5 N), so alignment needs the operator's cooperation. The
  // simulated operator holds the push F_h* they had and yields to the actuator force F they
  // feel, moving their set point along it: dF_h*/dt = operator_yield_per_s * F (with the
  // human's stiffness k_h that is a set point moving at operator_yield_per_s / k_h m/s per N).
  // No force felt (armed, safe): the push is held. Engaged again (on_engaged()), the push
  // returns to the scene's profile linearly over operator_rejoin_s. Scene time runs on
  // meanwhile (a scheduled e-stop keeps its times). operator_yield_per_s = 0: a push held
  // rigidly (the demo then cannot re-align, as before).
  double operator_yield_per_s{5.0};
  double operator_rejoin_s{1.0};

  // The paper's master paddle (0.040 kg, 0.41 Ns/m) held by a human.
  [[nodiscard]] static SimDeviceConfig paddle_master(sim::HumanParams human);
  // The paper's slave paddle (0.036 kg, 0.49 Ns/m) touching an environment.
  [[nodiscard]] static SimDeviceConfig paddle_slave(sim::Environment environment);
};

// Ground truth for logging and tests (never available from a real device).
struct SimTruth {
  double time_s{0.0};
  sim::PlantState state{};
  sim::PlantOutput output{};
  double applied_force_N{0.0};                   // after the amplifier, over the last period
  HumanImpedance human{};                        // the impedance in effect over the last period
  std::optional<std::size_t> malicious_index{};  // the malicious user's schedule position
  double human_push_N{0.0};          // F_h* at the start of the last period (0 without a human)
  bool operator_cooperating{false};  // after a coupling ended, until engaged again
};

class SimDevice final : public HapticDevice {
 public:
  explicit SimDevice(SimDeviceConfig config);

  // Builds plant, sensors and human from the configuration (errors name the field), resets
  // time to 0, the state to the initial position and the noise to the seed.
  Status configure() override;
  // Enables the amplifier and publishes a sample of the current state.
  Status activate() override;
  // Disables the amplifier (0 N); the physics keeps running under advance().
  Status deactivate() override;
  TELEOP_RT Status read(Sample& sample) noexcept override;
  // A non-finite command is refused (kInvalidArgument, 0 N held, flagged in the next sample).
  TELEOP_RT Status write(const Command& command) noexcept override;

  // One control period of physics with the held command, then a new sample. RT-safe at the
  // configured period; another period rebuilds the propagators first (slow, still no
  // allocation). Needs configure(); inactive or e-stopped, the actuator gives 0 N.
  TELEOP_RT Status advance(std::chrono::nanoseconds period) noexcept;
  // The node's cycle end: advance(period).
  TELEOP_RT Status tick(std::chrono::nanoseconds period) noexcept override {
    return advance(period);
  }
  TELEOP_RT void on_engaged() noexcept override;
  TELEOP_RT void on_disengaged() noexcept override;

  // The simulated e-stop button: while engaged the actuator gives 0 N and samples carry kFault.
  void set_estop(bool engaged) noexcept { estop_ = engaged; }

  [[nodiscard]] SimTruth truth() const noexcept;
  [[nodiscard]] const SimDeviceConfig& config() const noexcept { return config_; }
  // Valid after configure().
  [[nodiscard]] const sim::Plant& plant() const { return *plant_; }

 private:
  enum class Stage { kUnconfigured, kInactive, kActive };

  TELEOP_RT void take_sample(std::uint32_t flags) noexcept;

  SimDeviceConfig config_;
  Stage stage_{Stage::kUnconfigured};
  std::optional<sim::Plant> plant_{};
  std::optional<sim::Human> human_{};
  std::optional<sim::Encoder> encoder_{};
  std::optional<sim::LoadCell> load_cell_{};
  std::optional<sim::Amplifier> amplifier_{};
  std::chrono::nanoseconds time_{0};
  std::optional<std::chrono::nanoseconds> scene_origin_{};  // device time the scene started
  sim::AmplifierOutput command_{};
  bool command_rejected_{false};
  bool estop_{false};
  double applied_force_N_{0.0};
  HumanImpedance current_human_{};
  std::optional<std::size_t> malicious_index_{};
  // The operator after a coupling ended (SimDeviceConfig::operator_yield_per_s).
  TELEOP_RT [[nodiscard]] double scene_time_s() const noexcept;
  double last_push_N_{0.0};
  bool cooperating_{false};
  double held_push_N_{0.0};
  bool rejoining_{false};
  double rejoin_start_s_{0.0};
  double rejoin_offset_N_{0.0};
  Sample sample_{};
  std::string error_{};
};

}  // namespace teleop::device
