// The round trip's windowed quantiles (common/rt/windowed_histogram.hpp). Expected values are
// nearest-rank quantiles computed here from the values fed, and bin edges 1 us * 2^(i/24).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "common/rt/windowed_histogram.hpp"

namespace teleop::rt {
namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr double kBinRatio = 1.0293022366434921;  // 2^(1/24)

// Nearest rank of a sorted copy.
std::int64_t nearest_rank(std::vector<std::int64_t> v, double q) {
  std::sort(v.begin(), v.end());
  const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
  return v[std::max<std::size_t>(rank, 1) - 1];
}

TEST(WindowedHistogram, AQuantileIsTheTrueOneOrAtMostOneBinLonger) {
  // 5000 round trips at 1 kHz, uniform in 0.5..7.5 ms (one second's slot is 1000 of them).
  std::mt19937 rng(42);
  std::uniform_int_distribution<std::int64_t> d(500'000, 7'500'000);
  WindowedHistogram h;
  std::vector<std::int64_t> fed;
  for (int k = 0; k < 5000; ++k) {
    fed.push_back(d(rng));
    h.add(k * kMs, fed.back());
  }
  ASSERT_EQ(h.count(), 5000u);
  for (const double q : {0.5, 0.9, 0.99, 0.999}) {
    const auto truth = static_cast<double>(nearest_rank(fed, q));
    const auto got = static_cast<double>(h.quantile(q));
    EXPECT_GE(got, truth) << q;
    EXPECT_LE(got, truth * kBinRatio * (1.0 + 1e-9)) << q;
  }
}

TEST(WindowedHistogram, BinEdgesAreOneMicrosecondTimesTwoToTheIOverTwentyFour) {
  EXPECT_EQ(WindowedHistogram::upper_edge_ns(0), 1000);
  EXPECT_EQ(WindowedHistogram::upper_edge_ns(24), 2000);
  EXPECT_EQ(WindowedHistogram::upper_edge_ns(240), 1'024'000);
  // A value on an edge is in the bin the edge closes; one ns more is in the next.
  EXPECT_EQ(WindowedHistogram::bin_of(2000), 24);
  EXPECT_EQ(WindowedHistogram::bin_of(2001), 25);
  EXPECT_EQ(WindowedHistogram::bin_of(0), 0);
  EXPECT_EQ(WindowedHistogram::bin_of(-5), 0);
  EXPECT_EQ(WindowedHistogram::bin_of(std::int64_t{10'000'000'000}), WindowedHistogram::kBins - 1);
}

TEST(WindowedHistogram, AnHourOfAShortRoundTripDoesNotHideAGrownOne) {
  // An hour at 1 ms, then 3 ms: the p99 of the window (9-10 s, about 9500 samples) is 3 ms's
  // bin once more than 1 % of the window is at 3 ms, i.e. after at most 100 samples (0.1 s).
  // Over the whole hour (3.6 million samples) it would take 36 000, i.e. 36 s.
  WindowedHistogram h;
  std::int64_t t = 0;
  for (int k = 0; k < 3'600'000; ++k, t += kMs) h.add(t, 1 * kMs);
  const std::int64_t one = h.quantile(0.99);
  EXPECT_GE(one, 1 * kMs);
  EXPECT_LE(static_cast<double>(one), kBinRatio * 1e6);
  int grown_after = -1;
  for (int k = 0; k < 1000; ++k, t += kMs) {
    h.add(t, 3 * kMs);
    if (grown_after < 0 && h.quantile(0.99) >= 3 * kMs) grown_after = k + 1;
  }
  ASSERT_GT(grown_after, 0);
  EXPECT_LE(grown_after, 101);
  // Back to 1 ms: the 3 ms second leaves the window 10 s later, not before 9 s.
  int shrunk_after = -1;
  for (int k = 0; k < 12'000; ++k, t += kMs) {
    h.add(t, 1 * kMs);
    if (shrunk_after < 0 && h.quantile(0.99) < 3 * kMs) shrunk_after = k + 1;
  }
  ASSERT_GT(shrunk_after, 0);
  EXPECT_GE(shrunk_after, 8'000);  // the 3 ms slot started up to 1 s before the switch
  EXPECT_LE(shrunk_after, 10'000);
}

TEST(WindowedHistogram, ASilenceLongerThanTheWindowEmptiesIt) {
  WindowedHistogram h;
  for (int k = 0; k < 100; ++k) h.add(k * kMs, 2 * kMs);
  h.advance(100 * kMs + 10'000 * kMs);
  EXPECT_EQ(h.count(), 0u);
  EXPECT_EQ(h.quantile(0.99), 0);
  h.add(20'000 * kMs, 4 * kMs);
  EXPECT_EQ(h.count(), 1u);
  EXPECT_GE(h.quantile(0.5), 4 * kMs);
}

}  // namespace
}  // namespace teleop::rt
