// The deterministic lockstep simulator: the same control code as the nodes, on simulated
// devices, stepped one control period at a time, far faster than real time.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "common/scene/oscillation.hpp"
#include "common/scene/scene_setup.hpp"

namespace teleop::scene {

struct SimulationSummary {
  std::string kind{};  // "bilateral" or "force_device"
  double duration_s{0.0};
  long steps{0};
  double max_penetration_master_m{0.0};  // deepest point inside each side's fixture
  double max_penetration_slave_m{0.0};
  // Bilateral: alpha x_m - x_s. Force device: hand minus device position.
  double tracking_error_rms_m{0.0};
  // Bilateral: F_h - beta F_e (transparency). Force device: F_des - F_h (the force felt),
  // in contact with the virtual tissue.
  double force_error_rms_N{0.0};
  double force_error_peak_N{0.0};
  // The largest force the operator feels where nothing should be felt: bilateral, slave in
  // free space and outside its fixture; force device, outside the virtual tissue.
  double parasitic_force_peak_N{0.0};
  Oscillation oscillation{};         // slave (bilateral) or device position
  Oscillation master_oscillation{};  // bilateral only
  double wall_time_s{0.0};
  double real_time_factor{0.0};
  bool fault{false};  // a control law latched a fault
  // The equilibrium the scene started from (equilibrium starts only).
  double equilibrium_master_m{0.0};
  double equilibrium_slave_m{0.0};
};

struct SimulationResult {
  SimulationSummary summary{};
  std::vector<std::string> columns{};  // names of the recorded time series, SI units
  std::vector<double> rows{};          // row-major, columns.size() values per row
};

// How far a run is, in [0, 1]: called every 1000 steps and at the end (teleopctl's progress
// line on a terminal); empty: not called.
using Progress = std::function<void(double fraction)>;

// Runs the scene. Throws std::invalid_argument when the scene cannot be set up (a device that
// does not configure, no equilibrium for an equilibrium start), naming the reason.
[[nodiscard]] SimulationResult simulate(const SceneSetup& setup, const Progress& progress = {});

// The static equilibrium of the linear loop under a constant push (fixtures engaged where the
// equilibrium lies inside them). Throws when there is none (no restoring force).
struct Equilibrium {
  double master_m{0.0};
  double slave_m{0.0};
  bool master_fixture_engaged{false};
  bool slave_fixture_engaged{false};
};
[[nodiscard]] Equilibrium static_equilibrium(const TeleopParams& params, double push_N);

}  // namespace teleop::scene
