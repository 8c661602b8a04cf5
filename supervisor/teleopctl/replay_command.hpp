// `teleopctl replay FILE.mcap`: a recorded session (teleop-supervisor's MCAP, or `teleopctl
// simulate --out FILE.mcap`) summarised, printed, exported as CSV, recovered after a crash,
// re-published on the bus as if live, or re-simulated with other parameters (issue 5 "Replay
// and identification").
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

namespace teleop::ctl {

[[nodiscard]] std::string replay_usage();

// Handles the whole command, usage errors included (exit 2 with the usage on `err`; `--help`
// prints it on `out`, exit 0). Exit 1: the file is not MCAP, is damaged or cut short (the
// message suggests --recover), names an unknown channel, or another I/O or configuration error.
int run_replay(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

// One control cycle as a node recorded it (teleop.v1.CycleRecord, plain values).
struct RecordedCycle {
  std::uint64_t session_id{0};  // of the Telemetry message that carried it
  std::uint64_t sequence{0};
  std::int64_t sample_time_ns{0};
  int mode{0};  // teleop.v1.NodeMode
  double position_m{0.0};
  double velocity_m_per_s{0.0};
  double force_N{0.0};
  double command_N{0.0};
  std::uint64_t peer_sequence{0};
  double peer_position_m{0.0};
};

// Every cycle one node recorded in a session file (the CycleRecords of /master/telemetry or
// /slave/telemetry, in log-time order; flight records, which repeat cycles, left out). Throws
// std::runtime_error naming the file: not MCAP, damaged (suggesting --recover), no such
// channel, a message that does not decode.
[[nodiscard]] std::vector<RecordedCycle> read_recorded_cycles(const std::string& path, bool master);

// Whether `path` starts with the MCAP magic (false when it cannot be read).
[[nodiscard]] bool is_mcap_file(const std::string& path);

}  // namespace teleop::ctl
