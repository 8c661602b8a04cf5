// SimDevice: lifecycle, the physics it steps, its sensors and flags, the factory.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include "common/device/haptic_device.hpp"
#include "common/device/sim_device.hpp"

namespace teleop::device {
namespace {

using std::chrono::microseconds;
using std::chrono::milliseconds;

TEST(SimDevice, LifecycleGatesReadAndWrite) {
  SimDevice dev(SimDeviceConfig{});
  Sample s;
  EXPECT_EQ(dev.read(s).code, StatusCode::kNotActive);
  EXPECT_EQ(dev.write({1.0}).code, StatusCode::kNotActive);
  EXPECT_EQ(dev.advance(milliseconds(1)).code, StatusCode::kNotConfigured);
  EXPECT_EQ(dev.activate().code, StatusCode::kNotConfigured);
  ASSERT_TRUE(dev.configure().ok());
  EXPECT_EQ(dev.read(s).code, StatusCode::kNotActive);
  ASSERT_TRUE(dev.activate().ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.time_s, 0.0);
  EXPECT_TRUE(dev.write({1.0}).ok());
  ASSERT_TRUE(dev.deactivate().ok());
  EXPECT_EQ(dev.read(s).code, StatusCode::kNotActive);
}

TEST(SimDevice, ConfigureReportsTheBadField) {
  SimDeviceConfig c;
  c.plant.device.mass_kg = -1.0;
  SimDevice dev(c);
  const Status st = dev.configure();
  EXPECT_EQ(st.code, StatusCode::kInvalidArgument);
  EXPECT_NE(std::strstr(st.message, "device.mass_kg"), nullptr) << st.message;
  SimDeviceConfig e;
  e.encoder.counts_per_rev = 0;
  SimDevice dev2(e);
  EXPECT_NE(std::strstr(dev2.configure().message, "encoder.counts_per_rev"), nullptr);
}

TEST(SimDevice, WritesMoveItAsThePlantAloneWould) {
  SimDeviceConfig c = SimDeviceConfig::paddle_slave(sim::Environment::tissue(800.0, 1.0, 0.01));
  c.plant.coulomb_friction_N = 0.03;
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  sim::Plant alone(c.plant, c.period);
  const sim::Encoder enc(c.encoder);
  for (int k = 0; k < 2000; ++k) {
    const double u = 3.0 * std::sin(0.004 * k) + 1.0;
    ASSERT_TRUE(dev.write({u}).ok());
    ASSERT_TRUE(dev.advance(c.period).ok());
    alone.step(u);
    Sample s;
    ASSERT_TRUE(dev.read(s).ok());
    ASSERT_EQ(dev.truth().state.position_m, alone.state().position_m) << k;
    ASSERT_EQ(dev.truth().state.velocity_m_per_s, alone.state().velocity_m_per_s) << k;
    ASSERT_EQ(s.position_m, enc.read_m(alone.state().position_m));
    // Noiseless load cell: the true force, clipped to its +-10 N.
    ASSERT_EQ(s.force_N, std::min(alone.output().environment_force_N, 10.0));
    // One sample each from configure() and activate(), then one per period.
    ASSERT_EQ(s.sequence, static_cast<std::uint64_t>(k + 3));
    ASSERT_NEAR(s.time_s, (k + 1) * 1e-3, 1e-12);
  }
}

TEST(SimDevice, MasterLoadCellReadsTheHumanForce) {
  sim::HumanParams h;
  h.profile = sim::ForceProfile::constant(2.0);
  h.impedance = {0.01, 2.0, 100.0};
  const SimDeviceConfig c = SimDeviceConfig::paddle_master(h);
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  for (int k = 0; k < 3000; ++k) ASSERT_TRUE(dev.advance(c.period).ok());
  // At equilibrium the device is still and nothing pushes back: F_h = 0 at x = F_h*/k_h.
  EXPECT_NEAR(dev.truth().state.position_m, 0.02, 1e-9);
  Sample s;
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_NEAR(s.force_N, 0.0, 1e-7);
  // Holding it with the motor at -1 N, the human's force balances it: F_h = 1 N.
  ASSERT_TRUE(dev.write({-1.0}).ok());
  for (int k = 0; k < 3000; ++k) ASSERT_TRUE(dev.advance(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_NEAR(s.force_N, 1.0, 1e-7);
  EXPECT_NEAR(dev.truth().state.position_m, 0.01, 1e-9);
}

TEST(SimDevice, MaliciousUserWalksItsBandAndSaysWhere) {
  SimDeviceConfig c = SimDeviceConfig::paddle_master(
      sim::HumanParams::malicious_pushing(default_human_band(), 5.0, 0.1));
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  std::vector<std::size_t> visited;
  for (int k = 0; k < 1000; ++k) {
    ASSERT_TRUE(dev.advance(c.period).ok());
    const std::size_t i = *dev.truth().malicious_index;
    if (visited.empty() || visited.back() != i) visited.push_back(i);
    EXPECT_EQ(dev.plant().params().human.stiffness_N_per_m, dev.truth().human.stiffness_N_per_m);
  }
  ASSERT_EQ(visited.size(), 10U);  // 1 s at 0.1 s per impedance
  for (std::size_t i = 0; i < visited.size(); ++i) EXPECT_EQ(visited[i], i);
}

TEST(SimDevice, FlagsSaturationClippingRejectionAndEstop) {
  SimDeviceConfig c = SimDeviceConfig::paddle_slave(sim::Environment::rigid_wall(0.005));
  c.amplifier.max_force_N = 12.0;
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  Sample s;
  ASSERT_TRUE(dev.write({20.0}).ok());
  for (int k = 0; k < 200; ++k) ASSERT_TRUE(dev.advance(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_TRUE(s.flags & SampleFlags::kAmplifierSaturated);
  EXPECT_TRUE(s.flags & SampleFlags::kLoadCellClipped);  // 12 N on the wall, a 10 N cell
  EXPECT_EQ(s.force_N, 10.0);
  EXPECT_EQ(dev.truth().output.environment_force_N, 12.0);
  EXPECT_FALSE(s.flags & SampleFlags::kFault);

  EXPECT_EQ(dev.write({std::numeric_limits<double>::quiet_NaN()}).code,
            StatusCode::kInvalidArgument);
  ASSERT_TRUE(dev.advance(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_TRUE(s.flags & SampleFlags::kCommandRejected);
  EXPECT_EQ(dev.truth().applied_force_N, 0.0);

  ASSERT_TRUE(dev.write({5.0}).ok());
  dev.set_estop(true);
  ASSERT_TRUE(dev.advance(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_TRUE(s.flags & SampleFlags::kFault);
  EXPECT_FALSE(s.flags & SampleFlags::kCommandRejected);
  EXPECT_EQ(dev.truth().applied_force_N, 0.0);
  dev.set_estop(false);
  ASSERT_TRUE(dev.advance(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, 0U);
  EXPECT_EQ(dev.truth().applied_force_N, 5.0);
}

TEST(SimDevice, UnquantisedPositionIsTheTruePosition) {
  SimDeviceConfig c;
  c.quantize_position = false;
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  ASSERT_TRUE(dev.write({0.3}).ok());
  Sample s;
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(dev.advance(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.position_m, dev.truth().state.position_m);
  EXPECT_NE(s.position_m, sim::Encoder(c.encoder).read_m(s.position_m));
}

TEST(SimDevice, SameSeedSameSamplesOtherSeedOther) {
  const auto run = [](std::uint64_t seed) {
    SimDeviceConfig c = SimDeviceConfig::paddle_slave(sim::Environment::tissue(500.0, 0.5, 0.0));
    c.load_cell.noise_std_N = 0.05;
    c.seed = seed;
    SimDevice dev(c);
    EXPECT_TRUE(dev.configure().ok());
    EXPECT_TRUE(dev.activate().ok());
    std::vector<double> forces;
    for (int k = 0; k < 500; ++k) {
      EXPECT_TRUE(dev.write({1.0}).ok());
      EXPECT_TRUE(dev.advance(milliseconds(1)).ok());
      Sample s;
      EXPECT_TRUE(dev.read(s).ok());
      forces.push_back(s.force_N);
    }
    return forces;
  };
  EXPECT_EQ(run(3), run(3));
  EXPECT_NE(run(3), run(4));
}

TEST(SimDevice, AnotherPeriodStillStepsExactly) {
  SimDeviceConfig c;
  SimDevice dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  ASSERT_TRUE(dev.write({1.0}).ok());
  for (int k = 0; k < 4; ++k) ASSERT_TRUE(dev.advance(microseconds(250)).ok());
  sim::Plant alone(c.plant, milliseconds(1));
  alone.step(1.0);
  EXPECT_NEAR(dev.truth().state.position_m, alone.state().position_m,
              1e-12 * alone.state().position_m);
  EXPECT_NEAR(dev.truth().time_s, 1e-3, 1e-15);
  EXPECT_EQ(dev.advance(milliseconds(0)).code, StatusCode::kInvalidArgument);
}

TEST(MakeDevice, SimByDefaultAndUsbNamesTheMissingDevice) {
  MakeDeviceResult sim = make_device(DeviceKind::kSim);
  ASSERT_TRUE(sim.status.ok());
  ASSERT_NE(sim.device, nullptr);
  EXPECT_TRUE(sim.device->configure().ok());
  EXPECT_TRUE(sim.device->activate().ok());
  // No USB bus on the test machines: configuring the USB device names the ids it looked for.
  MakeDeviceResult usb = make_device(DeviceKind::kUsb);
  ASSERT_NE(usb.device, nullptr);
  const Status s = usb.device->configure();
  EXPECT_EQ(s.code, StatusCode::kUnavailable);
  EXPECT_NE(std::string(s.message).find("vendor 0x1209 product 0x7E1E"), std::string::npos)
      << s.message;
}

}  // namespace
}  // namespace teleop::device
