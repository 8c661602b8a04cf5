// What one node's recorded telemetry says about its loop (the summary of `teleopctl replay`):
// cycles, sequence gaps, restarts, modes, and the distribution of its wake-up latency and of
// its skipped deadlines over the seconds of the session.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "teleop/v1/telemetry.pb.h"

namespace teleop::record {

// Nearest-rank quantiles and a histogram of every cycle's wake-up latency.
struct WakeupLatencySummary {
  struct Bin {
    std::int64_t from_us{0};
    std::optional<std::int64_t> to_us{};  // nullopt: the last bin, open above
    std::uint64_t cycles{0};
  };
  double p50_us{0.0};
  double p99_us{0.0};
  double p999_us{0.0};
  double max_us{0.0};
  std::vector<Bin> histogram{};  // from 0 us: 0-50, 50-100, 100-200, ..., >= 5000
  // Negative latencies (a clock step), not in the histogram.
  std::uint64_t negative{0};
};

// Skipped deadlines in all, and how many seconds (with at least one cycle recorded) had how
// many.
struct OverrunSummary {
  struct Bin {
    std::uint64_t from{0};
    std::optional<std::uint64_t> to{};  // inclusive; nullopt: the last bin, open above
    std::uint64_t seconds{0};
  };
  std::uint64_t total{0};
  std::uint64_t seconds{0};  // seconds with at least one cycle
  std::uint64_t worst_second{0};
  std::vector<Bin> seconds_histogram{};  // 0, 1, 2-9, 10-99, >= 100
};

// One task-space axis over a node's cycles (issue 18): the range of its position and the
// largest magnitudes of its measured force and of its command.
struct AxisSummary {
  double min_position_m{0.0};
  double max_position_m{0.0};
  double max_abs_force_N{0.0};
  double max_abs_command_N{0.0};
};

// One node's telemetry messages added in log-time order.
class NodeTelemetryStats {
 public:
  void add(const v1::Telemetry& t);

  std::uint64_t messages{0};
  std::uint64_t cycles{0};
  std::uint64_t missing{0};  // sequence gaps within a session
  std::uint64_t restarts{0};
  std::uint64_t out_of_order{0};
  std::uint64_t cycles_dropped{0};  // the node's own count (telemetry queue)
  std::uint64_t flight_records{0};
  std::uint64_t first_sequence{0};
  std::uint64_t last_sequence{0};
  std::uint64_t session_id{0};
  bool any{false};                               // any cycle recorded
  std::map<std::string, std::uint64_t> modes{};  // cycles by teleop.v1.NodeMode name
  // Task-space axes (issue 18): the most of any cycle (1 for one-axis records, 0 before a
  // cycle), and the cycles whose axes differ from the cycle before (a node restarted with
  // another configuration).
  int axes{0};
  std::uint64_t axes_changes{0};
  // Records the codec refuses (telemetry::axes_from_proto: more than kMaxAxes axes, or a
  // per-axis field not holding one entry per axis): counted with their loop timing, left out of
  // per_axis; the first one's sequence.
  std::uint64_t refused{0};
  std::uint64_t first_refused_sequence{0};
  std::vector<AxisSummary> per_axis{};  // one per axis up to `axes`, over the cycles having it

  // nullopt without cycles.
  [[nodiscard]] std::optional<WakeupLatencySummary> wakeup_latency() const;
  [[nodiscard]] OverrunSummary overruns() const;

 private:
  // Wake-up latency of every cycle, and per second of the node's clock its cycles and the
  // deadlines it skipped (overruns: a cycle's sample time is its deadline on the loop's grid,
  // so a gap of n periods means n - 1 skipped; within one session).
  std::vector<std::int64_t> wakeups_ns_{};
  std::map<std::int64_t, std::pair<std::uint64_t, std::uint64_t>> per_second_{};
  std::int64_t last_sample_ns_{0};
  int last_axes_{0};

  void add_axes(const v1::CycleRecord& c);
};

}  // namespace teleop::record
