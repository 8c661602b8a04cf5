// The fault-injecting relay's decisions (teleopctl relay): each fault at the rate asked for
// (binomial bounds), delays where they were put, blackouts exactly in their window, and the
// same decisions for the same seed.
#include <gtest/gtest.h>

#include <cmath>

#include "supervisor/teleopctl/relay_command.hpp"

namespace teleop::ctl {
namespace {

// Within 5 standard deviations of a binomial(n, p) count.
void expect_binomial(std::uint64_t count, std::uint64_t n, double p, const char* what) {
  const double mean = static_cast<double>(n) * p;
  const double sd = std::sqrt(static_cast<double>(n) * p * (1.0 - p));
  EXPECT_NEAR(static_cast<double>(count), mean, 5.0 * sd + 1e-9) << what;
}

TEST(RelayPlanner, PureDelayForwardsEveryMessageOnceAtTheDelay) {
  RelayFaults f;
  f.delay_ms = 2.5;
  RelayPlanner p(f);
  for (int i = 0; i < 1000; ++i) {
    const RelayPlan plan = p.plan(i * 1e-3);
    ASSERT_EQ(plan.delays_ms.size(), 1u);
    EXPECT_EQ(plan.delays_ms[0], 2.5);
    EXPECT_FALSE(plan.hold);
  }
  EXPECT_EQ(p.received, 1000u);
  EXPECT_EQ(p.dropped + p.duplicated + p.reordered + p.blacked_out, 0u);
}

TEST(RelayPlanner, DropsDuplicatesAndReordersAtTheirRates) {
  RelayFaults f;
  f.drop = 0.1;
  f.duplicate = 0.2;
  f.reorder = 0.05;
  f.seed = 7;
  RelayPlanner p(f);
  constexpr std::uint64_t n = 100000;
  std::uint64_t copies = 0;
  for (std::uint64_t i = 0; i < n; ++i) {
    const RelayPlan plan = p.plan(static_cast<double>(i) * 1e-3);
    copies += plan.delays_ms.size();
    if (plan.delays_ms.size() == 2) {
      EXPECT_GT(plan.delays_ms[1], plan.delays_ms[0]);
    }
  }
  expect_binomial(p.dropped, n, 0.1, "dropped");
  // Duplicates and reorders are decided for the messages not dropped.
  expect_binomial(p.duplicated, n - p.dropped, 0.2, "duplicated");
  expect_binomial(p.reordered, n - p.dropped, 0.05, "reordered");
  EXPECT_EQ(copies, n - p.dropped + p.duplicated);
}

// --in-order: jitter of 3.5 +- 1.5 ms on a 1 ms stream would overtake itself about a third of
// the time; in order, send times never decrease, no delay is below its own draw's band
// (>= 2 ms), and a message is held only as long as the one before it.
TEST(RelayPlanner, InOrderJitterNeverOvertakesAndHoldsNoLongerThanThePreviousMessage) {
  RelayFaults f;
  f.delay_ms = 3.5;
  f.jitter_ms = 1.5;
  f.seed = 11;
  RelayFaults g = f;
  g.in_order = true;
  RelayPlanner free_running(f);
  RelayPlanner in_order(g);
  double last_free = -1.0;
  double last = -1.0;
  int overtaken = 0;
  for (int i = 0; i < 10000; ++i) {
    const double at_ms = i * 1.0;
    const RelayPlan a = free_running.plan(at_ms * 1e-3);
    const RelayPlan b = in_order.plan(at_ms * 1e-3);
    ASSERT_EQ(b.delays_ms.size(), 1u);
    if (at_ms + a.delays_ms[0] < last_free) ++overtaken;
    last_free = at_ms + a.delays_ms[0];
    // Same draws: the in-order delay is the free one, or raised to the previous send time.
    const double send = at_ms + b.delays_ms[0];
    EXPECT_GE(b.delays_ms[0], a.delays_ms[0]);
    EXPECT_GE(b.delays_ms[0], 2.0);
    EXPECT_LE(b.delays_ms[0], 5.0);
    if (b.delays_ms[0] > a.delays_ms[0]) {
      EXPECT_DOUBLE_EQ(send, last);
    }
    EXPECT_GE(send, last - 1e-9);  // (ms; rounding of the time arithmetic only)
    last = send;
  }
  EXPECT_GT(overtaken, 1000);  // the free-running relay does reorder (about 1 in 4)
}

TEST(RelayPlanner, JitterStaysWithinItsBandAndAveragesToTheDelay) {
  RelayFaults f;
  f.delay_ms = 3.0;
  f.jitter_ms = 1.0;
  RelayPlanner p(f);
  double sum = 0.0;
  constexpr int n = 40000;
  for (int i = 0; i < n; ++i) {
    const double d = p.plan(i * 1e-3).delays_ms.at(0);
    ASSERT_GE(d, 2.0);
    ASSERT_LE(d, 4.0);
    sum += d;
  }
  // Uniform on [2, 4]: mean 3, standard deviation 2 / sqrt(12) per draw.
  EXPECT_NEAR(sum / n, 3.0, 5.0 * (2.0 / std::sqrt(12.0)) / std::sqrt(n));
  // A jitter larger than the delay never makes a negative delay.
  RelayFaults g;
  g.delay_ms = 0.5;
  g.jitter_ms = 2.0;
  RelayPlanner q(g);
  for (int i = 0; i < 1000; ++i) ASSERT_GE(q.plan(i * 1e-3).delays_ms.at(0), 0.0);
}

TEST(RelayPlanner, BlackoutDropsExactlyTheMessagesInItsWindow) {
  RelayFaults f;
  f.blackout_at_s = 1.0;
  f.blackout_ms = 200.0;
  RelayPlanner p(f);
  for (int i = 0; i < 3000; ++i) {  // one message per ms for 3 s
    const double t = i * 1e-3;
    const bool inside = i >= 1000 && i < 1200;
    EXPECT_EQ(p.plan(t).delays_ms.empty(), inside) << "t=" << t;
  }
  EXPECT_EQ(p.blacked_out, 200u);
}

TEST(RelayPlanner, TheSameSeedMakesTheSameDecisions) {
  RelayFaults f;
  f.drop = 0.3;
  f.duplicate = 0.3;
  f.reorder = 0.3;
  f.jitter_ms = 1.0;
  f.delay_ms = 1.0;
  f.seed = 42;
  RelayPlanner a(f);
  RelayPlanner b(f);
  f.seed = 43;
  RelayPlanner c(f);
  int differ = 0;
  for (int i = 0; i < 1000; ++i) {
    const RelayPlan pa = a.plan(i * 1e-3);
    const RelayPlan pb = b.plan(i * 1e-3);
    const RelayPlan pc = c.plan(i * 1e-3);
    ASSERT_EQ(pa.delays_ms, pb.delays_ms);
    ASSERT_EQ(pa.hold, pb.hold);
    if (pa.delays_ms != pc.delays_ms || pa.hold != pc.hold) ++differ;
  }
  EXPECT_GT(differ, 100);  // another seed decides otherwise
}

}  // namespace
}  // namespace teleop::ctl
