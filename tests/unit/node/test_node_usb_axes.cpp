// The n-axis node on a USB device (issue 18 "Devices"): the configuration's USB fields
// (to_node_axes_setup), the node's device (runtime::open_axes_device, as teleop-master builds
// it, here over the emulator's in-memory link instead of libusb) and the node's RT core
// (NodeCoreAxes) against the n-channel emulator, its peer a simulated slave core.
//
// Expected values are computed here: the node's positions from the emulator's encoder counts
// through the paddle's encoder scaling and, for the five-bar, a closed-form forward kinematics
// written out below (two circles meeting); the DAC values from the centring force of docs/nodes.md
// (F = -k x_m - b v_m, scaled as a whole to its ceiling) through J^T (J by central differences of
// that forward kinematics) and (K_T K_amp)^-1. The emulator's clock is stepped by the test; the
// host's I/O thread is real, so the test waits on conditions with a generous deadline, never
// for time to pass.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <chrono>
#include <cmath>
#include <memory>
#include <numbers>
#include <string>
#include <thread>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/device/usb_emulator.hpp"
#include "common/node/node_core_axes.hpp"
#include "common/runtime/node_app.hpp"
#include "tests/unit/device/usb_axes_rig.hpp"

namespace teleop::node {
namespace {

namespace usb = device::usb;
using namespace std::chrono_literals;
using transport::Role;

const std::string kCartesian3 = std::string(TELEOP_SOURCE_DIR) + "/examples/cartesian3.textproto";
const std::string kFiveBar = std::string(TELEOP_SOURCE_DIR) + "/examples/five_bar.textproto";

// The paddle's encoder: kCount_rad of joint, kCount_m of arc on a Cartesian axis per count.
using device::test_axes::eventually;
using device::test_axes::kCount_m;
using device::test_axes::kCount_rad;

// The centring spring the tests set (link.*): k, b and the ceiling of |F|.
constexpr double kCentringK = 40.0;
constexpr double kCentringB = 0.3;
constexpr double kCentringMax = 0.4;

// Cartesian actuators: K_T (N/A) and K_amp (A/count) per channel.
constexpr double kForceConstant[3] = {3.0, 4.0, 1.0};
constexpr double kAmplifier[3] = {2.5e-4, 2.5e-4, 5e-4};
// Five-bar joints: K_T (N m/A) and K_amp (A/count).
constexpr double kTorqueConstant[2] = {0.05, 0.08};
constexpr double kJointAmplifier[2] = {1e-4, 1e-4};

std::vector<std::string> centring() {
  return {"link.centring_stiffness_N_per_m=" + std::to_string(kCentringK),
          "link.centring_damping_Ns_per_m=" + std::to_string(kCentringB),
          "link.centring_max_force_N=" + std::to_string(kCentringMax)};
}

std::vector<std::string> cartesian_usb_master() {
  std::vector<std::string> o = centring();
  o.push_back("master.device.kind=USB");
  o.push_back("master.device.force_constant_N_per_A=3,4,1");
  o.push_back("master.device.amplifier_A_per_count=2.5e-4,2.5e-4,5e-4");
  return o;
}

std::vector<std::string> five_bar_usb_master() {
  std::vector<std::string> o = centring();
  o.push_back("master.device.kind=USB");
  o.push_back("master.device.torque_constant_N_m_per_A=0.05,0.08");
  o.push_back("master.device.amplifier_A_per_count=1e-4,1e-4");
  return o;
}

// --- the five-bar, written out independently of common/kinematics ---------------------------
// The file's linkage: A1 = (-0.05, 0), A2 = (0.05, 0), proximal 0.15 m, distal 0.2 m. The end
// point is where the circles of radius 0.2 about the elbows meet, on the left of B1 -> B2.
Eigen::Vector2d five_bar_end(const Eigen::Vector2d& q) {
  const Eigen::Vector2d b1 =
      Eigen::Vector2d(-0.05, 0.0) + 0.15 * Eigen::Vector2d(std::cos(q(0)), std::sin(q(0)));
  const Eigen::Vector2d b2 =
      Eigen::Vector2d(0.05, 0.0) + 0.15 * Eigen::Vector2d(std::cos(q(1)), std::sin(q(1)));
  const Eigen::Vector2d d = b2 - b1;
  const double l = d.norm();
  const double along = l / 2.0;  // equal distal links: the chord's midpoint
  const double up = std::sqrt(0.2 * 0.2 - along * along);
  const Eigen::Vector2d left(-d(1) / l, d(0) / l);
  return b1 + along * d / l + up * left;
}

Eigen::Matrix2d five_bar_jacobian(const Eigen::Vector2d& q) {
  constexpr double h = 1e-6;
  Eigen::Matrix2d j;
  for (int c = 0; c < 2; ++c) {
    Eigen::Vector2d dq = Eigen::Vector2d::Zero();
    dq(c) = h;
    j.col(c) = (five_bar_end(q + dq) - five_bar_end(q - dq)) / (2.0 * h);
  }
  return j;
}

// The file's home, 120 and 60 degrees (as the rig's).
using device::test_axes::kHome_rad;

// The centring force on a still master with the slave at the origin: -k x_m, scaled to norm
// kCentringMax when above it (alpha = 1).
Eigen::VectorXd centring_force(const Eigen::VectorXd& x_m) {
  Eigen::VectorXd f = -kCentringK * x_m;
  if (f.norm() > kCentringMax) f *= kCentringMax / f.norm();
  return f;
}

// A master node on the USB emulator and its slave node on the simulated device, both from one
// file; the test is both loops' clock and the emulator's.
struct UsbMasterPair {
  UsbMasterPair(const std::vector<std::string>& overrides, const std::string& file,
                usb::EmulatorConfig emulator)
      : loaded(config::parse_config_file(file, overrides)),
        master_setup(config::to_node_axes_setup(loaded, Role::kMaster)),
        slave_setup(config::to_node_axes_setup(loaded, Role::kSlave)),
        emu(emulator, link.open_device()),
        master_dev(runtime::open_axes_device(
            master_setup, [this](const device::UsbDeviceConfig&) { return link.open_host(); })),
        slave_dev(runtime::open_axes_device(slave_setup)) {
    master_setup.axes_settings.session_id = 11;
    slave_setup.axes_settings.session_id = 22;
  }

