// RT safety (docs/architecture.md §4.3): the control steps make no allocation. This binary
// interposes the C allocator itself (an operator new counter would miss C allocations, and
// libstdc++'s operator new ends in malloc anyway): malloc & co forward to glibc's __libc_* entry
// points and count calls while a window is open (tests/support/alloc_counter.hpp). AddressSanitizer
// replaces malloc itself, so the sanitizer build leaves this binary out.
#include <gtest/gtest.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <limits>
#include <new>
#include <vector>

#include "common/control/force_loop_controller.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/control/control_test_util.hpp"

namespace teleop::control {
namespace {

constexpr int kSteps = 10000;
constexpr double kT = 1e-3;

TEST(RealTime, CounterSeesAllocations) {
  EXPECT_EQ(teleop::test::count_malloc_and_free(), 2);

  // libstdc++'s operator new ends in malloc, so C++ allocations are counted too. (Called
  // through pointers: the compiler may elide a new-expression paired with its delete.)
  void* (*volatile do_new)(std::size_t) = static_cast<void* (*)(std::size_t)>(&::operator new);
  void (*volatile do_delete)(void*) noexcept =
      static_cast<void (*)(void*) noexcept>(&::operator delete);
  teleop::test::start_counting(false);
  do_delete(do_new(100));
  EXPECT_EQ(teleop::test::stop_counting(), 2);
}

TEST(RealTime, MasterAndSlaveStepsDoNotAllocate) {
  const LawParams params = test::busy_params();
  MasterLaw master(params);
  SlaveLaw slave(params);
  std::vector<double> xm(kSteps);
  std::vector<double> xs(kSteps);
  for (std::size_t k = 0; k < xm.size(); ++k) {
    const double t = static_cast<double>(k) * kT;
    xm[k] = 0.02 * std::sin(2.0 * 3.14159 * 1.3 * t);
    xs[k] = 0.028 * std::sin(2.0 * 3.14159 * 1.3 * (t - 0.01)) + 0.01 * std::sin(50.0 * t);
  }
  PeerState to_slave;
  PeerState to_master;
  double sink = 0.0;
  int flags = 0;

  teleop::test::start_counting(false);
  for (int k = 0; k < kSteps; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    if (k % 1000 == 300) master.set_clutch(true);
    if (k % 1000 == 700) master.set_clutch(false);
    double xm_k = xm[i];
    if (k == 9500) xm_k = std::numeric_limits<double>::quiet_NaN();  // fault path
    if (k == 9600) {
      master.reset();
      slave.reset(xs[i]);
    }
    PeerState link_to_master = to_master;
    if (k % 2000 > 1900) link_to_master.valid = false;  // link loss path
    const Command cm = master.step(xm_k, link_to_master);
    const Command cs = slave.step(xs[i], 1.0 + 0.1 * xs[i], to_slave);
    to_slave = master.peer_state();
    to_master = slave.peer_state();
    sink += cm.force_N + cs.force_N;
    flags += cm.flags.saturated + cm.flags.rate_limited + cs.flags.limit_violation +
             cs.flags.reference_limited + cm.flags.input_fault;
  }
  const long calls = teleop::test::stop_counting();

  EXPECT_EQ(calls, 0) << "allocator calls in " << kSteps << " master + slave steps";
  EXPECT_TRUE(std::isfinite(sink));
  EXPECT_GT(flags, 0);  // the limit and fault paths did run
}

TEST(RealTime, ForceLoopStepsDoNotAllocate) {
  ForceLoopSettings s;
  s.period_s = kT;
  s.kp = 5.0;
  s.ki = 20.0;
  s.average_samples = 50;
  s.limits = {3.0, 500.0};
  ForceLoopController loop(s);
  VirtualEnvironmentRenderer device(s, 200.0, {125.0, 0.1, 0.03});
  std::vector<double> x(kSteps);
  for (std::size_t k = 0; k < x.size(); ++k) {
    x[k] = 0.035 + 0.01 * std::sin(static_cast<double>(k) * 0.005);
  }
  double sink = 0.0;

  teleop::test::start_counting(false);
  for (int k = 0; k < kSteps; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    const double sensed = 125.0 * (x[i] - 0.03) * 0.9;
    sink += loop.step(2.0 * std::sin(k * 0.01), sensed).force_N;
    sink += device.step(x[i], sensed).force_N;
    if (k == 5000) {
      sink += loop.step(std::numeric_limits<double>::infinity(), 0.0).force_N;
      loop.reset();
    }
  }
  const long calls = teleop::test::stop_counting();

  EXPECT_EQ(calls, 0) << "allocator calls in " << kSteps << " force-loop steps";
  EXPECT_TRUE(std::isfinite(sink));
}

}  // namespace
}  // namespace teleop::control
