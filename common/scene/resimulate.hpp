// Resimulation (issue 5 "Replay and identification", `teleopctl replay --resimulate`): a
// recorded master motion through the slave side of the law and a simulated slave, with the
// recorded parameters or others, and the measures that compare the outcome with the recording.
#pragma once

#include <cstddef>
#include <functional>
#include <optional>
#include <vector>

#include "common/control/law_params.hpp"
#include "common/core/teleop_params.hpp"
#include "common/device/sim_device.hpp"
#include "common/scene/oscillation.hpp"

namespace teleop::scene {

// The slave's tracking of the master states it received, its deepest point in its fixture and
// its oscillation: the same measures for a recording and for a resimulation.
struct SlaveOutcome {
  double tracking_rms_m{0.0};     // rms of alpha x_m - x_s over the cycles it followed
  double max_penetration_m{0.0};  // deepest x_s - p in its fixture (0 without a fixture)
  Oscillation oscillation{};
  std::size_t cycles{0};
  bool fault{false};  // the slave law latched a fault (a resimulation only)
};

// Takes the slave's sensed positions, each with the master position it followed then (none
// while it followed nothing).
class SlaveOutcomeMeter {
 public:
  SlaveOutcomeMeter(double position_scaling, const FixtureParams& slave_fixture)
      : alpha_(position_scaling), fixture_(slave_fixture) {}
  void add(double slave_m, std::optional<double> master_m);
  // The oscillation is looked for in the last min(1 s, a quarter of the run) of positions
  // sampled every `period_s` (more than four cycles needed), at least `threshold_m` wide.
  [[nodiscard]] SlaveOutcome finish(double period_s, double threshold_m);

 private:
  double alpha_{1.0};
  FixtureParams fixture_{};
  double sum_sq_{0.0};
  std::size_t tracked_{0};
  SlaveOutcome outcome_{};
  std::vector<double> positions_{};
};

// The smallest oscillation that counts in a simulated device's sensed positions: 1.5 encoder
// counts, at least 10 um (10 um without quantisation).
[[nodiscard]] double oscillation_threshold_m(const device::SimDeviceConfig& c);

// What a resimulation runs: the law, the simulated slave (its period and initial position are
// set from the fields below), where both sides start and the loop's timing.
struct ResimulationSetup {
  control::LawParams law{};
  device::SimDeviceConfig slave{};
  double master0_m{0.0};
  double slave0_m{0.0};
  double sample_rate_hz{1000.0};
  std::size_t round_trip_delay_samples{0};
  // For the measures: alpha, and the slave's fixture.
  double position_scaling{1.0};
  FixtureParams slave_fixture{};
};

// One recorded cycle of the master.
struct MasterCycle {
  double position_m{0.0};
  bool coupled{false};   // engaged or clutched: its state reaches the slave as valid
  bool clutched{false};  // indexing: the slave holds its reference
};

// The recorded master motion through the slave side of the law (lockstep.cpp's loop with the
// master device replaced by the recording): one cycle per recorded master cycle, the master's
// state reaching the slave round_trip_delay_samples + 1 cycles later. Throws std::runtime_error
// ("slave device: ...") when the simulated slave does not start. `progress`: the fraction of the
// cycles done, every 1000 cycles and at the end (teleopctl's progress line); empty: not called.
[[nodiscard]] SlaveOutcome resimulate(const ResimulationSetup& setup,
                                      const std::vector<MasterCycle>& master,
                                      const std::function<void(double fraction)>& progress = {});

}  // namespace teleop::scene
