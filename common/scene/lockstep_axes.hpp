// The lockstep simulator with n task-space axes (issue 18 "Simulation"; docs/simulate.md
// "Several axes"): the n-axis control law (law_axes.hpp) of both sides on two exact n-axis
// plants (plant_axes.hpp), the human an n-axis impedance on the master, tissue-like planes as
// the slave's environment, stepped one control period at a time as lockstep.hpp steps one axis.
// The same ordering and round trip as the one-axis simulator: the slave's state of a sample
// reaches the master at once, the master's goes through `round_trip_delay_samples` to the
// slave. Sensors are ideal here (no encoder quantisation or load-cell noise): the loop is the
// analysed one (stability/analysis_axes.hpp) while the planes it is in stay engaged.
#pragma once

#include <Eigen/Core>
#include <optional>
#include <string>
#include <vector>

#include "common/control/law_axes_params.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/scene/lockstep.hpp"
#include "common/scene/oscillation.hpp"
#include "common/sim/human.hpp"
#include "common/sim/plant_axes.hpp"

namespace teleop::scene {

struct AxesSceneSetup {
  // The loop: devices, gains, scaling, filter, round trip, the law's planes on both sides and
  // the human (kind kFixed: its matrices act on the master; any other kind: no human impedance).
  TeleopAxesParams teleop{};
  // The law the nodes would run; from_teleop_axes_params(teleop) when empty.
  std::optional<control::LawAxesParams> law{};
  std::vector<sim::ContactPlane> slave_environment{};  // tissue-like planes (at most 4)
  // The operator's push F_h*(t) = push_profile(t) push_direction: its size in newtons along a
  // direction (n, normalised by simulate_axes), held over each period as the analyser assumes.
  Eigen::VectorXd push_direction{};
  sim::ForceProfile push_profile{};
  double duration_s{0.0};
  // Start both sides at the static equilibrium under the push at t = 0 (coupled, no fade-in) with
  // the slave displaced by this (n); empty: both start at rest at 0.
  std::optional<Eigen::VectorXd> equilibrium_perturbation_m{};
  double output_rate_hz{0.0};  // rows kept; 0: every sample
};

struct AxesEquilibrium {
  Eigen::VectorXd master_m{};
  Eigen::VectorXd slave_m{};
  // Bit j: plane j of the law's master planes, slave planes, and the slave's environment
  // engaged (n^T x > offset) at the equilibrium.
  unsigned master_planes{0};
  unsigned slave_planes{0};
  unsigned environment_planes{0};
};

// The static equilibrium of the loop under a constant push: every engagement of the planes is
// tried (the most engaged first) and the first consistent one kept. Throws
// std::invalid_argument when there is none.
[[nodiscard]] AxesEquilibrium static_equilibrium_axes(
    const TeleopAxesParams& params, const Eigen::VectorXd& push_N,
    const std::vector<sim::ContactPlane>& slave_environment = {});

struct AxesSimulationSummary {
  int axes{0};
  double duration_s{0.0};
  long steps{0};
  double max_penetration_master_m{0.0};  // deepest n^T x - p over each side's stiff planes
  double max_penetration_slave_m{0.0};
  double tracking_error_rms_m{0.0};  // |alpha x_m - x_s|
  double force_error_rms_N{0.0};     // |F_h - beta F_e|
  // Each side's worst axis: its oscillation (a detected one first, then the largest amplitude).
  Oscillation oscillation{};
  int oscillation_axis{0};
  Oscillation master_oscillation{};
  int master_oscillation_axis{0};
  double wall_time_s{0.0};
  double real_time_factor{0.0};
  bool fault{false};
  std::optional<AxesEquilibrium> equilibrium{};
};

struct AxesSimulationResult {
  AxesSimulationSummary summary{};
  std::vector<std::string> columns{};  // "time_s", then per axis i "master_position_m[i]", ...
  std::vector<double> rows{};          // row-major
};

// Throws std::invalid_argument naming what cannot be set up.
[[nodiscard]] AxesSimulationResult simulate_axes(const AxesSceneSetup& setup,
                                                 const Progress& progress = {});

}  // namespace teleop::scene
