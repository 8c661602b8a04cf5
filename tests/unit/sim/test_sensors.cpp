// Encoder quantisation, load-cell noise/range/bias, amplifier saturation.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <vector>

#include "common/sim/sensors.hpp"

namespace teleop::sim {
namespace {

TEST(Encoder, QuantumIsTheArcPerCountAtTheHandle) {
  for (const double ratio : {1.0, 10.0, 19.7}) {
    const Encoder enc({500, ratio, 0.115});
    EXPECT_DOUBLE_EQ(enc.step_m(), 2.0 * std::numbers::pi * 0.115 / (500.0 * ratio));
  }
  EXPECT_NEAR(Encoder(EncoderParams{}).step_m(), 1.4451e-4, 1e-8);  // the default, 10:1
}

TEST(Encoder, ASlowRampReadsAStaircase) {
  const Encoder enc(EncoderParams{});
  const double q = enc.step_m();
  EXPECT_EQ(enc.read_m(0.0), 0.0);
  double previous = enc.read_m(-0.005);
  int risers = 0;
  for (int i = 1; i <= 100000; ++i) {
    const double x = -0.005 + 0.02 * i / 100000.0;  // 0.2 um per sample, ~700 samples per count
    const double r = enc.read_m(x);
    EXPECT_LE(std::abs(r - x), q / 2 + 1e-15);
    const double counts = r / q;
    EXPECT_NEAR(counts, std::round(counts), 1e-9);  // on the grid
    if (r != previous) {
      EXPECT_NEAR(r - previous, q, 1e-12);  // one count at a time, never down
      ++risers;
    }
    previous = r;
  }
  EXPECT_NEAR(risers, 0.02 / q, 1.0);
}

TEST(Encoder, RejectsNonsense) {
  EXPECT_THROW(Encoder({0, 10.0, 0.115}), std::invalid_argument);
  EXPECT_THROW(Encoder({500, 0.0, 0.115}), std::invalid_argument);
  EXPECT_THROW(Encoder({500, 10.0, -1.0}), std::invalid_argument);
}

TEST(LoadCell, NoiseHasTheConfiguredStandardDeviationAndBias) {
  for (const double sigma : {0.01, 0.2}) {
    LoadCell cell({sigma, 10.0, 0.05, 0.0}, 42);
    const int n = 100000;
    double sum = 0.0;
    double sum2 = 0.0;
    for (int i = 0; i < n; ++i) {
      const double e = cell.measure(1.0).force_N - 1.05;
      sum += e;
      sum2 += e * e;
    }
    const double mean = sum / n;
    const double std_dev = std::sqrt(sum2 / n - mean * mean);
    EXPECT_NEAR(std_dev, sigma, 0.02 * sigma);
    EXPECT_NEAR(mean, 0.0, 4.0 * sigma / std::sqrt(n));
  }
}

TEST(LoadCell, SameSeedSameNoiseOtherSeedOtherNoise) {
  const LoadCellParams p{0.1, 10.0, 0.0, 0.0};
  LoadCell a(p, 7);
  LoadCell b(p, 7);
  LoadCell c(p, 8);
  int differ = 0;
  for (int i = 0; i < 1000; ++i) {
    const double ra = a.measure(0.5).force_N;
    EXPECT_EQ(ra, b.measure(0.5).force_N);
    if (ra != c.measure(0.5).force_N) ++differ;
  }
  EXPECT_EQ(differ, 1000);
  a.reseed(7);
  LoadCell fresh(p, 7);
  EXPECT_EQ(a.measure(0.0).force_N, fresh.measure(0.0).force_N);
}

TEST(LoadCell, ClipsToItsRangeAndFlagsIt) {
  LoadCell cell(LoadCellParams{}, 1);
  EXPECT_EQ(cell.measure(12.0).force_N, 10.0);
  EXPECT_TRUE(cell.measure(12.0).clipped);
  EXPECT_EQ(cell.measure(-12.0).force_N, -10.0);
  EXPECT_TRUE(cell.measure(-12.0).clipped);
  EXPECT_EQ(cell.measure(9.9).force_N, 9.9);
  EXPECT_FALSE(cell.measure(9.9).clipped);
  EXPECT_FALSE(cell.measure(10.0).clipped);
  EXPECT_TRUE(cell.measure(std::numeric_limits<double>::quiet_NaN()).clipped);
  LoadCell biased({0.0, 10.0, 0.5, 0.0}, 1);
  EXPECT_TRUE(biased.measure(9.8).clipped);  // the bias pushes it over
}

TEST(LoadCell, QuantisesToItsResolution) {
  LoadCell cell({0.0, 10.0, 0.0, 0.01}, 1);
  EXPECT_NEAR(cell.measure(1.234).force_N, 1.23, 1e-12);
  EXPECT_NEAR(cell.measure(-1.236).force_N, -1.24, 1e-12);
}

TEST(Amplifier, SaturatesAndFlags) {
  const Amplifier amp({5.0});
  EXPECT_EQ(amp.apply(3.0).force_N, 3.0);
  EXPECT_FALSE(amp.apply(3.0).saturated);
  EXPECT_EQ(amp.apply(7.0).force_N, 5.0);
  EXPECT_TRUE(amp.apply(7.0).saturated);
  EXPECT_EQ(amp.apply(-7.0).force_N, -5.0);
  EXPECT_TRUE(amp.apply(-7.0).saturated);
  const AmplifierOutput nan = amp.apply(std::numeric_limits<double>::quiet_NaN());
  EXPECT_TRUE(nan.rejected);
  EXPECT_EQ(nan.force_N, 0.0);
  EXPECT_TRUE(amp.apply(std::numeric_limits<double>::infinity()).rejected);
  EXPECT_DOUBLE_EQ(AmplifierParams{}.max_force_N, 10.0 * 1.65);
  EXPECT_THROW(Amplifier({0.0}), std::invalid_argument);
}

}  // namespace
}  // namespace teleop::sim
