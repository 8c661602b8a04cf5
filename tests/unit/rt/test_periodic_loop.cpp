// The RT loop thread: its cycles sit on the absolute-deadline grid (checked from the deadlines
// the loop itself reports, not by timing the test), and refused RT settings are named.
#include <gtest/gtest.h>

#include <array>
#include <atomic>
#include <future>
#include <stdexcept>

#include "common/rt/periodic_loop.hpp"

namespace teleop::rt {
namespace {

using std::chrono::microseconds;
using std::chrono::nanoseconds;

TEST(PeriodicLoop, CyclesLieOnTheDeadlineGrid) {
  constexpr std::size_t kCycles = 300;
  std::array<std::int64_t, 100000> deadlines{};
  std::atomic<std::size_t> n{0};
  std::promise<void> enough;
  const nanoseconds period = microseconds(500);
  PeriodicLoop loop(period, RtSettings{}, [&](nanoseconds deadline) {
    const std::size_t i = n.load(std::memory_order_relaxed);
    if (i < deadlines.size()) deadlines[i] = deadline.count();
    n.store(i + 1, std::memory_order_release);
    if (i + 1 == kCycles) enough.set_value();
  });
  loop.start();
  enough.get_future().wait();
  loop.stop();
  const std::size_t count = n.load(std::memory_order_acquire);
  ASSERT_GE(count, kCycles);
  EXPECT_EQ(loop.timing().cycles(), count);
  std::uint64_t skipped = 0;
  for (std::size_t i = 1; i < count && i < deadlines.size(); ++i) {
    const std::int64_t gap = deadlines[i] - deadlines[i - 1];
    ASSERT_GT(gap, 0) << i;
    ASSERT_EQ(gap % period.count(), 0) << i;  // absolute deadlines: no drift, ever
    skipped += static_cast<std::uint64_t>(gap / period.count() - 1);
  }
  // Every deadline skipped between two cycles was counted as an overrun (the last cycle's
  // own overrun, if any, has no next cycle to show it).
  EXPECT_GE(loop.timing().overruns(), skipped);
  EXPECT_LE(loop.timing().overruns(), skipped + 1000);
  EXPECT_EQ(loop.timing().wakeup_latency().count(), count);
}

TEST(RtSettings, RefusalsAreNamedAndFatalOnlyWhenRequired) {
  // Not mlockall here: it would pin the whole test process (and a sanitizer's shadow maps).
  RtSettings s;
  s.fifo_priority = 10;
  std::vector<std::string> refused;
  std::thread t([&] { refused = apply_rt_settings(s); });  // a thread of its own to change
  t.join();
  for (const std::string& r : refused) {
    EXPECT_EQ(r.rfind("SCHED_FIFO", 0), 0u) << r;
  }
  s.required = true;
  std::thread u([&] {
    if (refused.empty()) {
      EXPECT_NO_THROW((void)apply_rt_settings(s));
    } else {
      EXPECT_THROW((void)apply_rt_settings(s), std::runtime_error);
    }
  });
  u.join();
  // An impossible CPU is refused on any machine, and names itself.
  RtSettings bad;
  bad.cpu = 1023;
  bad.required = true;
  std::thread w([&] {
    try {
      (void)apply_rt_settings(bad);
      ADD_FAILURE() << "CPU 1023 accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("CPU affinity"), std::string::npos) << e.what();
    }
  });
  w.join();
}

}  // namespace
}  // namespace teleop::rt
