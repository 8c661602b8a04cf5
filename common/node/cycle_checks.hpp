// What NodeCore and NodeCoreAxes check and report the same way on every cycle (one helper both
// cores call, so the one-axis and the n-axis node cannot drift apart):
//  - StallCheck: an own stall, measured on the clock read on waking (node_core.hpp "Time");
//  - take_command: the operator's command of the cycle;
//  - peer_state_age_ns: how old the newest peer state is on that clock;
//  - note_echo: the round trip a peer state's echo measures;
//  - fill_loop_snapshot: the loop and link statistics the cores publish every kStatsEvery cycles.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>

#include "common/core/rt_safe.hpp"
#include "common/node/node_state_machine.hpp"
#include "common/rt/loop_timing.hpp"
#include "common/rt/spsc_queue.hpp"
#include "common/rt/windowed_histogram.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::node {

struct LoopSnapshot;

// An own stall: the time since the previous cycle's clock beyond the peer timeout, or a burst
// of overruns (lateness beyond one period accumulating faster than half the time that passes
// drains it).
class StallCheck {
 public:
  // The reason of a stall at `clock` (a static string), nullptr when none. The first call only
  // starts the clock.
  TELEOP_RT [[nodiscard]] const char* check(std::chrono::nanoseconds clock,
                                            std::chrono::nanoseconds period,
                                            std::chrono::nanoseconds peer_timeout) noexcept;

 private:
  bool have_clock_{false};
  std::int64_t last_clock_ns_{0};
  std::int64_t overrun_debt_ns_{0};
};

// The operator's command of this cycle (one per cycle, in order, counted in `applied`); the
// clutch only on the side that takes it (the master).
TELEOP_RT [[nodiscard]] Command take_command(rt::SpscQueue<Command, 64>& queue,
                                             std::atomic<std::uint64_t>& applied,
                                             bool takes_clutch) noexcept;

// The newest peer state's age at `clock` (0 without one; never negative).
TELEOP_RT [[nodiscard]] std::int64_t peer_state_age_ns(bool have_peer,
                                                       std::chrono::nanoseconds clock,
                                                       std::int64_t arrival_ns) noexcept;

// The round trip an accepted peer state's echo measures (its last_peer_sequence, 0: none): the
// newest into `round_trip_ns` and, at `now`, into the window.
TELEOP_RT void note_echo(const transport::NodeStateRecord& state, std::int64_t arrival_ns,
                         std::chrono::nanoseconds now, transport::RoundTripEstimator& estimator,
                         std::int64_t& round_trip_ns, rt::WindowedHistogram& window) noexcept;

// What the link adds to a loop snapshot.
struct LinkSnapshotInputs {
  std::int64_t round_trip_ns{0};
  const rt::WindowedHistogram* round_trip_window{nullptr};
  std::uint64_t peer_restarts{0};
  std::uint64_t peer_session_id{0};  // 0 without a peer
  std::int64_t peer_age_ns{0};
};

// The loop's statistics (`timing`, when run by a PeriodicLoop; else only the cycle count,
// `sequence`) and the link's.
TELEOP_RT void fill_loop_snapshot(LoopSnapshot& s, const rt::LoopTiming* timing,
                                  std::uint64_t sequence, const LinkSnapshotInputs& link) noexcept;

}  // namespace teleop::node
