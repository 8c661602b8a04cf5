// `teleopctl analyze`: stability of a configuration, its fixture-stiffness limits, the force
// loop, and the paper's figures as tables and SVG.
#pragma once

#include <cstddef>
#include <functional>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/stability/stiffness_search.hpp"
#include "supervisor/teleopctl/cli_args.hpp"

namespace teleop::ctl {

struct Sweep {
  std::string path{};
  double from{0.0};
  double to{0.0};
  double step{0.0};
  [[nodiscard]] std::vector<double> values() const;
};

struct AnalyzeOptions {
  std::string config_path{};
  std::vector<std::string> overrides{};
  bool json{false};
  std::optional<stability::Side> max_stiffness_side{};
  std::vector<double> rates_hz{};
  std::optional<Sweep> sweep{};
  bool force_loop{false};
  std::optional<std::string> plot_path{};
};

// Exit codes of `teleopctl analyze` (1 and 2, bad input and usage, as every command:
// cli_args.hpp).
inline constexpr int kExitStable = kExitOk;  // also: a limits table or force-loop run completed
inline constexpr int kExitUnstable = 3;
inline constexpr int kExitUncertain = 4;

// The exit code of an analysis verdict (one axis or n): stable 0, unstable 3, uncertain 4,
// invalid 1.
[[nodiscard]] int verdict_exit_code(stability::Verdict v);

// The documents `teleopctl analyze --json` prints (fields in docs/analyze.md), from a parsed
// configuration (config::parse_config_file / parse_config_text with the overrides applied): the
// CLI and the Python module (python/) both print or return these. Each validates through the
// configuration's one path (to_teleop_params / to_force_loop_params) and throws
// config::ConfigError naming the field.
//
// `teleopctl analyze CONFIG --json`.
[[nodiscard]] nlohmann::json analysis_document(const config::LoadedConfig& cfg);
// `teleopctl analyze CONFIG --force-loop --json`.
[[nodiscard]] nlohmann::json force_loop_document(const config::LoadedConfig& cfg);
// `teleopctl analyze CONFIG --max-stiffness SIDE [--rates ...] [--sweep ...] --json`: the
// document, the curves for --plot, and whether a point's model was not finite (the CLI exits 1).
struct LimitsDocument {
  nlohmann::json document{};
  bool any_invalid{false};
};
// `rates_hz` empty: the configured rate. `progress(done, points)` after each point, if set.
[[nodiscard]] LimitsDocument limits_document(
    const config::LoadedConfig& cfg, stability::Side side, const std::vector<double>& rates_hz,
    const std::optional<Sweep>& sweep,
    const std::function<void(std::size_t done, std::size_t points)>& progress = {});
// "PATH=FROM:TO:STEP" (--sweep's argument); UsageError when it is malformed.
[[nodiscard]] Sweep parse_sweep(const std::string& spec);

[[nodiscard]] AnalyzeOptions parse_analyze_args(const std::vector<std::string>& args);
[[nodiscard]] std::string analyze_usage();

// Runs the command; results to `out`, errors to `err`; returns the exit code.
int run_analyze(const AnalyzeOptions& options, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
