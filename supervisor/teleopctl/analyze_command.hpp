// `teleopctl analyze`: stability of a configuration, its fixture-stiffness limits, the force
// loop, and the paper's figures as tables and SVG.
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

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

[[nodiscard]] AnalyzeOptions parse_analyze_args(const std::vector<std::string>& args);
[[nodiscard]] std::string analyze_usage();

// Runs the command; results to `out`, errors to `err`; returns the exit code.
int run_analyze(const AnalyzeOptions& options, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
