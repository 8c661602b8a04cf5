// docs/nodes.md "Before engage", the supervisor's side: both nodes' configuration fingerprints
// (from their telemetry) against its own, with the fields that differ named where telemetry shows
// them (ActiveParameters: the gains and the fixture stiffnesses in force); and the experiment
// banner. Pure functions of what the supervisor received.
#pragma once

#include <cstdint>
#include <string>

#include "common/core/teleop_params.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {

// What the supervisor approved: the file's values (change 0) or its newest guarded change.
struct ApprovedConfiguration {
  std::uint64_t change_id{0};
  Gains gains{};
  double master_fixture_N_per_m{0.0};
  double slave_fixture_N_per_m{0.0};
};

struct ConfigurationMismatch {
  std::string side{};     // "master", "slave" or "system" (both, or master against slave)
  std::string message{};  // "" when the supervisor and both nodes agree
};

// Compares the fingerprints of the nodes heard from (nullptr: not heard) with `own`. The message
// names every fingerprint and then the differing fields, e.g.
//   "configuration fingerprints differ: supervisor 1a.., master 1a.., slave 3c..; differing:
//    gains.kps (supervisor 600, master 600, slave 900)"
[[nodiscard]] ConfigurationMismatch compare_configurations(std::uint64_t own,
                                                           const ApprovedConfiguration& approved,
                                                           const v1::Telemetry* master,
                                                           const v1::Telemetry* slave);

// "" unless the supervisor's configuration or a node's check says experiment.allow_unstable;
// then one line for the console and `teleopctl status`, with the node's own verdict.
[[nodiscard]] std::string experiment_banner(bool own_allow_unstable, const v1::Telemetry* master,
                                            const v1::Telemetry* slave);

}  // namespace teleop::supervisor
