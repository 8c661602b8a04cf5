// The summary stream (issue 6): what a console draws, built from a node's telemetry at a
// bounded size whatever the loop rate. The supervisor publishes it ten times a second (topic
// "status" on its report endpoint) and answers status requests with it; `teleopctl replay
// --speed` builds the same from a recorded session, so one console watches both.
#pragma once

#include <cstdint>
#include <deque>

#include "supervisor/core/monitors.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {

// Feeds one cycle to a side's monitors: only while coupled (engaged or clutched); otherwise
// they restart. The port's force along +x: the human's on the master handle; minus the
// measured environment force on the slave (the load cell reads the slave's push).
void feed_monitors(const v1::CycleRecord& cycle, bool is_master, OscillationMonitor& oscillation,
                   PassivityObserver& passivity);

// The monitors' newest readings.
struct MonitorReadings {
  double oscillation_amplitude_m{0.0};
  double oscillation_frequency_hz{0.0};
  bool oscillating{false};
  double passivity_energy_J{0.0};
};
[[nodiscard]] MonitorReadings read_monitors(const OscillationMonitor& oscillation,
                                            const PassivityObserver& passivity);

// A node's cycle of n > 1 axes into its summary (NodeSummary.axes and the per-axis lists, the
// tracking error alpha x_m - x_s per axis from the cycle's own and peer positions); a one-axis or
// refused record leaves them empty.
void fill_node_axes(v1::NodeSummary& out, const v1::CycleRecord& cycle, bool is_master,
                    double position_scaling);

class NodeSummaryBuilder {
 public:
  // `fixture_position_m` and `fixture_stiffness_N_per_m`: this side's configured fixture (the
  // stiffness in force is taken from the telemetry when it carries one). The traces keep the
  // last `window_s` in buckets of `bucket_s`.
  // `position_scaling`: alpha, for the per-axis tracking errors alpha x_m - x_s of n > 1 axes.
  NodeSummaryBuilder(bool is_master, double fixture_position_m, double fixture_stiffness_N_per_m,
                     double window_s = 5.0, double bucket_s = 0.05, double position_scaling = 1.0);

  // One telemetry message, received at `received_ns` on the owner's clock.
  void add(const v1::Telemetry& t, std::int64_t received_ns);
  // Forgets everything (a new session of the node, a replay seek).
  void reset();
  [[nodiscard]] bool empty() const { return !have_; }

  // The summary at `now_ns` (owner's clock).
  void fill(v1::NodeSummary& out, std::int64_t now_ns, const MonitorReadings& monitors) const;

 private:
  struct Bucket {
    std::int64_t index{0};
    float position_min{0}, position_max{0};
    float force_min{0}, force_max{0};
    float penetration_min{0}, penetration_max{0};
  };
  [[nodiscard]] double penetration(double position_m, double stiffness_N_per_m) const;

  bool is_master_;
  double position_scaling_{1.0};
  double fixture_position_m_;
  double fixture_stiffness_N_per_m_;
  std::int64_t bucket_ns_;
  std::size_t buckets_kept_;
  bool have_{false};
  v1::Telemetry last_{};  // the newest message, without its cycles
  v1::CycleRecord newest_cycle_{};
  bool have_cycle_{false};
  std::int64_t received_ns_{0};
  std::deque<std::int64_t> cycle_times_ns_{};  // the last second of cycle timestamps
  // (node's sent time, overruns) pairs over the last minute, plus one older.
  std::deque<std::pair<std::int64_t, std::uint64_t>> overrun_history_{};
  std::deque<Bucket> buckets_{};
};

}  // namespace teleop::supervisor
