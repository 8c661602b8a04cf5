// The Vlachos-Papadopoulos force loop (docs/architecture.md §2.8):
//   F_in = F_des + K_p (F_des - F_avg) + K_i I,  I(k) = I(k-1) + T (F_des - F_avg)(k),
// F_avg the mean of the last N sensor samples. Expected values by hand.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "common/control/force_loop_controller.hpp"
#include "common/control/master_law.hpp"

namespace teleop::control {
namespace {

constexpr double kT = 1e-3;

[[nodiscard]] ForceLoopSettings settings(double kp, double ki, int n = 50) {
  ForceLoopSettings s;
  s.period_s = kT;
  s.kp = kp;
  s.ki = ki;
  s.average_samples = n;
  return s;
}

TEST(MovingAverage, AverageOfAConstantIsTheConstant) {
  MovingAverage avg(50);
  EXPECT_EQ(avg.window(), 50);
  for (int k = 0; k < 500; ++k) {
    EXPECT_DOUBLE_EQ(avg.push(0.37), 0.37) << k;
  }
  EXPECT_EQ(avg.count(), 50);
}

TEST(MovingAverage, StepRampsOverTheWindow) {
  MovingAverage avg(50);
  for (int k = 0; k < 120; ++k) static_cast<void>(avg.push(0.0));
  // After j samples of 1 N the window holds j ones and 50 - j zeros: mean j / 50.
  for (int j = 1; j <= 80; ++j) {
    EXPECT_NEAR(avg.push(1.0), std::min(j, 50) / 50.0, 1e-15) << j;
  }
}

TEST(MovingAverage, FillingWindowAveragesWhatItHas) {
  MovingAverage avg(4);
  EXPECT_DOUBLE_EQ(avg.push(2.0), 2.0);
  EXPECT_DOUBLE_EQ(avg.push(4.0), 3.0);
  EXPECT_DOUBLE_EQ(avg.push(6.0), 4.0);
  EXPECT_DOUBLE_EQ(avg.push(8.0), 5.0);
  EXPECT_DOUBLE_EQ(avg.push(10.0), 7.0);  // (4 + 6 + 8 + 10) / 4
  avg.clear();
  EXPECT_EQ(avg.count(), 0);
  EXPECT_DOUBLE_EQ(avg.push(-1.0), -1.0);
}

TEST(MovingAverage, NoDriftOverLongRuns) {
  MovingAverage avg(50);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> noise(100.0, 30.0);
  std::vector<double> history;
  for (int k = 0; k < 200000; ++k) {
    history.push_back(noise(rng));
    static_cast<void>(avg.push(history.back()));
  }
  long double exact = 0.0L;
  for (std::size_t i = history.size() - 50; i < history.size(); ++i) exact += history[i];
  EXPECT_NEAR(avg.mean(), static_cast<double>(exact / 50.0L), 1e-11);
}

TEST(MovingAverage, RejectsEmptyWindow) { EXPECT_THROW(MovingAverage(0), std::invalid_argument); }

TEST(ForceLoopController, ProportionalByHand) {
  ForceLoopController loop(settings(5.0, 0.0));
  // Sensor steady at 1.5 N, desired 2 N: 2 + 5 (2 - 1.5) = 4.5 N.
  for (int k = 0; k < 60; ++k) {
    const ForceLoopCommand c = loop.step(2.0, 1.5);
    EXPECT_NEAR(c.force_N, 4.5, 1e-12);
    EXPECT_NEAR(c.average_force_N, 1.5, 1e-15);
    EXPECT_EQ(c.desired_force_N, 2.0);
  }
}

TEST(ForceLoopController, ProportionalSeesTheAveragedSensor) {
  ForceLoopController loop(settings(5.0, 0.0));
  for (int k = 0; k < 50; ++k) static_cast<void>(loop.step(1.0, 1.0));  // in balance: 1 N
  // The sensor steps to 2 N; after j samples F_avg = 1 + j / 50.
  for (int j = 1; j <= 60; ++j) {
    const double avg = 1.0 + std::min(j, 50) / 50.0;
    EXPECT_NEAR(loop.step(1.0, 2.0).force_N, 1.0 + 5.0 * (1.0 - avg), 1e-12) << j;
  }
}

TEST(ForceLoopController, ProportionalIntegralByHand) {
  ForceLoopController loop(settings(5.0, 10.0));
  // Constant error 0.5 N: I(k) = 0.5 T k, F_in = 2 + 2.5 + 10 * 0.0005 k.
  for (int k = 1; k <= 100; ++k) {
    const ForceLoopCommand c = loop.step(2.0, 1.5);
    EXPECT_NEAR(c.integral_Ns, 0.0005 * k, 1e-15);
    EXPECT_NEAR(c.force_N, 4.5 + 0.005 * k, 1e-12) << k;
  }
}

TEST(ForceLoopController, Saturates) {
  ForceLoopSettings s = settings(100.0, 0.0);
  s.limits.max_force_N = 5.0;
  ForceLoopController loop(s);
  ForceLoopCommand c = loop.step(2.0, 1.5);  // 2 + 100 * 0.5 = 52 N requested
  EXPECT_EQ(c.force_N, 5.0);
  EXPECT_TRUE(c.saturated);
  loop.reset();
  c = loop.step(-2.0, -1.5);
  EXPECT_EQ(c.force_N, -5.0);
  EXPECT_TRUE(c.saturated);
  loop.reset();
  c = loop.step(1.0, 1.0);
  EXPECT_EQ(c.force_N, 1.0);
  EXPECT_FALSE(c.saturated);
}

TEST(ForceLoopController, IntegralDoesNotWindUpAgainstTheLimit) {
  ForceLoopSettings s = settings(5.0, 100.0);
  s.limits.max_force_N = 5.02;
  ForceLoopController loop(s);
  // Constant error 0.5 N: unlimited F_in(k) = 4.5 + 100 * 0.0005 k passes 5.02 N at k = 11;
  // from there on the integral keeps its k = 10 value 0.005.
  for (int k = 1; k <= 200; ++k) {
    const ForceLoopCommand c = loop.step(2.0, 1.5);
    const double integral = 0.0005 * std::min(k, 10);
    EXPECT_NEAR(c.integral_Ns, integral, 1e-15) << k;
    EXPECT_NEAR(c.force_N, 4.5 + 100.0 * integral, 1e-12) << k;
    EXPECT_LE(c.force_N, 5.02);
  }
  // The error reverses (desired 1 N, average 1.5 N): the integral unwinds from 0.005 at once.
  const ForceLoopCommand back = loop.step(1.0, 1.5);
  EXPECT_NEAR(back.integral_Ns, 0.005 - 0.0005, 1e-15);
  EXPECT_NEAR(back.force_N, 1.0 + 5.0 * (-0.5) + 100.0 * 0.0045, 1e-12);
}

TEST(ForceLoopController, RateLimit) {
  ForceLoopSettings s = settings(0.0, 0.0);
  s.limits.max_rate_N_per_s = 500.0;  // 0.5 N per sample
  ForceLoopController loop(s);
  for (int k = 1; k <= 6; ++k) {
    const ForceLoopCommand c = loop.step(2.0, 0.0);
    EXPECT_NEAR(c.force_N, std::min(0.5 * k, 2.0), 1e-12);
    EXPECT_EQ(c.rate_limited, k < 4);
  }
}

TEST(ForceLoopController, NonFiniteInputLatchesZeroUntilReset) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (const bool bad_desired : {true, false}) {
    for (const double bad : {nan, inf, -inf}) {
      ForceLoopController loop(settings(5.0, 1.0));
      EXPECT_NE(loop.step(2.0, 1.0).force_N, 0.0);
      const ForceLoopCommand c = bad_desired ? loop.step(bad, 1.0) : loop.step(2.0, bad);
      EXPECT_EQ(c.force_N, 0.0);
      EXPECT_TRUE(c.input_fault);
      EXPECT_TRUE(loop.faulted());
      EXPECT_EQ(loop.step(2.0, 1.0).force_N, 0.0);
      loop.reset();
      const ForceLoopCommand ok = loop.step(2.0, 1.0);
      EXPECT_FALSE(ok.input_fault);
      EXPECT_NEAR(ok.force_N, 2.0 + 5.0 * 1.0 + 1.0 * 0.001, 1e-12);
    }
  }
}

TEST(ForceLoopController, SettingsFromParamsAndValidation) {
  ForceLoopParams fp;
  fp.sample_rate_hz = 1000.0;
  fp.kp = 5.0;
  fp.ki = 2.0;
  fp.sensor_average_samples = 50;
  const ForceLoopSettings s = from_force_loop_params(fp);
  EXPECT_EQ(s.period_s, 1e-3);
  EXPECT_EQ(s.kp, 5.0);
  EXPECT_EQ(s.ki, 2.0);
  EXPECT_EQ(s.average_samples, 50);
  EXPECT_NO_THROW(ForceLoopController{s});
  ForceLoopSettings bad = s;
  bad.average_samples = 0;
  EXPECT_THROW(ForceLoopController{bad}, std::invalid_argument);
  bad = s;
  bad.period_s = 0.0;
  EXPECT_THROW(ForceLoopController{bad}, std::invalid_argument);
  bad = s;
  bad.limits.max_force_N = -1.0;
  EXPECT_THROW(ForceLoopController{bad}, std::invalid_argument);
}

TEST(VirtualSpringDamper, ActsOnlyInside) {
  const VirtualSpringDamper wall{125.0, 0.1, 0.03};
  EXPECT_EQ(wall.force_N(0.02, 0.5), 0.0);
  EXPECT_EQ(wall.force_N(0.03, 0.5), 0.0);
  EXPECT_NEAR(wall.force_N(0.04, 0.5), 125.0 * 0.01 + 0.1 * 0.5, 1e-12);
}

TEST(VirtualEnvironmentRenderer, RendersTissueThroughTheLoop) {
  // The paper's tissue, 125 N/m, surface 3 cm away; the device held 1 cm inside.
  VirtualEnvironmentRenderer device(settings(5.0, 0.0), 0.0, {125.0, 0.1, 0.03});
  for (int k = 0; k < 60; ++k) {
    const ForceLoopCommand c = device.step(0.04, 1.0);  // sensor reads 1 N
    EXPECT_NEAR(c.desired_force_N, 1.25, 1e-12);
    EXPECT_NEAR(c.force_N, 1.25 + 5.0 * 0.25, 1e-12);
  }
  const ForceLoopCommand outside = device.step(0.04, std::numeric_limits<double>::quiet_NaN());
  EXPECT_TRUE(outside.input_fault);
  EXPECT_EQ(outside.force_N, 0.0);
  device.reset();
  const ForceLoopCommand nan_position = device.step(std::numeric_limits<double>::quiet_NaN(), 0.0);
  EXPECT_TRUE(nan_position.input_fault);
  EXPECT_EQ(device.step(0.04, 1.0).force_N, 0.0);  // latched
}

}  // namespace
}  // namespace teleop::control

