// A busy n-axis master-slave pair's settings and simulated devices, shared by the NodeCoreAxes
// allocation test and its benchmark: 600 N/m and 2 Ns/m per axis, a 1500 N/m slave plane at
// 1 cm along axis 0, a human pushing 1.5 N along (1, ..., 1)/sqrt(n) once engaged, the master
// starting 3 mm off so that aligning has work to do.
#pragma once

#include <chrono>

#include "common/device/sim_device_axes.hpp"
#include "common/node/node_core_axes.hpp"

namespace teleop::node::axes_test {

inline NodeAxesSettings settings(transport::Role role, int n) {
  using namespace std::chrono_literals;
  using transport::Role;
  NodeAxesSettings s;
  s.role = role;
  s.period = 1ms;
  s.law.axes = n;
  s.law.period_s = 1e-3;
  const control::AxisMatrix eye = control::AxisMatrix::Identity(n, n);
  const control::AxisMatrix zero = control::AxisMatrix::Zero(n, n);
  s.law.gains = control::LawGainsAxes{600 * eye, 600 * eye, 2 * eye, 2 * eye, zero, zero, zero};
  s.law.master_actuator = control::no_actuator_limits(n);
  s.law.slave_actuator = control::no_actuator_limits(n);
  s.law.slave_limits = control::no_slave_limits(n);
  control::Plane plane;
  plane.normal = control::AxisVector::Zero(n);
  plane.normal(0) = 1.0;
  plane.offset_m = 0.01;
  plane.stiffness_N_per_m = 1500.0;
  s.law.slave_planes.add(plane);
  s.machine.peer_timeout = 30ms;
  s.machine.engage_ramp = 200ms;
  s.safe_ramp = 10ms;
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;
  return s;
}

inline device::SimDeviceAxesConfig device_config(int n, bool master) {
  device::SimDeviceAxesConfig c;
  c.plant.device.mass_kg = Eigen::MatrixXd::Identity(n, n) * (master ? 0.05 : 0.1);
  c.plant.device.damping_Ns_per_m = Eigen::VectorXd::Constant(n, 0.5);
  c.plant.device.coulomb_N = Eigen::VectorXd::Zero(n);
  c.initial_position_m = Eigen::VectorXd::Zero(n);
  if (master) {
    device::SimHumanAxes h;
    h.impedance.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.012;
    h.impedance.damping_Ns_per_m = Eigen::MatrixXd::Identity(n, n) * 0.76;
    h.impedance.stiffness_N_per_m = Eigen::MatrixXd::Identity(n, n) * 70.0;
    h.set_point_m = Eigen::VectorXd::Zero(n);
    h.direction = Eigen::VectorXd::Constant(n, 1.0).normalized();
    h.profile = sim::ForceProfile::constant(1.5);
    c.human = h;
    c.hold_scene_until_engaged = true;
    c.initial_position_m(0) = 0.003;  // aligning has work to do
  }
  return c;
}

}  // namespace teleop::node::axes_test
