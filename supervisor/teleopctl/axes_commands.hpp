// `teleopctl analyze` and `teleopctl simulate` on a configuration with several task-space axes
// (axes > 1, issue 18; docs/analyze.md and docs/simulate.md "Several axes"). The one-axis
// commands hand such a file here after parsing it; an option that has no n-axis meaning is
// refused with a UsageError naming it.
#pragma once

#include <iosfwd>
#include <nlohmann/json.hpp>

#include "common/config/config_loader.hpp"
#include "common/scene/lockstep_axes.hpp"
#include "common/stability/analysis_axes.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/simulate_command.hpp"

namespace teleop::ctl {

// analyze_axes with every plane's stiffness limit, as `analyze --json` prints it.
[[nodiscard]] nlohmann::json axes_analysis_json(const stability::AxesAnalysis& analysis,
                                                const TeleopAxesParams& params);

// The n-axis analysis of `cfg` (text, or --json); the exit code as the one-axis analyze's, and
// 2 (the message and the usage on `err`) for an option refused with several axes.
int run_analyze_axes(const config::LoadedConfig& cfg, const AnalyzeOptions& options,
                     std::ostream& out, std::ostream& err);

// The n-axis simulation of the scene `cfg` (summary text or --json, --out FILE.csv, --plot);
// the exit code as the one-axis simulate's (2 for a refused option, as above).
int run_simulate_axes(const config::LoadedConfig& cfg, const SimulateOptions& options,
                      std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
