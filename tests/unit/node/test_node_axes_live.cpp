// What the node process needs of the n-axis core and its configuration (issue 18, docs/nodes.md
// "n axes live"): config::to_node_axes_setup on examples/cartesian3.textproto, NodeCoreAxes'
// heartbeat and loop statistics, and the stall check both cores share.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <string>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/node/cycle_checks.hpp"
#include "tests/unit/node/node_axes_test_util.hpp"

namespace teleop::node {
namespace {

using namespace std::chrono_literals;
using transport::Role;

const std::string kExample = std::string(TELEOP_SOURCE_DIR) + "/examples/cartesian3.textproto";

config::NodeSetup setup_of(Role role, const std::vector<std::string>& overrides = {}) {
  return config::to_node_axes_setup(config::parse_config_file(kExample, overrides), role);
}

TEST(NodeAxesSetup, Cartesian3GivesBothNodesTheFileLawDevicesAndOneFingerprint) {
  const config::NodeSetup m = setup_of(Role::kMaster);
  const config::NodeSetup s = setup_of(Role::kSlave);
  EXPECT_EQ(m.axes, 3);
  EXPECT_EQ(m.axes_settings.law.axes, 3);
  EXPECT_EQ(m.settings.period, 1ms);  // sample_rate_hz: 1000
  // The file's gains on the diagonal (kpm 600, kdm_per_axis [2, 2, 2.5]) and its two slave
  // planes, the second (1, 1, 0) normalised.
  EXPECT_DOUBLE_EQ(m.axes_settings.law.gains.kpm(1, 1), 600.0);
  EXPECT_DOUBLE_EQ(m.axes_settings.law.gains.kdm(2, 2), 2.5);
  ASSERT_EQ(s.axes_settings.law.slave_planes.size(), 2);
  EXPECT_NEAR(s.axes_settings.law.slave_planes.plane(1).normal(0), 1.0 / std::sqrt(2.0), 1e-15);
  EXPECT_DOUBLE_EQ(s.axes_settings.law.slave_planes.plane(1).stiffness_N_per_m, 1000.0);
  // The devices: each side's mass matrix; the master's hand (the band's middle at its lowest
  // force level, 2 N: mass (0.003 + 0.012) / 2 = 7.5 g on x), the slave in free space.
  EXPECT_DOUBLE_EQ(m.sim_axes.plant.device.mass_kg(0, 1), 0.005);
  EXPECT_DOUBLE_EQ(s.sim_axes.plant.device.mass_kg(2, 2), 0.045);
  ASSERT_TRUE(m.sim_axes.human.has_value());
  EXPECT_DOUBLE_EQ(m.sim_axes.human->impedance.mass_kg(0, 0), 0.0075);
  // z band: stiffness (80 + 15 * 2 + 150 + 60 * 2) / 2 = 190 N/m.
  EXPECT_DOUBLE_EQ(m.sim_axes.human->impedance.stiffness_N_per_m(2, 2), 190.0);
  EXPECT_FALSE(s.sim_axes.human.has_value());
  EXPECT_TRUE(s.sim_axes.plant.planes.empty());
  // Both nodes of one file agree; a control value changes it, an endpoint does not.
  EXPECT_NE(m.settings.config_fingerprint, 0U);
  EXPECT_EQ(m.settings.config_fingerprint, s.settings.config_fingerprint);
  EXPECT_EQ(m.axes_settings.config_fingerprint, m.settings.config_fingerprint);
  EXPECT_NE(setup_of(Role::kMaster, {"slave.fixture.plane[1].stiffness_N_per_m=900"})
                .settings.config_fingerprint,
            m.settings.config_fingerprint);
  EXPECT_EQ(setup_of(Role::kMaster, {"master.node.command_endpoint=tcp://127.0.0.1:9999"})
                .settings.config_fingerprint,
            m.settings.config_fingerprint);
}

// A USB slave (issue 18 "Devices"): the n-axis USB device, version 2 with one channel per axis;
// without actuator gains a Cartesian device keeps the paddle's DAC step on every channel.
TEST(NodeAxesSetup, AUsbSlaveGetsTheNAxisUsbDevice) {
  const config::NodeSetup s = setup_of(Role::kSlave, {"slave.device.kind=USB"});
  EXPECT_EQ(s.device_kind, device::DeviceKind::kUsb);
  EXPECT_EQ(s.usb_axes.axes, 3);
  EXPECT_EQ(s.usb_axes.kinematics, device::DeviceKinematics::kCartesian);
  EXPECT_TRUE(s.usb_axes.actuators.empty());
  EXPECT_EQ(s.usb_axes.link.vendor_id, 0x1209);
  EXPECT_EQ(setup_of(Role::kMaster, {"slave.device.kind=USB"}).device_kind,
            device::DeviceKind::kSim);
}

TEST(NodeCoreAxesLive, PublishesAHeartbeatPerCycleAndLoopStatisticsEvery50Cycles) {
  const NodeAxesSettings settings = axes_test::settings(Role::kMaster, 3);
  device::SimDeviceAxes device(axes_test::device_config(3, true));
  ASSERT_TRUE(device.configure().ok());
  ASSERT_TRUE(device.activate().ok());
  NodeCoreAxes core(settings, device);
  LoopSnapshot stats{};
  EXPECT_FALSE(core.stats_out().read(stats));
  for (int i = 1; i <= 120; ++i) core.step(std::chrono::nanoseconds(i * 1'000'000LL));
  EXPECT_EQ(core.state_published().load(), 120U);
  // Published at cycles 1, 51 and 101 (sequence % 50 == 1); without a loop the cycle count is
  // the sequence.
  ASSERT_TRUE(core.stats_out().read(stats));
  EXPECT_EQ(stats.cycles, 101U);
  EXPECT_EQ(stats.peer_session_id, 0U);
  EXPECT_TRUE(core.post_command(Command::kArm));
  EXPECT_EQ(core.commands_posted(), 1U);
}

TEST(StallCheck, AGapPastTheTimeoutOrABurstOfOverrunsIsAStall) {
  StallCheck c;
  const auto period = 1ms;
  const auto timeout = 30ms;
  EXPECT_EQ(c.check(0ms, period, timeout), nullptr);  // starts the clock
  EXPECT_EQ(c.check(1ms, period, timeout), nullptr);
  EXPECT_STREQ(c.check(32ms, period, timeout), "own loop stalled past the peer timeout");
  // Cycles 3 ms apart: each adds 2 ms of lateness and drains 1.5 ms, so the debt grows 0.5 ms
  // per cycle and passes 30 ms at the 61st cycle.
  std::chrono::nanoseconds t = 32ms;
  int n = 0;
  const char* why = nullptr;
  while (why == nullptr && n < 100) {
    t += 3ms;
    ++n;
    why = c.check(t, period, timeout);
  }
  EXPECT_STREQ(why, "own loop overran in a burst");
  EXPECT_EQ(n, 61);
  EXPECT_EQ(peer_state_age_ns(false, 5ms, 1'000'000), 0);
  EXPECT_EQ(peer_state_age_ns(true, 5ms, 1'000'000), 4'000'000);
  EXPECT_EQ(peer_state_age_ns(true, 5ms, 9'000'000), 0);
}

}  // namespace
}  // namespace teleop::node
