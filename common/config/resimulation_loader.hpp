// What `teleopctl replay --resimulate` runs a recorded session's configuration with
// (common/scene/resimulate.hpp), built as the lockstep simulator or the slave node builds it.
#pragma once

#include <optional>

#include "common/config/config_loader.hpp"
#include "common/device/sim_device.hpp"
#include "common/scene/lockstep_axes.hpp"
#include "common/scene/resimulate.hpp"

namespace teleop::config {

struct Resimulation {
  scene::ResimulationSetup setup{};
  // The simulated slave of the recorded configuration, built the same way (for the
  // recording's own oscillation threshold).
  device::SimDeviceConfig recorded_slave{};
};

// `config` (the recorded one with any overrides) and `recorded` (as recorded): with a scene,
// the law and the simulated slave as the lockstep simulator builds them, starting where the
// scene starts (at rest, or at its static equilibrium); without one, as the slave node builds
// them (its scene not held until engaged), starting where the recording did
// (`recorded_master0_m`, `recorded_slave0_m`). nullopt for a force-device scene (no slave).
// Throws ConfigError as to_scene_setup and to_node_setup do.
[[nodiscard]] std::optional<Resimulation> to_resimulation(const LoadedConfig& config,
                                                          const LoadedConfig& recorded,
                                                          double recorded_master0_m,
                                                          double recorded_slave0_m);

// The same for a configuration of several axes (axes > 1, `replay --resimulate` of an n-axis
// session): with a scene, the law, the slave's device and environment as the n-axis lockstep
// simulator builds them (to_axes_scene_setup), starting where it starts (scene::axes_start);
// without one, as the n-axis slave node builds them (to_node_axes_setup: its device's plant,
// free space), starting where the recording did. Throws ConfigError as those do.
[[nodiscard]] scene::AxesResimulationSetup to_axes_resimulation(
    const LoadedConfig& config, const Eigen::VectorXd& recorded_master0_m,
    const Eigen::VectorXd& recorded_slave0_m);

}  // namespace teleop::config
