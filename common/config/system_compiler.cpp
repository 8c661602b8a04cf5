#include "common/config/system_compiler.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <utility>

#include "common/config/config_internal.hpp"
#include "common/config/simulated_sides.hpp"
#include "common/core/defaults.hpp"

namespace teleop::config {
namespace {

namespace v1 = teleop::v1;

// One encoder count of a simulated side, in metres along its arc.
double encoder_count_m(const sim::EncoderParams& e) {
  return 2.0 * std::numbers::pi * e.metres_per_radian / (e.counts_per_rev * e.transmission_ratio);
}

SupervisorSettings supervisor_settings(const v1::SystemConfig& c, const NodeSetup& master) {
  const v1::Supervisor& s = c.supervisor();
  SupervisorSettings out;
  out.report_endpoint = s.report_endpoint().empty()
                            ? std::string(defaults::kSupervisorReportEndpoint)
                            : s.report_endpoint();
  out.request_endpoint = s.request_endpoint().empty()
                             ? std::string(defaults::kSupervisorRequestEndpoint)
                             : s.request_endpoint();
  out.oscillation_threshold_m =
      s.has_oscillation_threshold_m()
          ? s.oscillation_threshold_m()
          : defaults::kOscillationThreshold_counts * encoder_count_m(master.sim.encoder);
  out.passivity_threshold_J =
      s.has_passivity_threshold_j() ? s.passivity_threshold_j() : defaults::kPassivityThreshold_J;
  out.passivity_power_threshold_W = s.has_passivity_power_threshold_w()
                                        ? s.passivity_power_threshold_w()
                                        : defaults::kPassivityPowerThreshold_W;
  out.escalation_ms = s.has_escalation_ms() ? s.escalation_ms()
                                            : static_cast<double>(defaults::kEscalation.count());
  out.change_ramp_ms = s.has_change_ramp_ms() ? s.change_ramp_ms()
                                              : static_cast<double>(defaults::kChangeRamp.count());
  out.max_sessions = s.has_max_sessions() ? s.max_sessions() : defaults::kMaxSessions;
  out.max_sessions_bytes = static_cast<std::uint64_t>(std::llround(
      (s.has_max_sessions_mb() ? s.max_sessions_mb() : defaults::kMaxSessions_MB) * 1e6));
  out.read_only_client_keys.assign(c.security().read_only_client_public_keys().begin(),
                                   c.security().read_only_client_public_keys().end());
  return out;
}

}  // namespace

CompiledSystem compile_system(LoadedConfig config) {
  validate(config);  // the one validation; everything below only reads
  CompiledSystem out;
  out.teleop_ = teleop_params_of_validated(config);
  const v1::SystemConfig& c = config.config;
  if (c.scene().has_force_device()) {
    throw ConfigError(config.source_name +
                      ": scene.force_device: the nodes run the bilateral paddles; a force-device "
                      "scene is for `teleopctl simulate`");
  }
  SceneChecks checks(config);
  check_scene_times(c.scene(), checks);
  const SimulatedSides sides = simulated_sides(config, out.teleop_, SidesFor::kNode, checks);
  checks.throw_if_any();
  // Both sides' sections are checked by either node: one file, one verdict.
  out.master_ = node_setup_of_validated(config, out.teleop_, sides, transport::Role::kMaster);
  out.slave_ = node_setup_of_validated(config, out.teleop_, sides, transport::Role::kSlave);
  out.supervisor_ = supervisor_settings(c, out.master_);
  out.allow_unstable_ = c.experiment().allow_unstable();
  out.source_ = std::move(config);
  return out;
}

CompiledSystem compile_system_file(const std::filesystem::path& path,
                                   const std::vector<std::string>& overrides) {
  return compile_system(parse_config_file(path, overrides));
}

const NodeSetup& CompiledSystem::node(transport::Role role) const {
  if (role == transport::Role::kMaster) return master_;
  if (role == transport::Role::kSlave) return slave_;
  throw std::invalid_argument("CompiledSystem::node: role must be master or slave");
}

}  // namespace teleop::config
