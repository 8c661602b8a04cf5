// The configuration fingerprint (docs/nodes.md "Before engage"; issue 14 finding 3): a 64-bit hash
// of everything the control law and its stability analysis depend on, taken from the typed,
// validated parameters (defaults applied), never from the text. So the same values written
// differently (field order, 600 or 6e2 or 600.0, a default written out or left absent,
// comments) give the same fingerprint, and a change of any control-relevant value gives another.
// Both nodes and the supervisor compute it from the file each read; the nodes exchange it
// every cycle (NodeState.config_fingerprint) and refuse arm and engage while it differs.
//
// The set (control_fields): sample rate; both devices' mass and damping; both fixtures
// (stiffness, position); the seven gains; position and force scaling; the velocity filter;
// the configured round trip; the human model the analysis takes (kind, fixed impedance or the
// band's force levels, grid and bounding lines); the analysis settings (required damping ratio,
// stiffness tolerance); both actuators' limits and the slave's workspace limits (the law clamps
// to them); the link timing the coupling depends on (peer timeout, engage and safe ramps,
// alignment tolerance, centring spring, damping and force cap); experiment.allow_unstable.
// Not in it: endpoints, keys, real-time and telemetry settings, USB ids, the simulated device's
// sensors and friction, the scene (what a simulated human does), the supervisor's settings.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/core/teleop_params.hpp"
#include "common/node/node_core.hpp"

namespace teleop::config {

// One control-relevant value: its configuration path and its canonical text (doubles in the
// shortest form that round-trips, -0 as 0, "inf" for no limit).
struct ControlField {
  std::string path{};
  std::string value{};
};

// The control-relevant fields of `params` and `settings` (the node's law, machine and
// alignment: role-independent), in a fixed order.
[[nodiscard]] std::vector<ControlField> control_fields(const TeleopParams& params,
                                                       const node::NodeSettings& settings,
                                                       bool allow_unstable);
// Of a whole configuration (validates it as a node does; throws ConfigError).
[[nodiscard]] std::vector<ControlField> control_fields(const LoadedConfig& config);

// FNV-1a 64 of the canonical serialisation (a version line, then "path=value\n" per field);
// never 0 (0 on the wire means "no fingerprint").
[[nodiscard]] std::uint64_t fingerprint(const std::vector<ControlField>& fields);
[[nodiscard]] std::uint64_t control_fingerprint(const LoadedConfig& config);

// "0123456789abcdef": how fingerprints are shown everywhere.
[[nodiscard]] std::string fingerprint_hex(std::uint64_t fingerprint);

// The node's own check of its configuration at start (setup code: runs the stability
// analysis): at a round trip of max(1, configured) samples, worst case over the configured
// human, the verdict must be stable with every mode's damping ratio >= the required one, or
// experiment.allow_unstable must be set.
struct ConfigurationCheck {
  std::string verdict{};  // "stable", "unstable", "uncertain" (or "invalid": not finite)
  double min_damping_ratio{0.0};
  double required_damping_ratio{0.0};
  int round_trip_samples{1};
  bool allow_unstable{false};
  bool permits_coupling{false};
  // Why arm and engage are refused (empty when permitted); names the verdict and zeta.
  std::string refusal{};
};
[[nodiscard]] ConfigurationCheck check_configuration(const TeleopParams& params,
                                                     bool allow_unstable);
// The same for n task-space axes (issue 18): analyze_axes of the whole loop with every plane
// active, at a round trip of at least one sample.
[[nodiscard]] ConfigurationCheck check_configuration_axes(const TeleopAxesParams& params,
                                                          bool allow_unstable);

}  // namespace teleop::config
