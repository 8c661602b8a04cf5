// RT safety of the n-axis law (docs/architecture.md §4.3): MasterLawAxes and SlaveLawAxes steps
// at n = 1, 3 and 6 make no allocation, with every path run (planes, filter, force channel,
// limits, workspace box, clutch, link loss, a fault and reset, retune). Interposes the C
// allocator as test_control_rt.cpp does (tests/support/alloc_counter.hpp), so it is its own
// binary, left out of the sanitizer build.
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <limits>
#include <vector>

#include "common/control/law_axes.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/control/law_axes_test_util.hpp"

namespace teleop::control {
namespace {

constexpr int kSteps = 5000;
constexpr double kT = 1e-3;

// Every feature on at n axes: coupled gain matrices, two planes per side, limits per axis.
[[nodiscard]] LawAxesParams busy_params(int n) {
  using test::coupled_gain;
  LawAxesParams p;
  p.axes = n;
  p.period_s = kT;
  p.gains = {coupled_gain(n, 400.0, 20.0), coupled_gain(n, 500.0, 25.0), coupled_gain(n, 4.0, 0.2),
             coupled_gain(n, 5.0, 0.3),    coupled_gain(n, 1.0, 0.0),    coupled_gain(n, 1.5, 0.1),
             coupled_gain(n, 0.5, 0.0)};
  p.scaling = {.position = 1.5, .force = 0.8};
  p.master_planes.add({test::tilted_normal(n), 0.01, 800.0});
  p.master_planes.add({test::first_axis(n), 0.012, 600.0});
  p.slave_planes.add({test::tilted_normal(n), 0.015, 1000.0});
  p.slave_planes.add({-test::first_axis(n), 0.012, 900.0});
  p.velocity_cutoff_hz = 200.0;
  p.master_actuator = test::actuator_limits(n, 4.0, 2000.0);
  p.slave_actuator = test::actuator_limits(n, 6.0, 3000.0);
  p.slave_limits = test::slave_box(n, -0.03, 0.03, 0.5, 5.0);
  p.clutch_fade_s = 0.02;
  return p;
}

TEST(LawAxesRealTime, CounterSeesAllocations) {
  EXPECT_EQ(teleop::test::count_malloc_and_free(), 2);
}

void run_without_allocation(int n) {
  const LawAxesParams params = busy_params(n);
  MasterLawAxes master(params);
  SlaveLawAxes slave(params);
  LawGainsAxes retuned = params.gains;
  retuned.kpm *= 0.5;
  std::vector<AxisVector> xm(kSteps);
  std::vector<AxisVector> xs(kSteps);
  for (std::size_t k = 0; k < xm.size(); ++k) {
    const double t = static_cast<double>(k) * kT;
    xm[k] = AxisVector::Zero(n);
    xs[k] = AxisVector::Zero(n);
    for (int i = 0; i < n; ++i) {
      xm[k](i) = 0.02 * std::sin(2.0 * 3.14159 * (1.3 + 0.1 * i) * t);
      xs[k](i) = 0.028 * std::sin(2.0 * 3.14159 * 1.3 * (t - 0.01)) + 0.01 * std::sin(50.0 * t);
    }
  }
  const AxisVector nan = AxisVector::Constant(n, std::numeric_limits<double>::quiet_NaN());
  PeerStateAxes to_slave;
  PeerStateAxes to_master;
  double sink = 0.0;
  int flags = 0;

  teleop::test::start_counting(false);
  for (int k = 0; k < kSteps; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    if (k % 1000 == 300) master.set_clutch(true);
    if (k % 1000 == 700) master.set_clutch(false);
    if (k == 2500) {
      master.retune(retuned, params.master_planes);
      slave.retune(retuned, params.slave_planes);
    }
    const AxisVector& xm_k = k == 4500 ? nan : xm[i];  // fault path
    if (k == 4600) {
      master.reset();
      slave.reset(xs[i]);
    }
    PeerStateAxes link_to_master = to_master;
    if (k % 2000 > 1900) link_to_master.valid = false;  // link loss path
    const CommandAxes cm = master.step(xm_k, link_to_master);
    const CommandAxes cs = slave.step(xs[i], 0.1 * xs[i], to_slave);
    to_slave = master.peer_state();
    to_master = slave.peer_state();
    sink += cm.force_N.sum() + cs.force_N.sum();
    flags += cm.flags.saturated + cm.flags.rate_limited + cs.flags.limit_violation +
             cs.flags.reference_limited + cm.flags.input_fault + (cm.penetration_m > 0.0);
  }
  const long calls = teleop::test::stop_counting();

  EXPECT_EQ(calls, 0) << "allocator calls in " << kSteps << " master + slave steps at n = " << n;
  EXPECT_TRUE(std::isfinite(sink));
  EXPECT_GT(flags, 0);
}

TEST(LawAxesRealTime, OneAxisStepsDoNotAllocate) { run_without_allocation(1); }
TEST(LawAxesRealTime, ThreeAxisStepsDoNotAllocate) { run_without_allocation(3); }
TEST(LawAxesRealTime, SixAxisStepsDoNotAllocate) { run_without_allocation(6); }

}  // namespace
}  // namespace teleop::control
