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
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "common/control/law_axes.hpp"
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

// Where a run of `setup` starts and the law it runs: at rest at 0 with setup.law (else
// from_teleop_axes_params(setup.teleop)), or at the static equilibrium under the push at t = 0
// with the slave displaced by equilibrium_perturbation_m, coupled already (no clutch fade-in).
// simulate_axes starts here, and so does a resimulation of the scene. Throws as
// static_equilibrium_axes and from_teleop_axes_params.
struct AxesStart {
  Eigen::VectorXd master_m{};
  Eigen::VectorXd slave_m{};
  control::LawAxesParams law{};
  std::optional<AxesEquilibrium> equilibrium{};
};
[[nodiscard]] AxesStart axes_start(const AxesSceneSetup& setup);

// What both laws saw and did at sample k, as the nodes record a cycle (--out FILE.mcap): each
// side's sensed position and load-cell force (the master's the hand's force on it, the slave's
// the force on its environment), its own filtered velocity, its command, and the master state
// the slave received (sent at sample k - round_trip_delay_samples; the initial state before).
struct AxesCycleView {
  long k{0};
  const control::AxisVector& master_m;
  const control::AxisVector& slave_m;
  const control::AxisVector& master_force_N;
  const control::AxisVector& slave_force_N;
  const control::AxisVector& master_velocity_m_per_s;
  const control::AxisVector& slave_velocity_m_per_s;
  const control::CommandAxes& master_command;
  const control::CommandAxes& slave_command;
  const control::PeerStateAxes& slave_received;
};
using AxesCycleObserver = std::function<void(const AxesCycleView&)>;

// Throws std::invalid_argument naming what cannot be set up. `observer`: every sample (not
// only the rows kept), before the plants advance.
[[nodiscard]] AxesSimulationResult simulate_axes(const AxesSceneSetup& setup,
                                                 const Progress& progress = {},
                                                 const AxesCycleObserver& observer = {});

// --- resimulation (`teleopctl replay --resimulate` of an n-axis session) ---------------------

// What a resimulation runs: the law, the slave's device and environment, where both sides start
// and the loop's timing (config::to_axes_resimulation builds it from a recorded configuration).
struct AxesResimulationSetup {
  control::LawAxesParams law{};
  DeviceAxesParams slave_device{};
  std::vector<sim::ContactPlane> slave_environment{};
  Eigen::VectorXd master0_m{};
  Eigen::VectorXd slave0_m{};
  double sample_rate_hz{1000.0};
  int round_trip_delay_samples{0};
  // For the measures: alpha and the slave's planes.
  double position_scaling{1.0};
  std::vector<PlaneFixtureParams> slave_planes{};
};

// One recorded cycle of the master (as MasterCycle, resimulate.hpp, for one axis).
struct AxesMasterCycle {
  Eigen::VectorXd position_m{};
  bool coupled{false};   // engaged or clutched: its state reaches the slave as valid
  bool clutched{false};  // indexing: the slave holds its reference
};

// The slave's tracking of the master states it followed (|alpha x_m - x_s|, rms), its deepest
// point in its planes and its worst axis's oscillation: the same measures for a recording and
// for a resimulation.
struct AxesSlaveOutcome {
  std::size_t cycles{0};
  double tracking_rms_m{0.0};
  double max_penetration_m{0.0};
  Oscillation oscillation{};
  int oscillation_axis{0};
  bool fault{false};  // the slave law latched a fault (a resimulation only)
};

class AxesSlaveOutcomeMeter {
 public:
  AxesSlaveOutcomeMeter(int axes, double position_scaling, std::vector<PlaneFixtureParams> planes);
  // The slave's position (axes entries) and the master position it followed then (none while
  // it followed nothing).
  void add(const Eigen::VectorXd& slave_m, const std::optional<Eigen::VectorXd>& master_m);
  // Oscillation over the last min(1 s, a quarter of the run), as simulate_axes looks.
  [[nodiscard]] AxesSlaveOutcome finish(double period_s) const;

 private:
  double alpha_{1.0};
  std::vector<PlaneFixtureParams> planes_{};
  double sum_sq_{0.0};
  std::size_t tracked_{0};
  double max_penetration_m_{0.0};
  std::vector<std::vector<double>> positions_{};  // per axis
};

struct AxesResimulation {
  // Per cycle (one per recorded master cycle): the slave's position the law sensed and the
  // command it wrote, `axes` entries each, cycle-major.
  int axes{0};
  std::vector<double> slave_position_m{};
  std::vector<double> slave_command_N{};
  AxesSlaveOutcome outcome{};
};

// The recorded master motion through both laws and the simulated slave (simulate_axes's loop
// with the master plant replaced by the recording): the same law, plant and order, so a session
// simulate_axes wrote resimulates bit for bit. Throws std::invalid_argument naming a master
// cycle whose position does not hold `axes` entries. `progress` as for simulate_axes.
[[nodiscard]] AxesResimulation resimulate_axes(const AxesResimulationSetup& setup,
                                               const std::vector<AxesMasterCycle>& master,
                                               const Progress& progress = {});

}  // namespace teleop::scene