  // The activation's re-arming command reaches the emulator, which reports: the node's device
  // has its first sample before the loops start.
  void bring_up() {
    take_command();
    emu.step(1ms);
    wait_report();
    master = std::make_unique<NodeCoreAxes>(master_setup.axes_settings, *master_dev);
    slave = std::make_unique<NodeCoreAxes>(slave_setup.axes_settings, *slave_dev);
  }

  void take_command() {
    const std::uint64_t before = emu.stats().commands_accepted;
    ASSERT_TRUE(eventually([&] {
      emu.process_commands();
      return emu.stats().commands_accepted > before;
    }));
  }
  // The emulator's newest report has reached the node's device.
  void wait_report() {
    auto& usb_dev = dynamic_cast<device::UsbDeviceAxes&>(*master_dev);
    ASSERT_TRUE(eventually([&] { return usb_dev.stats().reports_accepted > reports_seen; }));
    ++reports_seen;
  }

  // One period: both cores step, hand their states over; the emulator takes the master's
  // command (its DACs noted), steps and reports.
  void cycle() {
    now += 1ms;
    if (to_master.state.sequence != 0) master->peer_in().write(to_master);
    if (to_slave.state.sequence != 0) slave->peer_in().write(to_slave);
    master->step(now);
    slave->step(now);
    (void)master->state_out().read(to_slave.state);
    to_slave.arrival_ns = (now + 300us).count();
    (void)slave->state_out().read(to_master.state);
    to_master.arrival_ns = (now + 300us).count();
    while (auto r = master->telemetry_out().try_pop()) records.push_back(*r);
    while (slave->telemetry_out().try_pop()) {
    }
    take_command();
    std::array<int, usb::kMaxChannels> d{};
    for (std::size_t c = 0; c < usb::kMaxChannels; ++c) d[c] = emu.commanded_dac(c);
    dacs.push_back(d);
    emu.step(1ms);
    wait_report();
  }

  void command_both(Command c) {
    ASSERT_TRUE(master->post_command(c));
    ASSERT_TRUE(slave->post_command(c));
    cycle();
  }

  // Pushes each channel's plant (N, for `cycles`), then lets it come to rest.
  void push_then_settle(const std::vector<double>& push_N, int cycles) {
    for (std::size_t c = 0; c < push_N.size(); ++c) emu.set_external_force_N(c, push_N[c]);
    for (int i = 0; i < cycles; ++i) cycle();
    for (std::size_t c = 0; c < push_N.size(); ++c) emu.set_external_force_N(c, 0.0);
    // The paddle's plant: m / b = 0.036 / 0.49 s, so 1.5 s is 20 time constants.
    for (int i = 0; i < 1500; ++i) cycle();
  }

