// NodeCoreAxes::step allocates nothing at n = 3 and n = 6: link up, arm, aligning with the
// centring spring, engaged with the operator's push, clutch and unclutch, a guarded parameter
// change applied and ramped, a late wake-up into
// safe and the safe ramp. The allocator is interposed (tests/support/alloc_counter.hpp) and
// this thread's calls counted over the steps only.
#include <gtest/gtest.h>

#include "common/device/sim_device_axes.hpp"
#include "common/node/node_core_axes.hpp"
#include "tests/support/alloc_counter.hpp"
#include "tests/unit/node/node_axes_test_util.hpp"

namespace teleop::node {
namespace {

using namespace std::chrono_literals;
using axes_test::device_config;
using axes_test::settings;
using transport::Role;

void run(int n) {
  device::SimDeviceAxes master_dev(device_config(n, true));
  device::SimDeviceAxes slave_dev(device_config(n, false));
  for (device::SimDeviceAxes* d : {&master_dev, &slave_dev}) {
    ASSERT_TRUE(d->configure().ok());
    ASSERT_TRUE(d->activate().ok());
  }
  NodeCoreAxes master(settings(Role::kMaster, n), master_dev);
  NodeCoreAxes slave(settings(Role::kSlave, n), slave_dev);
  PeerSample to_master{};
  PeerSample to_slave{};
  std::chrono::nanoseconds now = 1s;
  std::uint64_t records = 0;
  long calls = 0;
  auto cycle = [&](std::chrono::nanoseconds late = 0ns) {
    now += 1ms;
    const std::chrono::nanoseconds clock = now + late;
    test::start_counting(true);
    if (to_master.state.sequence != 0) master.peer_in().write(to_master);
    if (to_slave.state.sequence != 0) slave.peer_in().write(to_slave);
    master.step(now, clock);
    slave.step(now, clock);
    calls += test::stop_counting();
    (void)master.state_out().read(to_slave.state);
    to_slave.arrival_ns = (clock + 300us).count();
    (void)slave.state_out().read(to_master.state);
    to_master.arrival_ns = (clock + 300us).count();
    while (master.telemetry_out().try_pop()) ++records;
    while (slave.telemetry_out().try_pop()) ++records;
  };
  auto both = [&](Command c) {
    ASSERT_TRUE(master.post_command(c));
    ASSERT_TRUE(slave.post_command(c));
    cycle();
  };
  for (int i = 0; i < 3; ++i) cycle();
  both(Command::kArm);
  both(Command::kEngage);
  ASSERT_EQ(master.mode(), Mode::kAligning);
  for (int i = 0; i < 5000 && master.mode() != Mode::kEngaged; ++i) cycle();
  ASSERT_EQ(master.mode(), Mode::kEngaged);
  for (int i = 0; i < 600; ++i) cycle();
  ASSERT_TRUE(master.post_command(Command::kClutch));
  for (int i = 0; i < 100; ++i) cycle();
  ASSERT_EQ(master.mode(), Mode::kClutched);
  ASSERT_TRUE(master.post_command(Command::kUnclutch));
  for (int i = 0; i < 100; ++i) cycle();
  ASSERT_EQ(master.mode(), Mode::kEngaged);
  // A guarded change through its ramp (posted by the command thread, outside the count): the
  // gains a fifth stiffer, the slave's planes halved, over 50 ms.
  RetuneAxes r;
  r.id = 1;
  const NodeAxesSettings s = settings(Role::kSlave, n);
  for (std::size_t g = 0; g < kGainMatrices; ++g) {
    r.gains[g] = gain_values(s.law.gains, n)[g];
    for (double& v : r.gains[g]) v *= 1.2;
  }
  for (int i = 0; i < s.law.slave_planes.size(); ++i) {
    r.slave_planes_N_per_m[static_cast<std::size_t>(i)] =
        0.5 * s.law.slave_planes.plane(i).stiffness_N_per_m;
  }
  r.apply_at_master_sequence = to_slave.state.sequence + 5;
  r.ramp = 50ms;
  master.post_retune(r);
  slave.post_retune(r);
  for (int i = 0; i < 100; ++i) cycle();
  ASSERT_EQ(master.mode(), Mode::kEngaged);
  ASSERT_EQ(master.active_change_id(), 1U);
  ASSERT_EQ(slave.active_change_id(), 1U);
  cycle(200ms);  // a late wake-up: safe, then the ramp
  ASSERT_EQ(master.mode(), Mode::kSafe);
  for (int i = 0; i < 50; ++i) cycle(200ms);
  EXPECT_GT(records, 0U);
  EXPECT_EQ(calls, 0) << "allocator calls from NodeCoreAxes::step at n = " << n;
}

TEST(NodeCoreAxesRealTime, ThreeAxesAllocateNothing) { run(3); }
TEST(NodeCoreAxesRealTime, SixAxesAllocateNothing) { run(6); }

}  // namespace
}  // namespace teleop::node
