// The one configuration pipeline (docs/architecture.md §6): a SystemConfig validated once and
// turned into the whole typed system, every left-out field from common/core/defaults.hpp. The
// nodes, the supervisor and the tools take their parameters from here; nothing downstream reads
// the file again or validates it again.
//
//   const CompiledSystem system = compile_system_file(path, overrides);  // parse, --set, compile
//   NodeSetup slave = system.node(transport::Role::kSlave);
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/core/teleop_params.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::config {

// The supervisor's own settings (teleop.v1.Supervisor), defaults filled in.
struct SupervisorSettings {
  std::string report_endpoint{};   // reports, alarms, status (PUB)
  std::string request_endpoint{};  // requests (REP)
  // A sustained oscillation above this is an alarm (default: kOscillationThreshold_counts of
  // the master's encoder counts).
  double oscillation_threshold_m{0.0};
  double passivity_threshold_J{0.0};
  double passivity_power_threshold_W{0.0};
  double escalation_ms{0.0};   // an alarm persisting this long lowers; this long again, disengage
  double change_ramp_ms{0.0};  // ramp of every accepted parameter change
  // Session retention: files and bytes kept in the record directory (0: no limit).
  std::uint32_t max_sessions{0};
  std::uint64_t max_sessions_bytes{0};
  std::vector<std::string> read_only_client_keys{};  // security.read_only_client_public_keys
};

class CompiledSystem;

// Validates the whole file once (validate(), then the teleoperator's sections, both nodes'
// sections and the scene's as far as the nodes' simulated devices use them) and returns the
// typed system. Throws ConfigError naming file, line and field of every problem.
//
// Each node's simulated device is the scene's (`scene`, when present: the human's push and the
// environment, its seed and `ideal`), on hold until the node engages; without a scene the human
// holds the handle without pushing (human.fixed, or the middle of human.band at its lowest force
// level) and the slave is in free space: the same builder as `teleopctl simulate`
// (simulated_sides.hpp), so a live run and a lockstep run of one file agree.
[[nodiscard]] CompiledSystem compile_system(LoadedConfig config);

// parse_config_file, then compile_system: one validation from file to system.
[[nodiscard]] CompiledSystem compile_system_file(const std::filesystem::path& path,
                                                 const std::vector<std::string>& overrides = {});

// The typed system. Only compile_system makes one, so holding one means the file passed.
class CompiledSystem {
 public:
  // The configuration as loaded (for recording it and for error locations).
  [[nodiscard]] const LoadedConfig& source() const noexcept { return source_; }
  // The teleoperator the stability engine analyses (the file's human, band or fixed).
  [[nodiscard]] const TeleopParams& teleop() const noexcept { return teleop_; }
  // A node's setup: law, simulated device, device kind, link timing, endpoints, keys, RT and
  // process settings, configuration fingerprint. Throws std::invalid_argument for another role.
  [[nodiscard]] const NodeSetup& node(transport::Role role) const;
  [[nodiscard]] const SupervisorSettings& supervisor() const noexcept { return supervisor_; }
  // experiment.allow_unstable: arm and engage even when the analysis refuses.
  [[nodiscard]] bool allow_unstable() const noexcept { return allow_unstable_; }

 private:
  friend CompiledSystem compile_system(LoadedConfig config);
  CompiledSystem() = default;

  LoadedConfig source_{};
  TeleopParams teleop_{};
  NodeSetup master_{};
  NodeSetup slave_{};
  SupervisorSettings supervisor_{};
  bool allow_unstable_{false};
};

}  // namespace teleop::config
