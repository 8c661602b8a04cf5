// Without a terminal (issue 6 groundwork): `teleopctl estop` sends e-stop straight to both
// nodes (never only through another process), and `teleopctl status [--json]` prints the
// supervisor's status: its stability report, the recorder, the nodes' liveness and alarms.
#pragma once

#include <ostream>
#include <string>
#include <vector>

namespace teleop::ctl {

[[nodiscard]] std::string estop_usage();
int run_estop(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

[[nodiscard]] std::string status_usage();
int run_status(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
