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
};

}  // namespace teleop::record
