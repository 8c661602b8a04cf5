// `teleopctl node HOST:PORT COMMAND`: one command to one node, straight to its command
// endpoint (so an e-stop never depends on another process); and `teleopctl launch CONFIG`:
// both nodes on loopback with simulated devices, engaged, stopped cleanly on Ctrl-C.
#pragma once

#include <sys/types.h>

#include <optional>
#include <ostream>
#include <string>
#include <vector>

#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

inline constexpr int kExitRefused = 3;  // the node answered but did not take the command
inline constexpr int kExitNoReply = 4;  // no reply within the timeout

[[nodiscard]] std::string node_usage();
int run_node_command(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

// Starts `binary` with `args` as a child that dies with this process (SIGTERM). A SIGINT or
// SIGTERM sent to the child at any time, even before its exec, ends it.
[[nodiscard]] pid_t spawn_process(const std::string& binary, const std::vector<std::string>& args);

// "HOST:PORT" -> "tcp://HOST:PORT"; a full endpoint is kept.
[[nodiscard]] std::string to_endpoint(const std::string& address);

struct NodeClientKeys {
  std::string secret_key_file{};  // this client's key pair (teleopctl keygen)
  std::string server_key{};       // the node's public key (Z85 or a .pub file)
};

// Sends one command; nullopt when no reply came within timeout_ms.
[[nodiscard]] std::optional<v1::NodeCommandReply> send_node_command(const std::string& endpoint,
                                                                    v1::NodeCommand::Kind kind,
                                                                    const NodeClientKeys& keys,
                                                                    int timeout_ms);

[[nodiscard]] std::string launch_usage();
int run_launch(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
