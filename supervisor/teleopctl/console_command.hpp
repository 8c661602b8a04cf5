// `teleopctl console`: the operator's full-screen console (issue 6), live on the supervisor
// or watching a replay. It draws from the supervisor's summary stream (topic "status" on the
// report endpoint, ten times a second) and sends every command through the supervisor's
// request endpoint, so nothing reaches the robot that the supervisor did not see; only the
// e-stop falls back to the nodes directly when the supervisor does not answer.
#pragma once

#include <ostream>
#include <string>
#include <vector>

namespace teleop::ctl {

[[nodiscard]] std::string console_usage();
int run_console(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
