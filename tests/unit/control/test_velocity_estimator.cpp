// Backward difference and first-order low-pass against closed forms (docs/architecture.md §2.4).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "common/control/velocity_estimator.hpp"

namespace teleop::control {
namespace {

constexpr double kT = 1e-3;

TEST(VelocityEstimator, FirstSamplePrimesAndReturnsZero) {
  VelocityEstimator est(kT, 0.0);
  EXPECT_EQ(est.step(0.123), 0.0);
  EXPECT_NEAR(est.step(0.124), 1.0, 1e-12);  // 1 mm in 1 ms
}

TEST(VelocityEstimator, RampGivesItsSlopeWithoutFilter) {
  VelocityEstimator est(kT, 0.0);
  const double x0 = 0.05;
  const double v = -0.37;
  est.reset(x0);
  for (int k = 1; k <= 1000; ++k) {
    const double x = x0 + v * k * kT;
    EXPECT_NEAR(est.step(x), v, 1e-10) << "k = " << k;
  }
  EXPECT_EQ(est.smoothing(), 1.0);
}

TEST(VelocityEstimator, FilterGainIsOneMinusExpOfCutoff) {
  const VelocityEstimator est(kT, 200.0);
  // 1 - e^{-2 pi 200 * 0.001} = 1 - e^{-0.4 pi}
  EXPECT_NEAR(est.smoothing(), 1.0 - std::exp(-0.4 * std::numbers::pi), 1e-15);
  EXPECT_NEAR(est.smoothing(), 0.715390, 1e-6);
}

// A ramp that starts from rest is a velocity step v: v_f(k) = v (1 - r^k), r = e^{-2 pi fc T}.
TEST(VelocityEstimator, FilteredRampFollowsStepResponse) {
  for (const double fc : {5.0, 35.0, 200.0, 900.0}) {
    VelocityEstimator est(kT, fc);
    const double r = std::exp(-2.0 * std::numbers::pi * fc * kT);
    const double x0 = -0.02;
    const double v = 0.25;
    est.reset(x0);
    for (int k = 1; k <= 400; ++k) {
      const double expected = v * (1.0 - std::pow(r, k));
      EXPECT_NEAR(est.step(x0 + v * k * kT), expected, 1e-11) << "fc = " << fc << " k = " << k;
      EXPECT_NEAR(est.raw_velocity_m_per_s(), v, 1e-10);
    }
  }
}

// A position step h at k = 1 is a velocity impulse h/T: v_f(k) = a (h/T) r^{k-1}.
TEST(VelocityEstimator, FilteredPositionStepIsDecayingImpulse) {
  const double fc = 50.0;
  VelocityEstimator est(kT, fc);
  const double r = std::exp(-2.0 * std::numbers::pi * fc * kT);
  const double a = 1.0 - r;
  const double h = 0.001;
  est.reset(0.0);
  for (int k = 1; k <= 200; ++k) {
    EXPECT_NEAR(est.step(h), a * (h / kT) * std::pow(r, k - 1), 1e-12) << "k = " << k;
  }
}

TEST(VelocityEstimator, ResetRestsAtGivenPositionOrNextSample) {
  VelocityEstimator est(kT, 100.0);
  est.reset(0.0);
  static_cast<void>(est.step(0.01));
  EXPECT_NE(est.velocity_m_per_s(), 0.0);
  est.reset(0.5);
  EXPECT_EQ(est.velocity_m_per_s(), 0.0);
  EXPECT_NEAR(est.step(0.5), 0.0, 0.0);
  est.reset();
  EXPECT_EQ(est.step(7.0), 0.0);
}

TEST(VelocityEstimator, RejectsBadSetup) {
  EXPECT_THROW(VelocityEstimator(0.0, 0.0), std::invalid_argument);
  EXPECT_THROW(VelocityEstimator(-1e-3, 0.0), std::invalid_argument);
  EXPECT_THROW(VelocityEstimator(kT, -1.0), std::invalid_argument);
  EXPECT_THROW(VelocityEstimator(kT, std::nan("")), std::invalid_argument);
}

}  // namespace
}  // namespace teleop::control
