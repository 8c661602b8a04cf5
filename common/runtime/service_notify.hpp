// The systemd notify protocol for the daemons (issue 8, `Type=notify` units): READY=1 once the
// process serves, STOPPING=1 on the way out, and a watchdog fed by a non-real-time thread only
// while the loop it watches (the node's RT loop, the supervisor's main loop) keeps cycling.
// Without NOTIFY_SOCKET every call is a no-op.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>

namespace teleop::runtime {

// What the watchdog thread does after one look at the loop's heartbeat.
struct WatchdogAction {
  bool feed{false};      // send WATCHDOG=1
  std::string status{};  // non-empty: a new STATUS= (the loop stalled, or runs again)
};

// Decides from the loop's heartbeat counter whether to feed the watchdog: every half watchdog
// interval, and only while the counter advances. The counter counts as stalled once it has not
// been seen to advance for longer than `stall_limit`; then the feeding stops (systemd restarts
// the service one watchdog interval after the last feed) and a status says why. Pure: the
// caller passes the time (monotonic) and the counter; no clock, no I/O.
class WatchdogFeeder {
 public:
  WatchdogFeeder(std::chrono::microseconds watchdog_interval, std::chrono::nanoseconds stall_limit,
                 std::chrono::nanoseconds now);

  // One look at `heartbeat` at `now`. The first look is the baseline (no feed).
  [[nodiscard]] WatchdogAction observe(std::uint64_t heartbeat, std::chrono::nanoseconds now);

  // How long the caller may wait after `now` before looking again: until the next feed is due,
  // and at most half the stall limit (and 100 ms) so that a stall is seen in time.
  [[nodiscard]] std::chrono::nanoseconds wait_after(std::chrono::nanoseconds now) const;

  [[nodiscard]] bool stalled() const noexcept { return stalled_; }
  [[nodiscard]] std::chrono::nanoseconds feed_every() const noexcept { return feed_every_; }
  [[nodiscard]] std::chrono::nanoseconds stall_limit() const noexcept { return stall_limit_; }

  // The stall limit the daemons use: a quarter of the watchdog interval, at most 1 s.
  [[nodiscard]] static std::chrono::nanoseconds default_stall_limit(
      std::chrono::microseconds watchdog_interval);

 private:
  std::chrono::microseconds interval_;
  std::chrono::nanoseconds feed_every_;
  std::chrono::nanoseconds stall_limit_;
  std::optional<std::uint64_t> heartbeat_{};
  std::chrono::nanoseconds advanced_at_;
  std::optional<std::chrono::nanoseconds> fed_at_{};
  bool stalled_{false};
};

// sd_notify for one daemon. Reads NOTIFY_SOCKET, WATCHDOG_USEC and WATCHDOG_PID once (at
// construction, which logs whether the watchdog is on and its interval). Not thread-safe: one
// non-RT thread (the daemon's signal thread) calls it.
class ServiceNotifier {
 public:
  // `loop`: what the heartbeat counts, for the log and the statuses ("RT loop", "main loop").
  explicit ServiceNotifier(std::string loop);

  [[nodiscard]] bool notify_socket() const noexcept { return socket_; }
  // WATCHDOG_USEC when the watchdog is on for this process.
  [[nodiscard]] std::optional<std::chrono::microseconds> watchdog_interval() const noexcept {
    return interval_;
  }

  void ready(const std::string& status);     // READY=1 and STATUS=
  void stopping(const std::string& status);  // STOPPING=1 and STATUS=
  void status(const std::string& status);    // STATUS=

  // One look at the loop's heartbeat (from a non-RT thread): feeds the watchdog while it
  // advances, says so in STATUS= (and the log) when it stalls or resumes. Returns how long the
  // caller may wait before the next look (100 ms when the watchdog is off).
  std::chrono::nanoseconds heartbeat(std::uint64_t counter);
  std::chrono::nanoseconds heartbeat(std::uint64_t counter, std::chrono::nanoseconds now);

  // Watchdog feeds sent so far.
  [[nodiscard]] std::uint64_t feeds() const noexcept { return feeds_; }

 private:
  void send(const std::string& text);

  std::string loop_;
  bool socket_{false};
  std::optional<std::chrono::microseconds> interval_{};
  std::optional<WatchdogFeeder> feeder_{};
  std::uint64_t feeds_{0};
};

// Monotonic now (CLOCK_MONOTONIC), the clock the feeder is driven by.
[[nodiscard]] std::chrono::nanoseconds monotonic_now() noexcept;

}  // namespace teleop::runtime
