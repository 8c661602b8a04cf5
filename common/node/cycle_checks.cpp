#include "common/node/cycle_checks.hpp"

#include <algorithm>
#include <optional>

#include "common/node/node_core.hpp"

namespace teleop::node {

const char* StallCheck::check(std::chrono::nanoseconds clock, std::chrono::nanoseconds period,
                              std::chrono::nanoseconds peer_timeout) noexcept {
  const char* own_stall = nullptr;
  if (have_clock_) {
    const std::int64_t gap_ns = clock.count() - last_clock_ns_;
    const std::int64_t period_ns = period.count();
    const std::int64_t timeout_ns = peer_timeout.count();
    overrun_debt_ns_ =
        std::max<std::int64_t>(0, overrun_debt_ns_ + std::max<std::int64_t>(0, gap_ns - period_ns) -
                                      std::max<std::int64_t>(0, gap_ns) / 2);
    if (gap_ns > timeout_ns) {
      own_stall = "own loop stalled past the peer timeout";
    } else if (overrun_debt_ns_ > timeout_ns) {
      own_stall = "own loop overran in a burst";
    }
  }
  if (own_stall != nullptr) overrun_debt_ns_ = 0;
  have_clock_ = true;
  last_clock_ns_ = clock.count();
  return own_stall;
}

Command take_command(rt::SpscQueue<Command, 64>& queue, std::atomic<std::uint64_t>& applied,
                     bool takes_clutch) noexcept {
  Command command = Command::kNone;
  if (const std::optional<Command> c = queue.try_pop()) {
    command = *c;
    applied.fetch_add(1, std::memory_order_acq_rel);
  }
  if (!takes_clutch && (command == Command::kClutch || command == Command::kUnclutch)) {
    command = Command::kNone;
  }
  return command;
}

std::int64_t peer_state_age_ns(bool have_peer, std::chrono::nanoseconds clock,
                               std::int64_t arrival_ns) noexcept {
  return have_peer ? std::max<std::int64_t>(0, clock.count() - arrival_ns) : 0;
}

void note_echo(const transport::NodeStateRecord& state, std::int64_t arrival_ns,
               std::chrono::nanoseconds now, transport::RoundTripEstimator& estimator,
               std::int64_t& round_trip_ns, rt::WindowedHistogram& window) noexcept {
  if (state.last_peer_sequence == 0) return;
  const auto rtt =
      estimator.echoed(state.last_peer_sequence, std::chrono::nanoseconds(state.peer_age_ns),
                       std::chrono::nanoseconds(arrival_ns));
  if (rtt && rtt->count() > 0) {
    round_trip_ns = rtt->count();
    window.add(now.count(), rtt->count());
  }
}

void fill_loop_snapshot(LoopSnapshot& s, const rt::LoopTiming* timing, std::uint64_t sequence,
                        const LinkSnapshotInputs& link) noexcept {
  if (timing != nullptr) {
    s.cycles = timing->cycles();
    s.overruns = timing->overruns();
    s.wakeup_p50_ns = timing->wakeup_latency().quantile(0.5).count();
    s.wakeup_p99_ns = timing->wakeup_latency().quantile(0.99).count();
    s.wakeup_p999_ns = timing->wakeup_latency().quantile(0.999).count();
    s.wakeup_max_ns = timing->wakeup_latency().max().count();
    s.compute_p50_ns = timing->compute_time().quantile(0.5).count();
    s.compute_p99_ns = timing->compute_time().quantile(0.99).count();
    s.compute_max_ns = timing->compute_time().max().count();
  } else {
    s.cycles = sequence;
  }
  s.round_trip_ns = link.round_trip_ns;
  if (link.round_trip_window != nullptr) {
    s.round_trip_p50_ns = link.round_trip_window->quantile(0.5);
    s.round_trip_p99_ns = link.round_trip_window->quantile(0.99);
  }
  s.peer_restarts = link.peer_restarts;
  s.peer_session_id = link.peer_session_id;
  s.peer_age_ns = link.peer_age_ns;
}

}  // namespace teleop::node
