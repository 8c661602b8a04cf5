// PassivityObserverAxes::add makes no allocation (docs/architecture.md §4.3), as the RT marking
// says: this binary interposes the C allocator (tests/support/alloc_counter.hpp, as
// test_control_rt does). AddressSanitizer owns malloc, so the sanitizer build leaves it out.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdlib>

#include "supervisor/core/monitors_axes.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::supervisor {
namespace {

TEST(MonitorsAxesRealTime, CounterSeesAllocations) {
  void* (*volatile do_malloc)(std::size_t) = &std::malloc;
  void (*volatile do_free)(void*) = &std::free;
  test::start_counting(false);
  do_free(do_malloc(64));
  EXPECT_GE(test::stop_counting(), 1);
}

TEST(MonitorsAxesRealTime, PassivityObserverAddAllocatesNothing) {
  // Six axes, a 0.2 s window filled and wrapped many times over.
  PassivityObserverAxes obs(6, 1e-3, 0.2);
  std::array<double, 6> f{};
  std::array<double, 6> v{};
  double sink = 0.0;
  test::start_counting(false);
  for (int k = 0; k < 10000; ++k) {
    for (std::size_t i = 0; i < 6; ++i) {
      f[i] = std::sin(0.01 * k + static_cast<double>(i));
      v[i] = std::cos(0.013 * k - static_cast<double>(i));
    }
    sink += obs.add(f, v) ? obs.recent_power_W() : 1.0;
  }
  obs.reset();
  const long calls = test::stop_counting();
  EXPECT_EQ(calls, 0) << "allocator calls in 10000 samples";
  EXPECT_TRUE(std::isfinite(sink));
}

}  // namespace
}  // namespace teleop::supervisor
