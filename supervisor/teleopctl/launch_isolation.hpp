// Isolation of `teleopctl launch` (issue 14, finding 8): the nodes and supervisor that answer on
// the configured endpoints must be the processes this launch started, and a second
// teleoperator on the same host takes its own ports (--instance N).
#pragma once

#include <sys/types.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "supervisor/teleopctl/node_command.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

// Ports of instance N are the configuration's (given or default) plus kInstancePortStride * N.
inline constexpr int kInstancePortStride = 10;
inline constexpr int kMaxInstance = 99;

// "tcp://HOST:PORT" with PORT shifted by `by`; throws std::invalid_argument naming the endpoint
// when it has no numeric TCP port or the result leaves 1..65535.
[[nodiscard]] std::string shift_endpoint_port(const std::string& endpoint, int by);

// The --set overrides that move every endpoint of `loaded` (both nodes' state, peer state,
// command and telemetry endpoints, the supervisor's report and request endpoints) to
// instance `instance`'s ports. Empty for instance 0.
[[nodiscard]] std::vector<std::string> instance_overrides(const config::LoadedConfig& loaded,
                                                          int instance);

// The supervisor's endpoints as it binds them (the configuration's or its defaults).
[[nodiscard]] std::string supervisor_request_endpoint(const config::LoadedConfig& loaded);
[[nodiscard]] std::string supervisor_report_endpoint(const config::LoadedConfig& loaded);

// Why a node's reply to `kind` is a refusal although the loop took the command (the state
// machine ignores a command that its mode does not allow: engage on a SAFE node, arm on an
// engaged one); "" when the node reached the mode the command asks for. STATUS, SHUTDOWN and
// the other non-state commands are never refused here.
[[nodiscard]] std::string command_refusal(v1::NodeCommand::Kind kind,
                                          const v1::NodeCommandReply& reply);

// One process launch started, to be confirmed as the one answering on its endpoint.
struct LaunchedProcess {
  std::string name;      // "teleop-master", "teleop-slave", "teleop-supervisor"
  pid_t pid{-1};         // the child launch spawned
  std::string endpoint;  // its command (nodes) or request (supervisor) endpoint
  bool supervisor{false};
  NodeClientKeys keys{};  // how to reach it (CURVE), empty: plaintext loopback
  // Filled once confirmed: the node's session id (its telemetry's), 0 for the supervisor.
  std::uint64_t session_id{0};
  bool confirmed{false};
  bool exited{false};
  int exit_status{0};  // waitpid status once exited
};

// Polls every process until each one's endpoint is answered by that very process (its pid in
// the reply) or `bound_ms` passes. Returns "" when all are confirmed; else why not, naming the
// endpoint and, when another process answers there, its pid: a process that exited at start
// (a port in use, a bad file), or an endpoint answered by another instance's process.
[[nodiscard]] std::string confirm_own_processes(std::vector<LaunchedProcess>& processes,
                                                int bound_ms);

}  // namespace teleop::ctl
