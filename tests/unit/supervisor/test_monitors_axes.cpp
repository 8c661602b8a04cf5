// The supervisor's n-axis monitors (issue 18): oscillation per axis and Ryu-Hannaford's
// passivity observer on the vector port. Expected values are closed forms derived in the
// comments (a sampled cosine's amplitude, the energy of a spring-mass port and of a negative
// damper), the one-axis PassivityObserver and OscillationMonitor (n = 1, bit for bit), and
// physics (the power f . v does not depend on the coordinates).
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/QR>
#include <array>
#include <cmath>
#include <numbers>
#include <random>
#include <stdexcept>
#include <vector>

#include "common/scene/oscillation.hpp"
#include "supervisor/core/monitors.hpp"
#include "supervisor/core/monitors_axes.hpp"

namespace teleop::supervisor {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kPeriod = 1e-3;  // 1 kHz telemetry
constexpr double kWindow = 0.5;   // the supervisor's window: 500 samples
constexpr int kPerCycle = 100;    // a 10 Hz swing: 100 samples a cycle

// x_k = A cos(w (k + 1/2) T), w T = 2 pi / 100. Over a window of whole cycles starting at a
// multiple of 100 samples the mean is 0 and the least-squares slope is 0 too: sum_i i cos(w (i +
// 1/2)) = N sin(phi - w/2) / (2 sin(w/2)) with phi = w/2. So the detector's residual is the
// signal itself, whose extreme samples (k + 1/2 = 0.5, 49.5, ...) are +-A cos(pi/100): the
// amplitude (half the peak-to-peak) is A cos(pi / 100).
double swing(double amplitude_m, int k) {
  return amplitude_m * std::cos(2.0 * kPi * (k + 0.5) / kPerCycle);
}

TEST(OscillationMonitorAxes, TiltedSineHasTheClosedFormAmplitudeOnEachAxis) {
  // A swing along the unit direction (2, 3, 6, 0) / 7: axis i swings with amplitude A |n_i|.
  const std::array<double, 4> direction{2.0 / 7.0, 3.0 / 7.0, 6.0 / 7.0, 0.0};
  const double a_m = 1e-3;
  OscillationMonitorAxes m(4, kPeriod, kWindow, 1e-5);
  // 1500 samples: the last two windows are samples 500-999 and 1000-1499, whole cycles each.
  for (int k = 0; k < 1500; ++k) {
    std::array<double, 4> x{};
    for (std::size_t i = 0; i < 4; ++i) x[i] = direction[i] * swing(a_m, k);
    m.add(x);
  }
  ASSERT_TRUE(m.full());
  const OscillationAxes o = m.check();
  ASSERT_EQ(o.per_axis.size(), 4U);
  for (std::size_t i = 0; i < 3; ++i) {
    const double want = a_m * direction[i] * std::cos(kPi / kPerCycle);
    EXPECT_TRUE(o.per_axis[i].detected) << "axis " << i;
    EXPECT_NEAR(o.per_axis[i].amplitude_m, want, 1e-9 * want) << "axis " << i;
    EXPECT_NEAR(o.per_axis[i].previous_amplitude_m, want, 1e-9 * want) << "axis " << i;
    EXPECT_NEAR(o.per_axis[i].frequency_hz, 10.0, 1.0) << "axis " << i;
  }
  EXPECT_FALSE(o.per_axis[3].detected);
  EXPECT_EQ(o.per_axis[3].amplitude_m, 0.0);
  // The worst axis is the one most aligned with the swing.
  EXPECT_TRUE(o.detected());
  EXPECT_EQ(o.worst_axis, 2);
  EXPECT_EQ(o.worst.amplitude_m, o.per_axis[2].amplitude_m);
}

TEST(OscillationMonitorAxes, CircleOfConstantNormIsDetectedOnBothAxes) {
  // x = r cos, y = r sin: |x| = r at every sample, so the norm about its mean is flat.
  const double r_m = 5e-4;
  OscillationMonitorAxes m(2, kPeriod, kWindow, 1e-5);
  std::vector<double> norm;
  for (int k = 0; k < 1500; ++k) {
    const double th = 2.0 * kPi * (k + 0.5) / kPerCycle;
    const std::array<double, 2> x{r_m * std::cos(th), r_m * std::sin(th)};
    m.add(x);
    norm.push_back(std::hypot(x[0], x[1]));
  }
  const OscillationAxes o = m.check();
  EXPECT_TRUE(o.per_axis[0].detected);
  EXPECT_TRUE(o.per_axis[1].detected);
  EXPECT_NEAR(o.per_axis[0].amplitude_m, r_m * std::cos(kPi / kPerCycle), 1e-9 * r_m);
  EXPECT_TRUE(o.detected());
  // The same detector on the norm sees nothing (what the per-axis monitor exists to avoid).
  const scene::Oscillation on_norm = scene::detect_oscillation(norm, kPeriod, kWindow, 1e-5);
  EXPECT_FALSE(on_norm.detected);
  EXPECT_LT(on_norm.amplitude_m, 1e-12);
}

TEST(OscillationMonitorAxes, DetectedAxisIsWorseThanALargerUndetectedOne) {
  // Axis 0: a slow 1 Hz swing of 5 mm (half a cycle per window, no buzz); axis 1: a 10 Hz buzz
  // of 0.1 mm. The buzz is reported, though its amplitude is 50 times smaller.
  OscillationMonitorAxes m(2, kPeriod, kWindow, 1e-5);
  for (int k = 0; k < 1000; ++k) {
    const std::array<double, 2> x{5e-3 * std::sin(2.0 * kPi * k * kPeriod), swing(1e-4, k)};
    m.add(x);
  }
  const OscillationAxes o = m.check();
  EXPECT_FALSE(o.per_axis[0].detected);
  EXPECT_GT(o.per_axis[0].amplitude_m, 10.0 * o.per_axis[1].amplitude_m);
  EXPECT_TRUE(o.per_axis[1].detected);
  EXPECT_EQ(o.worst_axis, 1);
  // Nothing detected anywhere: the largest amplitude is the worst.
  OscillationMonitorAxes quiet(2, kPeriod, kWindow, 1e-5);
  for (int k = 0; k < 1000; ++k) {
    const std::array<double, 2> x{1e-3 * k * kPeriod, 2e-3 * std::sin(2.0 * kPi * k * kPeriod)};
    quiet.add(x);
  }
  const OscillationAxes q = quiet.check();
  EXPECT_FALSE(q.detected());
  EXPECT_EQ(q.worst_axis, 1);
}

TEST(OscillationMonitorAxes, OneAxisIsTheOneAxisMonitor) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 2e-5);
  OscillationMonitor one(kPeriod, kWindow, 1e-5);
  OscillationMonitorAxes axes(1, kPeriod, kWindow, 1e-5);
  for (int k = 0; k < 1200; ++k) {
    const double x = swing(3e-5, k) + noise(rng);
    one.add(x);
    axes.add(std::array<double, 1>{x});
    if (k % 97 == 0) {
      const scene::Oscillation a = one.check();
      const scene::Oscillation b = axes.check().worst;
      EXPECT_EQ(a.detected, b.detected);
      EXPECT_EQ(a.amplitude_m, b.amplitude_m);
      EXPECT_EQ(a.frequency_hz, b.frequency_hz);
      EXPECT_EQ(a.previous_amplitude_m, b.previous_amplitude_m);
    }
  }
}

