// `teleopctl replay FILE.mcap`: a recorded session (teleop-supervisor's MCAP, or `teleopctl
// simulate --out FILE.mcap`) summarised, printed, exported as CSV, recovered after a crash,
// re-published on the bus as if live, or re-simulated with other parameters (issue 5 "Replay
// and identification").
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

namespace teleop::ctl {

[[nodiscard]] std::string replay_usage();

// Handles the whole command, usage errors included (exit 2 with the usage on `err`; `--help`
// prints it on `out`, exit 0). Exit 1: the file is not MCAP, is damaged or cut short (the
// message suggests --recover), names an unknown channel, or another I/O or configuration error.
int run_replay(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
