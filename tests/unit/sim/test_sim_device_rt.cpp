// read/write/advance of the simulated device never allocate (docs/architecture.md §4.3): malloc,
// calloc, realloc and free are interposed (an operator-new counter would miss C allocations) and
// counted over 10 000 cycles. Sanitizer builds replace the allocator themselves, so they leave this
// binary out.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>

#include "common/device/sim_device.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::device {
namespace {

TEST(SimDeviceRt, ReadWriteAdvanceNeverAllocate) {
  // The busiest configuration: a malicious user (propagators rebuilt at each new impedance),
  // friction, a noisy load cell, a trace profile with first-order hold.
  sim::HumanParams h = sim::HumanParams::malicious_pushing(default_human_band(), 5.0, 0.5);
  h.profile = sim::ForceProfile::trace({0.0, 2.0, 5.0, 10.0}, {0.0, 5.0, 3.0, 6.0});
  h.sampling = sim::ProfileSampling::kFirstOrderHold;
  SimDeviceConfig c = SimDeviceConfig::paddle_master(h);
  c.plant.coulomb_friction_N = 0.02;
  c.load_cell.noise_std_N = 0.02;
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  // A slave on tissue too, with sub-steps.
  SimDeviceConfig sc = SimDeviceConfig::paddle_slave(sim::Environment::tissue(3000.0, 2.0, 0.02));
  sc.plant.method = sim::SteppingMethod::kSubSteps;
  sc.plant.coulomb_friction_N = 0.02;
  SimDevice slave(sc);
  ASSERT_TRUE(slave.configure().ok());
  ASSERT_TRUE(slave.activate().ok());

  teleop::test::start_counting(false);
  Sample s;
  Sample ss;
  bool ok = true;
  for (int k = 0; k < 10000; ++k) {
    ok = ok && dev.read(s).ok() && slave.read(ss).ok();
    ok = ok && dev.write({-200.0 * (s.position_m - ss.position_m)}).ok();
    ok = ok && slave.write({200.0 * (s.position_m - ss.position_m)}).ok();
    ok = ok && dev.advance(c.period).ok() && slave.advance(sc.period).ok();
  }
  const long calls = teleop::test::stop_counting();
  EXPECT_TRUE(ok);
  EXPECT_EQ(calls, 0);
  EXPECT_GT(*dev.truth().malicious_index, 10U);  // it did switch impedances on the way
}

}  // namespace
}  // namespace teleop::device
