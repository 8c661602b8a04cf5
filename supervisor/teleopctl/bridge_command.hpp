// `teleopctl bridge`: the live view in Foxglove (issue 17; docs/foxglove.md). A Foxglove
// WebSocket protocol server (common/bridge) fed, like the console, by the nodes' telemetry and
// the supervisor's report endpoint, as a client with this machine's console key: the same
// channels as a recorded session, live, plus one message per control cycle per node. A
// separate process, so no WebSocket client ever touches a node's or the supervisor's loop,
// and it only listens: nothing a Foxglove user does reaches the teleoperator.
#pragma once

#include <ostream>
#include <string>
#include <vector>

namespace teleop::ctl {

[[nodiscard]] std::string bridge_usage();
int run_bridge(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

// Whether `address` is an IPv4 or IPv6 loopback address (127.0.0.0/8, ::1).
[[nodiscard]] bool is_loopback_address(const std::string& address);

}  // namespace teleop::ctl
