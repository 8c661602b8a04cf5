// Inside teleop_config only: the builders compile_system (system_compiler.hpp) and
// to_scene_setup (scene_loader.hpp) call after their one validate(). Each requires the sections
// it reads, as the public to_* functions do, but does not validate again.
#pragma once

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/simulated_sides.hpp"
#include "common/core/teleop_params.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::config {

// to_teleop_params without its validate().
[[nodiscard]] TeleopParams teleop_params_of_validated(const LoadedConfig& config);
// to_force_loop_params without its validate().
[[nodiscard]] ForceLoopParams force_loop_params_of_validated(const LoadedConfig& config);
// One node's setup (node_loader.cpp): its law and simulated device from `sides`, its link,
// endpoints, keys and process settings, and the configuration fingerprint. Throws ConfigError
// naming the field.
[[nodiscard]] NodeSetup node_setup_of_validated(const LoadedConfig& config,
                                                const TeleopParams& teleop,
                                                const SimulatedSides& sides, transport::Role role);

}  // namespace teleop::config
