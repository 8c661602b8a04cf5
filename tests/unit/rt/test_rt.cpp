// RT building blocks. Expected values by hand (histogram bin edges 2^(i/3) us, deadline grid
// arithmetic) and by invariants a lost, reordered or torn record would break.
#include <gtest/gtest.h>

#include <cstdint>
#include <thread>

#include "common/rt/latest_value.hpp"
#include "common/rt/loop_timing.hpp"
#include "common/rt/spsc_queue.hpp"

namespace teleop::rt {
namespace {

using std::chrono::microseconds;
using std::chrono::milliseconds;
using std::chrono::nanoseconds;

TEST(SpscQueue, FifoFullAndDropped) {
  SpscQueue<int, 4> q;
  EXPECT_FALSE(q.try_pop().has_value());
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(q.try_push(i));
  EXPECT_FALSE(q.try_push(99));  // full: dropped, counted
  EXPECT_EQ(q.dropped(), 1u);
  EXPECT_EQ(q.size(), 4u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(q.try_pop().value(), i);
  EXPECT_FALSE(q.try_pop().has_value());
}

TEST(SpscQueue, TwoThreadsLoseAndReorderNothing) {
  constexpr std::uint64_t kCount = 1'000'000;
  SpscQueue<std::uint64_t, 1024> q;
  std::thread producer([&] {
    for (std::uint64_t i = 1; i <= kCount; ++i) {
      while (!q.try_push(i)) std::this_thread::yield();
    }
  });
  std::uint64_t expected = 1;
  bool in_order = true;
  while (expected <= kCount) {
    if (const auto v = q.try_pop()) {
      in_order = in_order && *v == expected;
      ++expected;
    }
  }
  producer.join();
  EXPECT_TRUE(in_order);
  EXPECT_FALSE(q.try_pop().has_value());
}

struct Pair {
  std::uint64_t a{0};
  std::uint64_t b{1};  // always 3 a + 1 when written
};

TEST(LatestValue, NewestWinsAndReadsOnce) {
  LatestValue<Pair> v;
  Pair out;
  EXPECT_FALSE(v.read(out));
  v.write({1, 4});
  v.write({2, 7});
  ASSERT_TRUE(v.read(out));
  EXPECT_EQ(out.a, 2u);
  EXPECT_FALSE(v.read(out));  // nothing new
  v.write({3, 10});
  ASSERT_TRUE(v.read(out));
  EXPECT_EQ(out.a, 3u);
}

TEST(LatestValue, ConcurrentReadsAreNeverTornNorOlder) {
  LatestValue<Pair> v;
  constexpr std::uint64_t kWrites = 500'000;
  std::thread writer([&] {
    for (std::uint64_t a = 1; a <= kWrites; ++a) v.write({a, 3 * a + 1});
  });
  std::uint64_t last = 0;
  bool consistent = true;
  bool monotonic = true;
  while (last < kWrites) {
    Pair p;
    if (v.read(p)) {
      consistent = consistent && p.b == 3 * p.a + 1;
      monotonic = monotonic && p.a > last;
      last = p.a;
    }
  }
  writer.join();
  EXPECT_TRUE(consistent);
  EXPECT_TRUE(monotonic);
}

TEST(LatencyHistogram, QuantilesAreBinEdgesByHand) {
  LatencyHistogram h;
  for (int i = 0; i < 99; ++i) h.add(microseconds(10));
  h.add(microseconds(1000));
  // 10 us: bin ceil(3 log2 10) = 10, upper edge 2^(10/3) us = 10.079 us.
  EXPECT_NEAR(static_cast<double>(h.quantile(0.5).count()), 10079.4, 1.0);
  EXPECT_NEAR(static_cast<double>(h.quantile(0.99).count()), 10079.4, 1.0);
  // 1000 us: bin ceil(3 log2 1000) = 30, edge 2^10 us.
  EXPECT_EQ(h.quantile(1.0), microseconds(1024));
  EXPECT_EQ(h.max(), microseconds(1000));
  EXPECT_EQ(h.count(), 100u);
}

TEST(LoopTiming, DeadlinesLatencyAndSkipAhead) {
  LoopTiming t(milliseconds(1), nanoseconds(0));
  EXPECT_EQ(t.next_deadline(), milliseconds(1));
  EXPECT_EQ(t.woke(milliseconds(1) + microseconds(20)), milliseconds(1));
  EXPECT_EQ(t.next_deadline(), milliseconds(2));
  t.finished(microseconds(1300));
  EXPECT_EQ(t.overruns(), 0u);
  // Slept through the deadlines at 3, 4 and 5 ms: three overruns, resume at 6 ms.
  EXPECT_EQ(t.woke(microseconds(5100)), milliseconds(2));
  EXPECT_EQ(t.overruns(), 3u);
  EXPECT_EQ(t.next_deadline(), milliseconds(6));
  // The work ran past 6 ms: that cycle is lost too, next at 7 ms.
  t.finished(microseconds(6500));
  EXPECT_EQ(t.overruns(), 4u);
  EXPECT_EQ(t.next_deadline(), milliseconds(7));
  EXPECT_EQ(t.cycles(), 2u);
  EXPECT_EQ(t.wakeup_latency().max(), microseconds(3100));
  EXPECT_EQ(t.compute_time().max(), microseconds(1400));
}

}  // namespace
}  // namespace teleop::rt
