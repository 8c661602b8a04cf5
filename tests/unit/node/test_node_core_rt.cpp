// NodeCore::step allocates nothing on the paths issue 14 added or changed (findings 6, 10,
// 11): a late wake-up and a burst of overruns going safe, clutch and unclutch with the offset
// absorbed, clear/arm/engage and the alignment with the cooperating simulated operator. The
// allocator is interposed (tests/support/alloc_counter.hpp) and this thread's calls counted
// over the steps only; the live loop's own test is tests/unit/runtime/test_node_rt.cpp.
#include <gtest/gtest.h>

#include "common/device/sim_device.hpp"
#include "common/node/node_core.hpp"
#include "common/rt/loop_timing.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::node {
namespace {

using namespace std::chrono_literals;
using transport::Role;

NodeSettings settings(Role role) {
  NodeSettings s;
  s.role = role;
  s.period = 1ms;
  s.law.period_s = 1e-3;
  s.law.gains = Gains{600, 600, 2, 2, 0, 0, 0};
  s.law.slave_fixture = FixtureParams{1500.0, 0.006};
  s.machine.peer_timeout = 30ms;
  s.machine.engage_ramp = 200ms;
  s.safe_ramp = 10ms;
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;  // the same configuration on both sides (arm needs it)
  return s;
}

TEST(NodeCoreRealTime, StallsClutchAndReEngagementAllocateNothing) {
  sim::HumanParams h;
  h.impedance = HumanImpedance{0.012, 0.76, 70.0};
  h.profile = sim::ForceProfile::constant(1.5);
  device::SimDeviceConfig mc = device::SimDeviceConfig::paddle_master(h);
  mc.hold_scene_until_engaged = true;
  device::SimDevice master_dev(mc);
  device::SimDevice slave_dev(
      device::SimDeviceConfig::paddle_slave(sim::Environment::tissue(200.0, 1.0, 0.004)));
  for (device::SimDevice* d : {&master_dev, &slave_dev}) {
    ASSERT_TRUE(d->configure().ok());
    ASSERT_TRUE(d->activate().ok());
  }
  NodeCore master(settings(Role::kMaster), master_dev);
  NodeCore slave(settings(Role::kSlave), slave_dev);
  rt::LoopTiming timing(1ms, 1s);
  PeerSample to_master{};
  PeerSample to_slave{};
  std::uint64_t records = 0;
  long calls = 0;
  auto cycle = [&](std::chrono::nanoseconds late = 0ns) {
    const std::chrono::nanoseconds deadline = timing.next_deadline();
    const std::chrono::nanoseconds clock = deadline + late;
    PeerSample s = to_master;
    s.arrival_ns = (clock - 100us).count();
    test::start_counting(true);
    if (s.state.sequence != 0) master.peer_in().write(s);
    if (to_slave.state.sequence != 0) slave.peer_in().write(to_slave);
    (void)timing.woke(clock);
    master.step(deadline, &timing);
    timing.finished(clock + 20us);
    slave.step(clock);
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
  auto until = [&](Mode m, int bound) {
    for (int i = 0; i < bound && master.mode() != m; ++i) cycle();
    ASSERT_EQ(master.mode(), m);
  };
  for (int i = 0; i < 3; ++i) cycle();
  both(Command::kArm);
  both(Command::kEngage);
  ASSERT_NO_FATAL_FAILURE(until(Mode::kEngaged, 3000));
  for (int i = 0; i < 1500; ++i) cycle();
  // Clutch, the operator's push moves the free master, unclutch (offset absorbed).
  ASSERT_TRUE(master.post_command(Command::kClutch));
  for (int i = 0; i < 300; ++i) cycle();
  ASSERT_EQ(master.mode(), Mode::kClutched);
  ASSERT_TRUE(master.post_command(Command::kUnclutch));
  for (int i = 0; i < 300; ++i) cycle();
  ASSERT_EQ(master.mode(), Mode::kEngaged);
  // A late wake-up: safe. Clear, arm, engage: the operator cooperates, aligned, engaged.
  cycle(200ms);
  ASSERT_EQ(master.mode(), Mode::kSafe);
  for (int i = 0; i < 500; ++i) cycle();
  both(Command::kClear);
  both(Command::kArm);
  both(Command::kEngage);
  ASSERT_EQ(master.mode(), Mode::kAligning);
  ASSERT_NO_FATAL_FAILURE(until(Mode::kEngaged, 10000));
  for (int i = 0; i < 500; ++i) cycle();
  // A burst of overruns: safe again.
  for (int i = 0; i < 6; ++i) cycle(19ms);
  ASSERT_EQ(master.mode(), Mode::kSafe);
  EXPECT_GT(records, 0u);
  EXPECT_EQ(calls, 0) << "allocator calls from NodeCore::step";
}

}  // namespace
}  // namespace teleop::node
