// `teleopctl simulate`: play a scene on simulated devices with the nodes' control code.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/scene/lockstep.hpp"

namespace teleop::ctl {

struct SimulateOptions {
  std::string scene_path{};
  std::vector<std::string> overrides{};
  std::optional<double> duration_s{};
  std::optional<unsigned long long> seed{};
  std::optional<std::string> out_path{};   // CSV time series
  std::optional<std::string> plot_path{};  // SVG of positions and forces
  // The session file's first log time, ns since the epoch; none: the wall clock at the start.
  std::optional<std::int64_t> log_start_ns{};
  bool json{false};
};

// The summary `teleopctl simulate --json` prints (docs/cli.md): the run's figures of merit and,
// for a bilateral scene, what the analyser predicts for its loop. The Python module returns it.
[[nodiscard]] nlohmann::json simulation_document(const config::LoadedConfig& cfg,
                                                 const scene::SceneSetup& setup,
                                                 const scene::SimulationResult& result);

[[nodiscard]] SimulateOptions parse_simulate_args(const std::vector<std::string>& args);
[[nodiscard]] std::string simulate_usage();

// Exit codes: 0 ran and no sustained oscillation, 1 bad scene or I/O, 2 usage, 3 a sustained
// oscillation was detected, 5 a control law latched a fault.
int run_simulate(const SimulateOptions& options, std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
