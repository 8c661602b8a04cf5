// A node's part of the SystemConfig (issue 4 "Launch"): defaults from the issue, every bad
// value named by its field.
#include <gtest/gtest.h>

#include <string>

#include "common/config/node_loader.hpp"

namespace teleop::config {
namespace {

using namespace std::chrono_literals;
using transport::Role;

const std::string kPaddles =
    "sample_rate_hz: 1000\n"
    "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }\n"
    "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } }\n"
    "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n";

NodeSetup setup(const std::string& text, Role role, const std::vector<std::string>& set = {}) {
  return to_node_setup(load_config_text(text, "node.textproto", set), role);
}

std::string error_of(const std::string& text, Role role, const std::vector<std::string>& set) {
  try {
    (void)setup(text, role, set);
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(NodeLoader, DefaultsAreTheIssuesOnLoopback) {
  const NodeSetup m = setup(kPaddles, Role::kMaster);
  EXPECT_EQ(m.settings.period, 1ms);
  EXPECT_EQ(m.settings.machine.peer_timeout, 30ms);
  EXPECT_EQ(m.settings.safe_ramp, 10ms);
  EXPECT_EQ(m.settings.machine.engage_ramp, 200ms);
  EXPECT_EQ(m.endpoints.state, "tcp://127.0.0.1:5560");
  EXPECT_EQ(m.endpoints.peer_state, "tcp://127.0.0.1:5561");
  EXPECT_EQ(m.endpoints.command, "tcp://127.0.0.1:5562");
  EXPECT_EQ(m.endpoints.telemetry, "tcp://127.0.0.1:5564");
  EXPECT_EQ(m.rt.fifo_priority, 80);
  EXPECT_TRUE(m.rt.lock_memory);
  EXPECT_FALSE(m.rt.required);
  EXPECT_EQ(m.cpu_dma_latency_us, 10);
  EXPECT_EQ(m.device_kind, device::DeviceKind::kSim);
  EXPECT_TRUE(m.sim.hold_scene_until_engaged);
  const NodeSetup s = setup(kPaddles, Role::kSlave);
  EXPECT_EQ(s.endpoints.state, "tcp://127.0.0.1:5561");
  EXPECT_EQ(s.endpoints.peer_state, "tcp://127.0.0.1:5560");
  // The node runs the law the analyser checks: same gains, period.
  EXPECT_EQ(s.settings.law.gains.kps, 600.0);
  EXPECT_DOUBLE_EQ(s.settings.law.period_s, 1e-3);
}

TEST(NodeLoader, EachSideTakesItsOwnNodeSectionAndThePeersEndpoint) {
  const NodeSetup m =
      setup(kPaddles, Role::kMaster,
            {"master.node.state_endpoint=tcp://10.0.0.1:6000",
             "slave.node.state_endpoint=tcp://10.0.0.2:6001", "link.peer_timeout_ms=50",
             "master.node.rt.cpu=1", "master.device.kind=USB", "master.node.usb.vendor_id=4660"});
  EXPECT_EQ(m.endpoints.state, "tcp://10.0.0.1:6000");
  EXPECT_EQ(m.endpoints.peer_state, "tcp://10.0.0.2:6001");
  EXPECT_EQ(m.settings.machine.peer_timeout, 50ms);
  EXPECT_EQ(m.rt.cpu, 1);
  EXPECT_EQ(m.device_kind, device::DeviceKind::kUsb);
  EXPECT_EQ(m.usb.vendor_id, 0x1234u);
}

TEST(NodeLoader, BadValuesAreNamed) {
  EXPECT_NE(error_of(kPaddles, Role::kMaster, {"master.node.rt.fifo_priority=120"})
                .find("master.node.rt.fifo_priority: must be in [0, 99], got 120"),
            std::string::npos);
  EXPECT_NE(error_of(kPaddles, Role::kSlave, {"link.peer_timeout_ms=0"})
                .find("link.peer_timeout_ms: must be > 0"),
            std::string::npos);
  EXPECT_NE(error_of(kPaddles, Role::kSlave, {"security.master_public_key=short"})
                .find("security.master_public_key: must be a 40-character Z85"),
            std::string::npos);
  EXPECT_NE(error_of(kPaddles, Role::kMaster, {"slave.node.telemetry_rate_hz=5000"}), "");
  EXPECT_NE(error_of(kPaddles, Role::kSlave, {"slave.node.telemetry_rate_hz=5000"})
                .find("slave.node.telemetry_rate_hz: must be in (0, 1000]"),
            std::string::npos);
}

// The simulated device's scheduled e-stop (issue 7 fault table): taken as given, and each
// impossible schedule named by its field.
TEST(NodeLoader, SimulatedEStopScheduleIsTakenAndBadOnesAreNamed) {
  const NodeSetup s =
      setup(kPaddles, Role::kSlave,
            {"slave.device.estop.press_at_s=1.25", "slave.device.estop.release_at_s=2"});
  ASSERT_TRUE(s.sim.estop_press_at_s.has_value());
  EXPECT_EQ(*s.sim.estop_press_at_s, 1.25);
  ASSERT_TRUE(s.sim.estop_release_at_s.has_value());
  EXPECT_EQ(*s.sim.estop_release_at_s, 2.0);
  EXPECT_FALSE(setup(kPaddles, Role::kMaster, {"slave.device.estop.press_at_s=1"})
                   .sim.estop_press_at_s.has_value());
  EXPECT_NE(error_of(kPaddles, Role::kSlave, {"slave.device.estop.release_at_s=2"})
                .find("slave.device.estop.press_at_s: is required when estop is given"),
            std::string::npos);
  EXPECT_NE(error_of(kPaddles, Role::kSlave,
                     {"slave.device.estop.press_at_s=2", "slave.device.estop.release_at_s=1"})
                .find("slave.device.estop.release_at_s: must be after press_at_s"),
            std::string::npos);
  EXPECT_NE(error_of(kPaddles, Role::kMaster, {"master.device.estop.press_at_s=-1"})
                .find("master.device.estop.press_at_s: must be >= 0"),
            std::string::npos);
}

TEST(NodeLoader, UnknownLinkFieldIsALoadError) {
  try {
    (void)load_config_text(kPaddles + "link { peer_timeout: 30 }\n", "node.textproto");
    FAIL() << "accepted an unknown field";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("peer_timeout"), std::string::npos) << e.what();
  }
}

TEST(NodeLoader, ABandOfHumansHoldsTheLiveMasterAsTheBandsMiddleAtItsLowestForce) {
  const std::string band =
      kPaddles +
      "human { band { force_levels_N: [2, 5]\n"
      "  mass_kg { lower { intercept: 0.004 } upper { intercept: 0.010 } }\n"
      "  damping_Ns_per_m { lower { intercept: 0.6 slope_per_N: 0.1 } upper { intercept: 2 } }\n"
      "  stiffness_N_per_m { lower { intercept: 50 slope_per_N: 10 } upper { intercept: 100 } } "
      "} }\n";
  const NodeSetup m = setup(band, Role::kMaster);
  ASSERT_TRUE(m.sim.human.has_value());
  // At F = 2 N: mass (0.004 + 0.010)/2, damping (0.8 + 2)/2, stiffness (70 + 100)/2.
  EXPECT_DOUBLE_EQ(m.sim.human->impedance.mass_kg, 0.007);
  EXPECT_DOUBLE_EQ(m.sim.human->impedance.damping_Ns_per_m, 1.4);
  EXPECT_DOUBLE_EQ(m.sim.human->impedance.stiffness_N_per_m, 85.0);
}

}  // namespace
}  // namespace teleop::config