namespace teleop::control {
namespace {

TEST(ForceLoopInnerLoop, MasterCommandTrackedDespiteADisturbance) {
  // The force loop as the master's inner loop: the master law's command is F_des, the handle's
  // load cell senses what reaches the hand through a first-order transmission lag,
  // F_s(k+1) = F_s(k) + g (F_in(k) - d - F_s(k)), with a parasitic force d (friction) the
  // actuator must overcome. Steady state by hand: F_s = F_in - d with
  // F_in = F_des + K_p (F_des - F_s), so F_s = F_des - d / (1 + K_p); open loop, F_des - d.
  // The loop's pole is 1 - g (1 + K_p) = 0.4 for g = 0.1: it converges.
  LawParams law;
  law.period_s = 1e-3;
  law.gains.kpm = 600.0;
  law.clutch_fade_s = 0.0;
  MasterLaw master(law);
  master.reset(0.01);
  const PeerState slave{0.0, 0.0, 0.0, false, true};
  ForceLoopSettings settings;
  settings.period_s = 1e-3;
  settings.kp = 5.0;
  settings.average_samples = 1;
  ForceLoopController inner(settings);
  const double d = 0.3;
  double sensed = 0.0;
  double desired = 0.0;
  for (int k = 0; k < 2000; ++k) {
    desired = master.step(0.01, slave).force_N;  // K_pm (x_m - x_s) = 600 * 0.01 = 6 N
    const ForceLoopCommand c = inner.step(desired, sensed);
    sensed += 0.1 * (c.force_N - d - sensed);
  }
  EXPECT_NEAR(desired, 6.0, 1e-12);
  EXPECT_NEAR(sensed, 6.0 - d / 6.0, 1e-9);
}

}  // namespace
}  // namespace teleop::control
