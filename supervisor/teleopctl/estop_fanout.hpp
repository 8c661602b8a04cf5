// The e-stop of `teleopctl estop` and of the console's x (issue 14, finding 7): sent to both
// nodes directly and at once, each on its own socket, and to the supervisor too, in the same
// instant; the nodes' replies are awaited together, each bounded by the same short timeout,
// so a hung or unreachable node never delays the other, and the supervisor is never waited
// for (its reply is taken if it comes while the nodes are awaited).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "supervisor/teleopctl/node_command.hpp"
#include "teleop/v1/supervisor.pb.h"

namespace teleop::ctl {

struct EstopTarget {
  std::string name{};      // "master", "slave"
  std::string endpoint{};  // its command endpoint
  NodeClientKeys keys{};
};

struct SupervisorTarget {
  std::string endpoint{};
  std::string key_file{};    // this client's key pair, or empty
  std::string server_key{};  // the supervisor's public key, or empty
};

struct EstopOutcome {
  std::string name{};
  std::string endpoint{};
  std::optional<v1::NodeCommandReply> reply{};  // nullopt: no reply within the timeout
  std::string error{};                          // the socket could not even be set up
  long long reply_ns{0};                        // from the send to the reply
  // No direct reply (e.g. the node does not take this client's key), but the supervisor's
  // forwarded e-stop reached it: `reply` is the node's answer to the supervisor.
  bool via_supervisor{false};
  [[nodiscard]] bool safe() const {
    return reply && (reply->mode() == v1::SAFE || reply->mode() == v1::FAULT);
  }
};

struct EstopResult {
  std::vector<EstopOutcome> nodes{};
  bool supervisor_asked{false};
  std::optional<v1::SupervisorReply> supervisor{};  // its reply, if it came in the meantime
  std::string supervisor_error{};
  long long sent_monotonic_ns{0};  // CLOCK_MONOTONIC when the requests went out
  [[nodiscard]] bool all_safe() const;
  // "master SAFE (estop), slave NO REPLY within 500 ms at tcp://..."
  [[nodiscard]] std::string nodes_text() const;
};

// Sends ESTOP to every target and (when given) the supervisor's node-command ESTOP, all
// before waiting for any reply; returns once every node answered or `timeout_ms` passed.
// Never throws: a bad key or endpoint is that target's error, the others still go.
[[nodiscard]] EstopResult estop_everywhere(const std::vector<EstopTarget>& nodes,
                                           const std::optional<SupervisorTarget>& supervisor,
                                           const std::string& requested_by, int timeout_ms);

}  // namespace teleop::ctl
