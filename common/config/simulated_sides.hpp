// Inside teleop_config only: the two simulated sides of a SystemConfig (hardware, the human on
// the master, the environment on the slave) and the law with the hardware's limits. One
// builder for both readers, so a live node and a lockstep run of one file agree:
// compile_system (system_compiler.hpp) builds the nodes' devices with it, to_scene_setup
// (scene_loader.hpp) the simulator's.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/control/law_params.hpp"
#include "common/device/sim_device.hpp"

namespace teleop::config {

// Problems with the scene and device sections, one line per problem naming where it is.
class SceneChecks {
 public:
  explicit SceneChecks(const LoadedConfig& c) : config_(c) {}
  void positive(const std::string& path, double v);
  void non_negative(const std::string& path, double v);
  void add(const std::string& path, const std::string& message);
  // Throws ConfigError with every line, in the order added; nothing when none.
  void throw_if_any() const;

 private:
  const LoadedConfig& config_;
  std::vector<std::string> lines_;
};

// Who the sides are for.
enum class SidesFor {
  kScene,  // `teleopctl simulate`: simulated devices only; a band of humans needs
           // scene.malicious_user
  kNode,   // a live node: a USB side gets a simulated stand-in (unused); without
           // scene.malicious_user a band of humans holds the handle as the band's middle at its
           // lowest force level, without pushing
};

struct SimulatedSides {
  // control::from_teleop_params(teleop) with the actuators' limits and the slave's workspace
  // limits (none in an ideal scene).
  control::LawParams law{};
  device::SimDeviceConfig master{};  // with the human (scene.human_force, the human section)
  device::SimDeviceConfig slave{};   // with the environment (scene.environment, free space)
};

// scene.duration_s and scene.output_rate_hz, when present, are > 0.
void check_scene_times(const teleop::v1::Scene& scene, SceneChecks& checks);
// A scene's force profile (scene.human_force as `path`), its problems named under `path`.
[[nodiscard]] sim::ForceProfile scene_force_profile(const teleop::v1::ForceProfile& profile,
                                                    SceneChecks& checks, const std::string& path);

// One side's sensors and actuator; the analyser's assumptions when `ideal`. A USB kind is a
// problem for a scene (check_kind), not for a node's stand-in.
void fill_hardware(const teleop::v1::Device& d, const std::string& path, bool ideal,
                   std::uint64_t seed, bool check_kind, device::SimDeviceConfig& cfg,
                   control::ActuatorLimits& limits, SceneChecks& checks);

// Both sides from a configuration validate() passed and its teleoperator (`teleop`); the
// scene section (all of it optional here) gives the human's push, the environment, the seed and
// `ideal`. Adds every problem to `checks`.
[[nodiscard]] SimulatedSides simulated_sides(const LoadedConfig& config, const TeleopParams& teleop,
                                             SidesFor purpose, SceneChecks& checks);

}  // namespace teleop::config
