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

namespace text_format {
class Problems;
}

// to_teleop_params without its validate(). Refuses axes > 1 and any n-axis field
// (require_one_axis): the one-axis tools never run the first axis of an n-axis file.
[[nodiscard]] TeleopParams teleop_params_of_validated(const LoadedConfig& config);
// The same without that refusal: what the n-axis form shares with the one-axis one
// (axes_config.cpp). Requires the sections the analysis needs.
[[nodiscard]] TeleopParams one_axis_params_of_validated(const LoadedConfig& config);
// A human band section as the analysis reads it (default points per axis filled in).
[[nodiscard]] HumanBand to_band(const teleop::v1::HumanBand& band);
// Several axes (axes_config.cpp): every rule on the n-axis fields, for validate() ...
void check_axes(const LoadedConfig& config, text_format::Problems& problems);
// ... and the one-axis tools' refusal: ConfigError naming `axes` when it is not 1, else each
// n-axis field given.
void require_one_axis(const LoadedConfig& config);
// ... and the scene's n-axis fields (axes_scene_loader.cpp), for validate() through check_axes.
void check_scene_axes(const LoadedConfig& config, text_format::Problems& problems);
// to_force_loop_params without its validate().
[[nodiscard]] ForceLoopParams force_loop_params_of_validated(const LoadedConfig& config);
// One node's setup (node_loader.cpp): its law and simulated device from `sides`, its link,
// endpoints, keys and process settings, and the configuration fingerprint. Throws ConfigError
// naming the field.
[[nodiscard]] NodeSetup node_setup_of_validated(const LoadedConfig& config,
                                                const TeleopParams& teleop,
                                                const SimulatedSides& sides, transport::Role role);

}  // namespace teleop::config
