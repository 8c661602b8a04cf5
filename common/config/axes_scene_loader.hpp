// The `scene` section of an n-axis configuration (axes > 1) as a setup of the n-axis lockstep
// simulator (common/scene/lockstep_axes.hpp; docs/simulate.md "Several axes").
#pragma once

#include "common/config/config_loader.hpp"
#include "common/scene/lockstep_axes.hpp"

namespace teleop::config {

// Validates, requires scene.duration_s and what the n-axis simulator needs (a fixed human or
// none, human_force_direction with a push), and fills the loop (to_axes_params), the push
// (human_force along human_force_direction), the slave's environment planes, the equilibrium
// start and the output rate. Throws ConfigError naming the file, line and field.
[[nodiscard]] scene::AxesSceneSetup to_axes_scene_setup(const LoadedConfig& config);

}  // namespace teleop::config
