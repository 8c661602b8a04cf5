#include "common/rt/periodic_loop.hpp"

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <time.h>

#include <cerrno>
#include <cstring>
#include <future>
#include <optional>
#include <stdexcept>

#include "common/rt/fifo_check.hpp"

namespace teleop::rt {

namespace {

std::string refusal(const std::string& what, int error) {
  return what + ": " + std::strerror(error);
}

}  // namespace

// Runs at start, before the first cycle: the facts behind a refusal are read from /proc and
// /sys here, never in the loop.
std::vector<std::string> apply_rt_settings(const RtSettings& s) {
  std::vector<std::string> refused;
  std::optional<RtFacts> facts;
  auto gathered = [&facts]() -> const RtFacts& {
    if (!facts) facts = gather_rt_facts();
    return *facts;
  };
  if (s.lock_memory && mlockall(MCL_CURRENT | MCL_FUTURE) != 0) {
    const int error = errno;
    std::string r = refusal("mlockall", error);
    if (error == EPERM || error == ENOMEM || error == EAGAIN) {
      r += ". " + explain_mlock_refusal(gathered());
    }
    refused.push_back(r);
  }
  if (s.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<unsigned>(s.cpu), &set);
    const int rc = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
    if (rc != 0) refused.push_back(refusal("CPU affinity", rc));
  }
  if (s.fifo_priority > 0) {
    sched_param p{};
    p.sched_priority = s.fifo_priority;
    const int rc = pthread_setschedparam(pthread_self(), SCHED_FIFO, &p);
    if (rc != 0) {
      std::string r = refusal("SCHED_FIFO priority " + std::to_string(s.fifo_priority), rc);
      if (rc == EPERM || rc == EINVAL)
        r += ". " + explain_fifo_refusal(gathered(), s.fifo_priority);
      refused.push_back(r);
    }
  }
  if (s.required && !refused.empty()) {
    std::string text = "real-time settings refused (rt.required is set):";
    for (const std::string& r : refused) text += "\n  " + r;
    throw std::runtime_error(text);
  }
  return refused;
}

std::chrono::nanoseconds PeriodicLoop::monotonic_now() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::chrono::seconds(ts.tv_sec) + std::chrono::nanoseconds(ts.tv_nsec);
}

PeriodicLoop::PeriodicLoop(std::chrono::nanoseconds period, RtSettings settings, Step step)
    : period_(period), settings_(settings), step_(std::move(step)), timing_(period, {}) {
  if (period_.count() <= 0) throw std::invalid_argument("loop period must be > 0");
}

PeriodicLoop::~PeriodicLoop() { stop(); }

void PeriodicLoop::start() {
  if (started_.exchange(true)) return;
  std::promise<std::vector<std::string>> ready;
  auto refused = ready.get_future();
  running_ = true;
  thread_ = std::thread([this, &ready] {
    try {
      ready.set_value(apply_rt_settings(settings_));
    } catch (...) {
      running_ = false;
      ready.set_exception(std::current_exception());
      return;
    }
    run();
  });
  try {
    refused_ = refused.get();
  } catch (...) {
    thread_.join();
    throw;
  }
}

void PeriodicLoop::stop() {
  running_ = false;
  if (thread_.joinable()) thread_.join();
}

void PeriodicLoop::run() {
  timing_ = LoopTiming(period_, monotonic_now());
  while (running_.load(std::memory_order_relaxed)) {
    const std::chrono::nanoseconds deadline = timing_.next_deadline();
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(deadline.count() / 1'000'000'000);
    ts.tv_nsec = static_cast<long>(deadline.count() % 1'000'000'000);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    const std::chrono::nanoseconds cycle = timing_.woke(monotonic_now());
    step_(cycle);
    timing_.finished(monotonic_now());
  }
}

}  // namespace teleop::rt