  // The first master record in aligning, and its index.
  std::size_t first_aligning() const {
    for (std::size_t i = 0; i < records.size(); ++i) {
      if (records[i].mode == Mode::kAligning) return i;
    }
    return records.size();
  }

  config::LoadedConfig loaded;
  config::NodeSetup master_setup;
  config::NodeSetup slave_setup;
  usb::MemoryLink link;
  usb::Emulator emu;
  std::unique_ptr<device::HapticDeviceAxes> master_dev;
  std::unique_ptr<device::HapticDeviceAxes> slave_dev;
  std::unique_ptr<NodeCoreAxes> master;
  std::unique_ptr<NodeCoreAxes> slave;
  std::chrono::nanoseconds now{1s};
  PeerSample to_master{};
  PeerSample to_slave{};
  std::vector<CycleRecordAxes> records;
  std::vector<std::array<int, usb::kMaxChannels>> dacs;
  std::uint64_t reports_seen{0};
};

usb::EmulatorConfig emulator(std::size_t channels, std::uint8_t version = usb::kProtocolVersion2) {
  usb::EmulatorConfig e;
  e.protocol_version = version;
  e.channels = channels;
  return e;
}

std::string refusal_of(const std::vector<std::string>& overrides, const std::string& file) {
  try {
    (void)config::to_node_axes_setup(config::parse_config_file(file, overrides), Role::kMaster);
  } catch (const config::ConfigError& e) {
    return e.what();
  }
  return "";
}

TEST(NodeUsbAxes, TheConfigurationGivesTheMasterAUsbDeviceOfItsKinematicsAndActuators) {
  const config::NodeSetup five = config::to_node_axes_setup(
      config::parse_config_file(kFiveBar, five_bar_usb_master()), Role::kMaster);
  EXPECT_EQ(five.device_kind, device::DeviceKind::kUsb);
  EXPECT_EQ(five.usb_axes.axes, 2);
  EXPECT_EQ(five.usb_axes.kinematics, device::DeviceKinematics::kFiveBar);
  EXPECT_DOUBLE_EQ(five.usb_axes.five_bar_home_joint_rad(0), 2.0943951023931953);
  EXPECT_DOUBLE_EQ(five.usb_axes.five_bar.distal_m[1], 0.2);
  ASSERT_EQ(five.usb_axes.actuators.size(), 2U);
  EXPECT_DOUBLE_EQ(five.usb_axes.actuators[1].torque_constant_per_A, 0.08);
  EXPECT_DOUBLE_EQ(five.usb_axes.actuators[1].amplifier_A_per_count, 1e-4);
  // node.usb's ids and watchdog reach the link.
  std::vector<std::string> ids = cartesian_usb_master();
  ids.push_back("master.node.usb.vendor_id=4660");
  ids.push_back("master.node.usb.watchdog_ms=35");
  const config::NodeSetup cart =
      config::to_node_axes_setup(config::parse_config_file(kCartesian3, ids), Role::kMaster);
  EXPECT_EQ(cart.usb_axes.link.vendor_id, 0x1234);
  EXPECT_EQ(cart.usb_axes.link.watchdog, 35ms);
  EXPECT_EQ(cart.usb_axes.kinematics, device::DeviceKinematics::kCartesian);
  ASSERT_EQ(cart.usb_axes.actuators.size(), 3U);
  EXPECT_DOUBLE_EQ(cart.usb_axes.actuators[0].torque_constant_per_A, 3.0);
  // The slave of the same file stays simulated.
  EXPECT_EQ(config::to_node_axes_setup(config::parse_config_file(kCartesian3, ids), Role::kSlave)
                .device_kind,
            device::DeviceKind::kSim);
}

TEST(NodeUsbAxes, BadActuatorGainsOrAHomeAtASingularityAreRefusedNamingTheField) {
  auto with = [](std::vector<std::string> base, const std::string& extra) {
    base.push_back(extra);
    return base;
  };
  std::string e =
      refusal_of({"master.device.kind=USB", "master.device.force_constant_N_per_A=3,4,1",
                  "master.device.amplifier_A_per_count=2.5e-4,2.5e-4"},
                 kCartesian3);
  EXPECT_NE(e.find("master.device.amplifier_A_per_count: must have 3 elements"), std::string::npos)
      << e;
  e = refusal_of(with(cartesian_usb_master(), "master.device.force_constant_N_per_A[1]=nan"),
                 kCartesian3);
  EXPECT_NE(e.find("master.device.force_constant_N_per_A[1]: must be finite, got nan"),
            std::string::npos)
      << e;
  e = refusal_of(with(cartesian_usb_master(), "master.device.amplifier_A_per_count[0]=0"),
                 kCartesian3);
  EXPECT_NE(e.find("master.device.amplifier_A_per_count[0]:"), std::string::npos) << e;
  // The five-bar's joints take torque constants; a USB five-bar needs them.
  e = refusal_of(with(five_bar_usb_master(), "master.device.force_constant_N_per_A=1,1"), kFiveBar);
  EXPECT_NE(e.find("master.device.force_constant_N_per_A: not for this device's kinematics"),
            std::string::npos)
      << e;
  e = refusal_of({"master.device.kind=USB"}, kFiveBar);
  EXPECT_NE(e.find("master.device.torque_constant_N_m_per_A: a USB five-bar needs"),
            std::string::npos)
      << e;
  // Home at (pi - 0.05, 0.05): the elbows (-+0.1998125, 0.0074969) are 0.3996251 m apart,
  // 0.4 mm short of the distal links' reach (0.4 m). Each distal link leaves the chord at
  // atan(sqrt(0.2^2 - 0.1998125^2) / 0.1998125) = 0.0433001 rad, so the two meet 0.0866003 rad
  // from aligned: |sin| = 0.0864921 < 0.2 (the proximal-distal angles are 0.0933 from aligned).
  e = refusal_of(with(five_bar_usb_master(),
                      "master.device.kinematics.five_bar.home_joint_rad=3.0915926535897933,0.05"),
                 kFiveBar);
  EXPECT_NE(e.find("master.device.kinematics.five_bar.home_joint_rad: the home pose is 0.0864921 "),
            std::string::npos)
      << e;
  // The gains are n-axis fields: a one-axis file refuses them.
  try {
    (void)config::to_node_setup(
        config::parse_config_file(
            std::string(TELEOP_SOURCE_DIR) + "/examples/paddles.textproto",
            {"master.device.kind=USB", "master.device.amplifier_A_per_count=1e-4",
             "master.device.force_constant_N_per_A=2"}),
        Role::kMaster);
    ADD_FAILURE() << "no error";
  } catch (const config::ConfigError& error) {
    e = error.what();
  }
  EXPECT_NE(e.find("master.device.amplifier_A_per_count: an n-axis field, given with axes: 1"),
            std::string::npos)
      << e;
}

TEST(NodeUsbAxes, ACartesianMasterReadsTheCountsAndWritesTheCentringForceAsDacCounts) {
  UsbMasterPair p(cartesian_usb_master(), kCartesian3, emulator(3));
  ASSERT_NO_FATAL_FAILURE(p.bring_up());
  ASSERT_NO_FATAL_FAILURE(p.push_then_settle({0.02, -0.035, 0.01}, 150));
  ASSERT_EQ(p.master->mode(), Mode::kDisarmed);
  // The node's position of each axis: the emulator's counts times the encoder's step.
  const usb::ReportPacketV2& report = p.emu.last_report_v2();
  Eigen::VectorXd x_m(3);
  for (int c = 0; c < 3; ++c) {
    x_m(c) = report.encoder_counts[static_cast<std::size_t>(c)] * kCount_m;
    EXPECT_NE(report.encoder_counts[static_cast<std::size_t>(c)], 0) << c;
    EXPECT_NEAR(p.records.back().position_m[static_cast<std::size_t>(c)], x_m(c), 1e-15) << c;
  }
  EXPECT_LT(report.encoder_counts[1], 0);  // pushed the other way
  // Still: its speed is far below a count per period.
  for (std::size_t c = 0; c < 3; ++c)
    ASSERT_LT(std::abs(p.emu.plant(c).state().velocity_m_per_s), 1e-7);

  ASSERT_NO_FATAL_FAILURE(p.command_both(Command::kArm));
  ASSERT_NO_FATAL_FAILURE(p.command_both(Command::kEngage));
  const std::size_t i = p.first_aligning();
  ASSERT_LT(i, p.records.size());
  // The first aligning cycle: the slave still at the origin, the master still at x_m.
  const Eigen::VectorXd f = centring_force(x_m);
  for (int c = 0; c < 3; ++c) {
    const auto k = static_cast<std::size_t>(c);
    EXPECT_NEAR(p.records[i].command_N[k], f(c), 1e-6) << c;
    const double step_N = kForceConstant[c] * kAmplifier[c];
    EXPECT_EQ(p.dacs[i][k], std::lround(f(c) / step_N)) << c << ": F " << f(c);
    EXPECT_GT(std::abs(p.dacs[i][k]), 50) << c;  // a real force, not a rounding of nothing
  }
  // The device's e-stop faults the node: 0 on every channel from the next command on.
  p.emu.set_estop_pressed(true);
  p.cycle();
  p.cycle();
  EXPECT_EQ(p.master->mode(), Mode::kFault);
  for (std::size_t c = 0; c < 3; ++c) EXPECT_EQ(p.dacs.back()[c], 0) << c;
}

TEST(NodeUsbAxes, AFiveBarMasterReadsItsJointsThroughTheKinematicsAndWritesJTransposeF) {
  UsbMasterPair p(five_bar_usb_master(), kFiveBar, emulator(2));
  ASSERT_NO_FATAL_FAILURE(p.bring_up());
  ASSERT_NO_FATAL_FAILURE(p.push_then_settle({0.03, -0.02}, 150));
  const usb::ReportPacketV2& report = p.emu.last_report_v2();
  const Eigen::Vector2d counts(static_cast<double>(report.encoder_counts[0]),
                               static_cast<double>(report.encoder_counts[1]));
  const Eigen::Vector2d q = kHome_rad + kCount_rad * counts;
  ASSERT_NE(report.encoder_counts[0], 0);
  ASSERT_NE(report.encoder_counts[1], 0);
  const Eigen::Vector2d x_m = five_bar_end(q) - five_bar_end(kHome_rad);
  EXPECT_NEAR(p.records.back().position_m[0], x_m(0), 1e-12);
  EXPECT_NEAR(p.records.back().position_m[1], x_m(1), 1e-12);
  EXPECT_GT(x_m.norm(), 1e-3);

  ASSERT_NO_FATAL_FAILURE(p.command_both(Command::kArm));
  ASSERT_NO_FATAL_FAILURE(p.command_both(Command::kEngage));
  const std::size_t i = p.first_aligning();
  ASSERT_LT(i, p.records.size());
  const Eigen::VectorXd f = centring_force(x_m);
  EXPECT_NEAR(p.records[i].command_N[0], f(0), 1e-6);
  EXPECT_NEAR(p.records[i].command_N[1], f(1), 1e-6);
  const Eigen::Vector2d tau_Nm = five_bar_jacobian(q).transpose() * Eigen::Vector2d(f(0), f(1));
  for (int c = 0; c < 2; ++c) {
    const double u = tau_Nm(c) / (kTorqueConstant[c] * kJointAmplifier[c]);
    EXPECT_NEAR(p.dacs[i][static_cast<std::size_t>(c)], u, 0.5 + 1e-3) << c;
    EXPECT_GT(std::abs(u), 100.0) << c;
  }
}

TEST(NodeUsbAxes, AVersionOneDeviceFaultsTheNodeNamingTheVersion) {
  UsbMasterPair p(cartesian_usb_master(), kCartesian3, emulator(1, usb::kProtocolVersion));
  p.master = std::make_unique<NodeCoreAxes>(p.master_setup.axes_settings, *p.master_dev);
  // The v1 firmware refuses every v2 command and reports in v1: the host never accepts a
  // report and, once its report timeout passed, names the version.
  std::string reason;
  const bool named = eventually([&] {
    p.now += 1ms;
    p.master->step(p.now);
    p.emu.step(1ms);
    reason = p.master->mode_reason();
    return reason.find("protocol version 1") != std::string::npos;
  });
  EXPECT_TRUE(named) << reason;
  EXPECT_EQ(p.master->mode(), Mode::kFault);
  EXPECT_NE(reason.find("this host speaks protocol version 2 with 3 channels"), std::string::npos)
      << reason;
  EXPECT_EQ(p.emu.stats().commands_accepted, 0U);
  EXPECT_GT(p.emu.stats().rejected[usb::PacketError::kBadVersion], 0U);
  EXPECT_EQ(p.emu.output_force_N(), 0.0);
  // Clear is refused while the device stays what it is.
  ASSERT_TRUE(p.master->post_command(Command::kClear));
  p.now += 1ms;
  p.master->step(p.now);
  EXPECT_EQ(p.master->mode(), Mode::kFault);
}

}  // namespace
}  // namespace teleop::node
