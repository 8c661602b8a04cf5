// read() and write() of the n-axis USB host never allocate (docs/architecture.md §4.3), at n = 1,
// 3 (the five-bar on channels 0-1) and 6, against the emulator: the RT thread's allocator calls
// are counted around each read and write (tests/support/alloc_counter.hpp, as
// test_sim_device_axes_rt); the emulator's steps and the host's I/O thread are not counted.
// Sanitizer builds replace the allocator themselves and leave this binary out.
#include <gtest/gtest.h>

#include <cmath>

// The rig (Eigen, gtest) first: clang's mm_malloc.h must declare posix_memalign before the
// counter's interposer defines it.
#include "tests/unit/device/usb_axes_rig.hpp"
// clang-format off
#include "tests/support/alloc_counter.hpp"
// clang-format on

namespace teleop::device {
namespace {

using namespace test_axes;  // NOLINT(google-build-using-namespace): the rig's helpers

long count_allocations(int n, bool five_bar) {
  UsbDeviceAxesConfig c = five_bar_config();
  c.axes = n;
  if (five_bar) {
    c.actuators.resize(static_cast<std::size_t>(n), c.actuators.back());
  } else {
    c.kinematics = DeviceKinematics::kCartesian;
    c.actuators.clear();
  }
  AxesRig rig(emulator_config(static_cast<std::size_t>(n)), c);
  if (!rig.dev.configure().ok()) return -1;  // (bring_up() configures again)
  for (int i = 0; i < n; ++i) {
    rig.emu.set_external_force_N(static_cast<std::size_t>(i), 0.05 * (i % 2 == 0 ? 1.0 : -1.0));
  }
  SampleAxes s = rig.bring_up();
  CommandAxes command;
  long calls = 0;
  bool ok = true;
  for (int k = 0; k < 200; ++k) {
    teleop::test::start_counting(true);
    ok = rig.dev.read(s).ok() && ok;
    command.force_N = -20.0 * s.position_m;
    command.force_N(0) += 0.01 * std::sin(0.1 * k);
    ok = rig.dev.write(command).ok() && ok;
    calls += teleop::test::stop_counting();
    rig.take_command();
    rig.emu.step(milliseconds{1});
    s = rig.next_sample(s.sequence);
  }
  EXPECT_TRUE(ok) << "n = " << n;
  EXPECT_GT(s.position_m.cwiseAbs().maxCoeff(), 1e-4) << "n = " << n;  // it moved
  return calls;
}

TEST(UsbDeviceAxesRt, ReadAndWriteNeverAllocate) {
  EXPECT_GT(teleop::test::count_malloc_and_free(), 0);  // the counter counts
  for (const int n : {1, 6}) EXPECT_EQ(count_allocations(n, false), 0) << "n = " << n;
  for (const int n : {3, 6}) EXPECT_EQ(count_allocations(n, true), 0) << "five-bar, n = " << n;
}

}  // namespace
}  // namespace teleop::device
