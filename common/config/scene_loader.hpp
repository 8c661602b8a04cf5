// The `scene` section of a SystemConfig as a lockstep-simulator setup.
#pragma once

#include "common/config/config_loader.hpp"
#include "common/scene/scene_setup.hpp"

namespace teleop::config {

// Validates, requires scene.duration_s and what the scene needs (the teleoperator's sections
// for the paddles, force_loop for a force_device scene), and fills the devices, the human, the
// environment and the laws. Throws ConfigError naming the file, line and field.
[[nodiscard]] scene::SceneSetup to_scene_setup(const LoadedConfig& config);

}  // namespace teleop::config
