// read/write/tick of the n-axis simulated device never allocate (docs/architecture.md §4.3), at
// n = 1, 3 and 6: malloc and friends are interposed and counted (tests/support/alloc_counter.hpp,
// as test_sim_device_rt). Sanitizer builds replace the allocator themselves and leave it out.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>

#include "common/device/sim_device_axes.hpp"
#include "tests/support/alloc_counter.hpp"

namespace teleop::device {
namespace {

// A master (human pushing a first-order-hold sinusoid, quantised Cartesian encoders, a noisy load
// cell, friction) and a slave on planes, or the five-bar on axes 0 and 1.
SimDeviceAxesConfig busy(int n, bool master, bool five_bar) {
  SimDeviceAxesConfig c;
  c.plant.device.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.1;
  c.plant.device.damping_Ns_per_m = Eigen::VectorXd::Constant(n, 0.5);
  c.plant.device.coulomb_N = Eigen::VectorXd::Constant(n, 0.02);
  c.load_cell.noise_std_N = 0.02;
  if (master) {
    SimHumanAxes h;
    h.impedance.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.05;
    h.impedance.damping_Ns_per_m = Eigen::MatrixXd::Identity(n, n) * 2.0;
    h.impedance.stiffness_N_per_m = Eigen::MatrixXd::Identity(n, n) * 40.0;
    h.set_point_m = Eigen::VectorXd::Constant(n, 0.001);
    h.direction = Eigen::VectorXd::Ones(n).normalized();
    h.profile = sim::ForceProfile::sinusoid(0.5, 1.0, 2.0);
    h.sampling = sim::ProfileSampling::kFirstOrderHold;
    c.human = h;
    c.hold_scene_until_engaged = true;
  } else {
    for (int j = 0; j < 2; ++j) {
      sim::ContactPlane p;
      p.normal = Eigen::VectorXd::Unit(n, j % n);
      p.offset_m = 0.002;
      p.stiffness_N_per_m = 2000.0;
      p.damping_Ns_per_m = 3.0;
      c.plant.planes.push_back(p);
    }
  }
  if (five_bar) {
    c.kinematics = DeviceKinematics::kFiveBar;
    c.five_bar.base_separation_m = 0.1;
    c.five_bar.proximal_m[0] = c.five_bar.proximal_m[1] = 0.1;
    c.five_bar.distal_m[0] = c.five_bar.distal_m[1] = 0.15;
    c.five_bar_home_m = Eigen::Vector2d(0.0, 0.2);
    c.encoders.assign(static_cast<std::size_t>(n), sim::EncoderParams{4096, 1.0, 0.02});
  }
  return c;
}

long count_allocations(int n, bool five_bar) {
  const SimDeviceAxesConfig mc = busy(n, true, five_bar);
  const SimDeviceAxesConfig sc = busy(n, false, five_bar);
  SimDeviceAxes master(mc);
  SimDeviceAxes slave(sc);
  EXPECT_TRUE(master.configure().ok());
  EXPECT_TRUE(slave.configure().ok());
  EXPECT_TRUE(master.activate().ok());
  EXPECT_TRUE(slave.activate().ok());
  SampleAxes sm;
  SampleAxes ss;
  CommandAxes to_master;
  CommandAxes to_slave;
  bool ok = true;
  double travel = 0.0;
  teleop::test::start_counting(false);
  for (int k = 0; k < 2000; ++k) {
    if (k == 10) master.on_engaged();
    ok = ok && master.read(sm).ok() && slave.read(ss).ok();
    to_master.force_N = -300.0 * (sm.position_m - ss.position_m);
    to_slave.force_N = 300.0 * (sm.position_m - ss.position_m);
    ok = ok && master.write(to_master).ok() && slave.write(to_slave).ok();
    ok = ok && master.tick(mc.period).ok() && slave.tick(sc.period).ok();
    travel = std::max(travel, ss.position_m.cwiseAbs().maxCoeff());
  }
  const long calls = teleop::test::stop_counting();
  EXPECT_TRUE(ok) << "n = " << n;
  EXPECT_GT(travel, 1e-3) << "n = " << n;  // the slave followed the push
  return calls;
}

TEST(SimDeviceAxesRt, ReadWriteTickNeverAllocate) {
  for (const int n : {1, 3, 6}) EXPECT_EQ(count_allocations(n, false), 0) << "n = " << n;
  for (const int n : {3, 6}) EXPECT_EQ(count_allocations(n, true), 0) << "five-bar, n = " << n;
}

}  // namespace
}  // namespace teleop::device
