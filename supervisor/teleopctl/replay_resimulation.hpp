// `teleopctl replay FILE.mcap --resimulate` (docs/cli.md): the parts the one-axis resimulation
// (replay_command.cpp) and the n-axis one (issue 18) share, and the n-axis one.
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/session/session_reader.hpp"
#include "supervisor/teleopctl/progress_line.hpp"

namespace teleop::ctl {

// The parts of --resimulate's progress line, in the time they take (measured on a 104 MB
// session of 300 s: a pass over the file for the configuration 0.12 s, one reading a node's
// cycles 0.30 s, the resimulation of its 300 000 cycles and the analyses 0.09 s).
inline constexpr double kConfigPass = 0.12;
inline constexpr double kCyclesPass = 0.30;
inline constexpr double kResimulation = 0.09;

struct ResimulationRequest {
  std::string file{};
  std::vector<std::string> overrides{};  // --set
  bool json{false};
};

// The configuration as recorded, and with the overrides (the same when there are none).
struct ResimulationConfigs {
  config::LoadedConfig recorded{};
  config::LoadedConfig config{};
};

// Reads the recorded /config (throws naming the file when there is none) and applies the
// overrides (a bad one throws naming itself). One pass over the file, two with overrides.
[[nodiscard]] ResimulationConfigs resimulation_configs(const record::SessionReader& session,
                                                       const ResimulationRequest& request,
                                                       ProgressParts& parts);

// The exit code follows the verdicts, as analyze's does: a fault (5), then the resimulated
// model not finite (1: never "ok"), then oscillation seen or an unstable analysis (3), then an
// uncertain analysis (4).
[[nodiscard]] int resimulation_exit_code(bool fault, bool oscillation, const std::string& verdict);

// The n-axis resimulation (configured axes > 1): the recorded master motion through both n-axis
// laws and the simulated slave (scene::resimulate_axes), with the recorded configuration plus
// the overrides, and per axis the deviation of the resimulated slave from the recorded one,
// cycle by cycle (text, or --json). Every cycle of both nodes must have the configured number of
// axes: otherwise it throws naming the file, topic and sequence. `progress` is reset before
// anything is printed.
int resimulate_axes(const record::SessionReader& session, const ResimulationRequest& request,
                    const ResimulationConfigs& configs, ProgressParts& parts,
                    std::optional<ProgressLine>& progress, std::ostream& out);

}  // namespace teleop::ctl
