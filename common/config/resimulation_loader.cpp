#include "common/config/resimulation_loader.hpp"

#include <stdexcept>

#include "common/config/axes_config.hpp"
#include "common/config/axes_scene_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/scene/lockstep.hpp"

namespace teleop::config {
namespace {

// The recorded configuration again only when overrides made `config` another one: each
// configuration is validated once (to_scene_setup / compile_system).
[[nodiscard]] bool same_configuration(const LoadedConfig& a, const LoadedConfig& b) {
  return a.config.SerializeAsString() == b.config.SerializeAsString();
}

}  // namespace

std::optional<Resimulation> to_resimulation(const LoadedConfig& config,
                                            const LoadedConfig& recorded, double recorded_master0_m,
                                            double recorded_slave0_m) {
  Resimulation out;
  scene::ResimulationSetup& r = out.setup;
  r.master0_m = recorded_master0_m;
  r.slave0_m = recorded_slave0_m;
  TeleopParams params;
  if (config.config.has_scene()) {
    const scene::SceneSetup setup = to_scene_setup(config);
    if (setup.force_device) return std::nullopt;
    params = setup.teleop;
    r.law = setup.law;
    r.slave = setup.slave;
    out.recorded_slave =
        same_configuration(config, recorded) ? setup.slave : to_scene_setup(recorded).slave;
    r.master0_m = setup.master.initial_position_m;
    r.slave0_m = setup.slave.initial_position_m;
    if (setup.equilibrium_perturbation_m) {
      const scene::Equilibrium eq =
          scene::static_equilibrium(setup.teleop, setup.equilibrium_push_N);
      r.master0_m = eq.master_m;
      r.slave0_m = eq.slave_m + *setup.equilibrium_perturbation_m;
      r.law.clutch_fade_s = 0.0;
    }
  } else {
    const CompiledSystem system = compile_system(config);
    const NodeSetup& node = system.node(transport::Role::kSlave);
    params = system.teleop();
    r.law = node.settings.law;
    r.slave = node.sim;
    r.slave.hold_scene_until_engaged = false;
    out.recorded_slave = same_configuration(config, recorded)
                             ? node.sim
                             : compile_system(recorded).node(transport::Role::kSlave).sim;
  }
  r.sample_rate_hz = params.sample_rate_hz;
  r.round_trip_delay_samples = static_cast<std::size_t>(params.round_trip_delay_samples);
  r.position_scaling = params.scaling.position;
  r.slave_fixture = params.slave_fixture;
  return out;
}

scene::AxesResimulationSetup to_axes_resimulation(const LoadedConfig& config,
                                                  const Eigen::VectorXd& recorded_master0_m,
                                                  const Eigen::VectorXd& recorded_slave0_m) {
  scene::AxesResimulationSetup r;
  TeleopAxesParams params;
  if (config.config.has_scene()) {
    const scene::AxesSceneSetup setup = to_axes_scene_setup(config);
    scene::AxesStart start;
    try {
      start = scene::axes_start(setup);
    } catch (const std::invalid_argument& e) {
      throw ConfigError(config.source_name + ": " + e.what());
    }
    params = setup.teleop;
    r.law = start.law;
    r.slave_device = setup.teleop.slave_device;
    r.slave_environment = setup.slave_environment;
    r.master0_m = start.master_m;
    r.slave0_m = start.slave_m;
  } else {
    const NodeSetup node = to_node_axes_setup(config, transport::Role::kSlave);
    params = to_axes_params(config);
    r.law = node.axes_settings.law;
    r.slave_device = node.sim_axes.plant.device;
    r.slave_environment = node.sim_axes.plant.planes;
    r.master0_m = recorded_master0_m;
    r.slave0_m = recorded_slave0_m;
  }
  r.sample_rate_hz = params.sample_rate_hz;
  r.round_trip_delay_samples = params.round_trip_delay_samples;
  r.position_scaling = params.scaling.position;
  r.slave_planes = params.slave_planes;
  return r;
}

}  // namespace teleop::config
