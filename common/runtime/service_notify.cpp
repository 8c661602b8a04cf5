#include "common/runtime/service_notify.hpp"

#include <spdlog/spdlog.h>
#include <systemd/sd-daemon.h>
#include <time.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>

namespace teleop::runtime {
namespace {

using namespace std::chrono_literals;

long long to_ms(std::chrono::nanoseconds d) {
  return std::chrono::duration_cast<std::chrono::milliseconds>(d).count();
}

// One STATUS= line: the protocol separates assignments by newlines.
std::string one_line(const std::string& text) {
  std::string out = text;
  std::replace(out.begin(), out.end(), '\n', ' ');
  return out;
}

}  // namespace

std::chrono::nanoseconds monotonic_now() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::chrono::seconds(ts.tv_sec) + std::chrono::nanoseconds(ts.tv_nsec);
}

WatchdogFeeder::WatchdogFeeder(std::chrono::microseconds watchdog_interval,
                               std::chrono::nanoseconds stall_limit, std::chrono::nanoseconds now)
    : interval_(watchdog_interval),
      feed_every_(std::chrono::nanoseconds(watchdog_interval) / 2),
      stall_limit_(stall_limit),
      advanced_at_(now) {}

std::chrono::nanoseconds WatchdogFeeder::default_stall_limit(
    std::chrono::microseconds watchdog_interval) {
  return std::min<std::chrono::nanoseconds>(watchdog_interval / 4, 1s);
}

WatchdogAction WatchdogFeeder::observe(std::uint64_t heartbeat, std::chrono::nanoseconds now) {
  WatchdogAction action;
  if (!heartbeat_) {
    heartbeat_ = heartbeat;
    advanced_at_ = now;
    return action;
  }
  const std::chrono::nanoseconds quiet = now - advanced_at_;
  if (heartbeat != *heartbeat_) {
    heartbeat_ = heartbeat;
    advanced_at_ = now;
    if (stalled_) {
      stalled_ = false;
      action.status = "running again after " + std::to_string(to_ms(quiet)) +
                      " ms without a cycle; feeding the watchdog";
    }
  } else if (!stalled_ && quiet > stall_limit_) {
    stalled_ = true;
    action.status = "stalled: its cycle counter has stayed at " + std::to_string(heartbeat) +
                    " for " + std::to_string(to_ms(quiet)) + " ms (limit " +
                    std::to_string(to_ms(stall_limit_)) +
                    " ms); not feeding the watchdog (WATCHDOG_USEC " +
                    std::to_string(to_ms(interval_)) + " ms)";
  }
  if (!stalled_ && (!fed_at_ || now - *fed_at_ >= feed_every_)) {
    action.feed = true;
    fed_at_ = now;
  }
  return action;
}

std::chrono::nanoseconds WatchdogFeeder::wait_after(std::chrono::nanoseconds now) const {
  const std::chrono::nanoseconds look = std::min<std::chrono::nanoseconds>(100ms, stall_limit_ / 2);
  if (!fed_at_ || stalled_) return std::max<std::chrono::nanoseconds>(look, 1ms);
  const std::chrono::nanoseconds until_due = *fed_at_ + feed_every_ - now;
  if (until_due <= 0ns) return std::max<std::chrono::nanoseconds>(look, 1ms);
  return std::min(until_due, std::max<std::chrono::nanoseconds>(look, 1ms));
}

ServiceNotifier::ServiceNotifier(std::string loop) : loop_(std::move(loop)) {
  const char* socket = std::getenv("NOTIFY_SOCKET");
  socket_ = socket != nullptr && socket[0] != '\0';
  std::uint64_t usec = 0;
  const int enabled = sd_watchdog_enabled(0, &usec);
  if (!socket_) {
    spdlog::info("systemd notify: off (no NOTIFY_SOCKET); watchdog off");
    return;
  }
  if (enabled < 0) {
    spdlog::warn("systemd notify: on ({}); watchdog off: WATCHDOG_USEC/WATCHDOG_PID unusable ({})",
                 socket, std::strerror(-enabled));
    return;
  }
  if (enabled == 0 || usec == 0) {
    spdlog::info("systemd notify: on ({}); watchdog off (no WATCHDOG_USEC for this process)",
                 socket);
    return;
  }
  interval_ = std::chrono::microseconds(static_cast<long long>(usec));
  feeder_.emplace(*interval_, WatchdogFeeder::default_stall_limit(*interval_), monotonic_now());
  spdlog::info(
      "systemd notify: on ({}); watchdog on, interval {} ms: fed every {} ms while the {} "
      "advances, no longer fed once it has not for {} ms",
      socket, to_ms(*interval_), to_ms(feeder_->feed_every()), loop_,
      to_ms(feeder_->stall_limit()));
}

void ServiceNotifier::send(const std::string& text) {
  if (!socket_) return;
  const int rc = sd_notify(0, text.c_str());
  if (rc < 0) spdlog::warn("sd_notify failed: {}", std::strerror(-rc));
}

void ServiceNotifier::ready(const std::string& status) {
  send("READY=1\nSTATUS=" + one_line(status));
}

void ServiceNotifier::stopping(const std::string& status) {
  send("STOPPING=1\nSTATUS=" + one_line(status));
}

void ServiceNotifier::status(const std::string& status) { send("STATUS=" + one_line(status)); }

std::chrono::nanoseconds ServiceNotifier::heartbeat(std::uint64_t counter) {
  return heartbeat(counter, monotonic_now());
}

std::chrono::nanoseconds ServiceNotifier::heartbeat(std::uint64_t counter,
                                                    std::chrono::nanoseconds now) {
  if (!feeder_) return 100ms;
  const WatchdogAction action = feeder_->observe(counter, now);
  std::string text;
  if (action.feed) {
    text = "WATCHDOG=1";
    ++feeds_;
  }
  if (!action.status.empty()) {
    const std::string status = loop_ + " " + action.status;
    if (feeder_->stalled()) {
      spdlog::error("{}", status);
    } else {
      spdlog::warn("{}", status);
    }
    text += (text.empty() ? "" : "\n") + ("STATUS=" + one_line(status));
  }
  if (!text.empty()) send(text);
  return feeder_->wait_after(now);
}

}  // namespace teleop::runtime