TEST(OscillationMonitorAxes, RefusesBadSizes) {
  EXPECT_THROW(OscillationMonitorAxes(0, kPeriod, kWindow, 1e-5), std::invalid_argument);
  EXPECT_THROW(OscillationMonitorAxes(7, kPeriod, kWindow, 1e-5), std::invalid_argument);
  EXPECT_THROW(OscillationMonitorAxes(2, 0.0, kWindow, 1e-5), std::invalid_argument);
  // A window of 1e308 s, or 1e300 periods: refused before any size is computed from it.
  EXPECT_THROW(OscillationMonitorAxes(2, kPeriod, 1e308, 1e-5), std::invalid_argument);
  EXPECT_THROW(OscillationMonitorAxes(2, 1e-300, 1.0, 1e-5), std::invalid_argument);
  EXPECT_THROW(PassivityObserverAxes(2, 1e-300, 1.0), std::invalid_argument);
  OscillationMonitorAxes m(3, kPeriod, kWindow, 1e-5);
  EXPECT_THROW(m.add(std::array<double, 2>{0.0, 0.0}), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Passivity

TEST(PassivityObserverAxes, OneAxisGivesPassivityObserversNumbersBitForBit) {
  std::mt19937 rng(2024);
  std::normal_distribution<double> force(0.0, 3.0);
  std::normal_distribution<double> velocity(0.0, 0.05);
  PassivityObserver one(kPeriod, 0.05);
  PassivityObserverAxes axes(1, kPeriod, 0.05);
  for (int k = 0; k < 3000; ++k) {
    if (k == 2000) {
      one.reset();
      axes.reset();
    }
    const double f = force(rng);
    const double v = velocity(rng);
    one.add(f, v);
    ASSERT_TRUE(axes.add(std::array<double, 1>{f}, std::array<double, 1>{v}));
    ASSERT_EQ(one.energy_J(), axes.energy_J()) << "sample " << k;
    ASSERT_EQ(one.min_energy_J(), axes.min_energy_J()) << "sample " << k;
    ASSERT_EQ(one.recent_power_W(), axes.recent_power_W()) << "sample " << k;
  }
}

TEST(PassivityObserverAxes, LosslessSpringMassPortReturnsToZeroEveryHalfCycle) {
  // A port that is a mass m with a spring k_i per axis: f = m x'' + K x. Driven along
  // x_i = X_i sin(w t): v_i = X_i w cos(w t), f_i = (k_i - m w^2) X_i sin(w t), so
  // E(t) = int f . v dt = sum_i (k_i - m w^2) X_i^2 sin^2(w t) / 2 — the energy stored, back to
  // 0 every half cycle. The observer's sum T sum_k f(kT) . v(kT) has sin(2 w k T) summed over
  // whole cycles of 2 w: exactly 0 at every half cycle.
  const double m_kg = 0.05;
  const std::array<double, 3> k_N_per_m{400.0, 900.0, 250.0};
  const std::array<double, 3> x_m{2e-3, -1e-3, 3e-3};
  const double w = 2.0 * kPi * 10.0;
  PassivityObserverAxes obs(3, kPeriod);
  double peak_power_W = 0.0;
  for (std::size_t i = 0; i < 3; ++i) {
    peak_power_W += std::abs(k_N_per_m[i] - m_kg * w * w) * x_m[i] * x_m[i] * w / 2.0;
  }
  for (int k = 0; k < 3 * kPerCycle; ++k) {
    const double t = k * kPeriod;
    std::array<double, 3> f{};
    std::array<double, 3> v{};
    double want_J = 0.0;  // the closed form at the end of this sample
    for (std::size_t i = 0; i < 3; ++i) {
      f[i] = (k_N_per_m[i] - m_kg * w * w) * x_m[i] * std::sin(w * t);
      v[i] = x_m[i] * w * std::cos(w * t);
      want_J += (k_N_per_m[i] - m_kg * w * w) * x_m[i] * x_m[i] *
                std::pow(std::sin(w * (t + kPeriod)), 2) / 2.0;
    }
    obs.add(f, v);
    // The left Riemann sum is within T * max |f . v| of the integral.
    EXPECT_NEAR(obs.energy_J(), want_J, 2.0 * kPeriod * peak_power_W) << "sample " << k;
    if ((k + 1) % (kPerCycle / 2) == 0) {
      EXPECT_NEAR(obs.energy_J(), 0.0, 1e-15) << "after " << (k + 1) << " samples";
    }
  }
  EXPECT_GT(obs.min_energy_J(), -1e-15);  // never active
}

TEST(PassivityObserverAxes, NegativeDamperIsActiveByTheClosedForm) {
  // f = -b v (the port pushes along its own motion) with v_i = V_i sin(w k T): the observer's
  // E after K samples is -b T sum_k |V|^2 sin^2(w k T) = -b T |V|^2 K / 2 for K whole cycles
  // (sum of cos(2 w k T) over whole cycles is 0), and the power over the last 1 s window is
  // -b |V|^2 / 2.
  const double b = 2.0;
  const std::array<double, 3> v_m_per_s{0.1, 0.05, -0.02};
  const double v2 = 0.1 * 0.1 + 0.05 * 0.05 + 0.02 * 0.02;
  const double w = 2.0 * kPi * 10.0;
  PassivityObserverAxes active(3, kPeriod, 1.0);
  PassivityObserverAxes passive(3, kPeriod, 1.0);  // f = +b v
  const int samples = 20 * kPerCycle;              // 2 s
  for (int k = 0; k < samples; ++k) {
    std::array<double, 3> v{};
    std::array<double, 3> f{};
    for (std::size_t i = 0; i < 3; ++i) {
      v[i] = v_m_per_s[i] * std::sin(w * k * kPeriod);
      f[i] = -b * v[i];
    }
    active.add(f, v);
    for (double& x : f) x = -x;
    passive.add(f, v);
  }
  const double want_J = -b * kPeriod * v2 * samples / 2.0;  // -25.8 mJ
  EXPECT_NEAR(active.energy_J(), want_J, 1e-12 * std::abs(want_J));
  EXPECT_EQ(active.min_energy_J(), active.energy_J());  // f . v <= 0 at every sample
  EXPECT_NEAR(active.recent_power_W(), -b * v2 / 2.0, 1e-9);
  // The supervisor's alarm: E below -5 mJ while still giving out more than 2 mW.
  EXPECT_TRUE(active.energy_J() < -5e-3 && active.recent_power_W() < -2e-3);
  EXPECT_NEAR(passive.energy_J(), -want_J, 1e-12 * std::abs(want_J));
  EXPECT_EQ(passive.min_energy_J(), 0.0);
  EXPECT_NEAR(passive.recent_power_W(), b * v2 / 2.0, 1e-9);
}

TEST(PassivityObserverAxes, EnergyDoesNotDependOnTheCoordinates) {
  // The power f . v is a scalar: rotating both f and v by the same orthogonal Q leaves it.
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  Eigen::Matrix3d r;
  for (int i = 0; i < 9; ++i) r(i / 3, i % 3) = g(rng);
  const Eigen::Matrix3d q = Eigen::HouseholderQR<Eigen::Matrix3d>(r).householderQ();
  ASSERT_NEAR((q.transpose() * q - Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-14);
  PassivityObserverAxes a(3, kPeriod, 0.2);
  PassivityObserverAxes b(3, kPeriod, 0.2);
  double scale_J = 0.0;
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector3d f(g(rng), g(rng), g(rng));
    const Eigen::Vector3d v = 0.1 * Eigen::Vector3d(g(rng), g(rng), g(rng)) + 0.02 * f;
    const Eigen::Vector3d qf = q * f;
    const Eigen::Vector3d qv = q * v;
    a.add(std::span<const double>(f.data(), 3), std::span<const double>(v.data(), 3));
    b.add(std::span<const double>(qf.data(), 3), std::span<const double>(qv.data(), 3));
    scale_J += kPeriod * f.norm() * v.norm();
  }
  EXPECT_GT(std::abs(a.energy_J()), 1e-3 * scale_J);  // not a trivially zero energy
  EXPECT_NEAR(b.energy_J(), a.energy_J(), 1e-13 * scale_J);
  EXPECT_NEAR(b.min_energy_J(), a.min_energy_J(), 1e-13 * scale_J);
  EXPECT_NEAR(b.recent_power_W(), a.recent_power_W(), 1e-10 * scale_J);
}

TEST(PassivityObserverAxes, RefusesBadSizesAndPeriods) {
  EXPECT_THROW(PassivityObserverAxes(0, kPeriod), std::invalid_argument);
  EXPECT_THROW(PassivityObserverAxes(7, kPeriod), std::invalid_argument);
  EXPECT_THROW(PassivityObserverAxes(2, std::nan("")), std::invalid_argument);
  EXPECT_THROW(PassivityObserverAxes(2, kPeriod, 0.0), std::invalid_argument);
  PassivityObserverAxes o(2, kPeriod);
  EXPECT_FALSE(o.add(std::array<double, 3>{1.0, 1.0, 1.0}, std::array<double, 2>{1.0, 1.0}));
  EXPECT_FALSE(o.add(std::array<double, 2>{1.0, 1.0}, std::array<double, 1>{1.0}));
  EXPECT_EQ(o.energy_J(), 0.0);
  EXPECT_EQ(o.recent_power_W(), 0.0);
}

}  // namespace
}  // namespace teleop::supervisor
