// SimDeviceAxes (issue 18, "Devices"): the five-bar's quantised reading against the linkage's
// Jacobian by finite differences, the device against PlantAxes driven directly and against the
// one-axis SimDevice, the flags, the e-stop against the closed-form decay of a damped mass, the
// human's first push against F / (M + M_h), and the validation messages.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <string>

#include "common/device/sim_device.hpp"
#include "common/device/sim_device_axes.hpp"
#include "common/kinematics/five_bar.hpp"
#include "common/sim/plant_axes.hpp"

namespace teleop::device {
namespace {

using std::chrono::milliseconds;
using std::chrono::nanoseconds;

// An isotropic diagonal device: M = m I, B = b I, no friction.
sim::PlantAxesParams isotropic(int n, double mass_kg, double damping_Ns_per_m) {
  sim::PlantAxesParams p;
  p.device.mass_kg = Eigen::MatrixXd::Identity(n, n) * mass_kg;
  p.device.damping_Ns_per_m = Eigen::VectorXd::Constant(n, damping_Ns_per_m);
  return p;
}

AxisVector vec(std::initializer_list<double> values) {
  AxisVector v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (const double x : values) v(i++) = x;
  return v;
}

// ---- The five-bar: a count of joint i moves the reading by J e_i times the count -------------

kinematics::FiveBarGeometry paddle_linkage() {
  kinematics::FiveBarGeometry g;
  g.base_separation_m = 0.10;
  g.proximal_m[0] = g.proximal_m[1] = 0.10;
  g.distal_m[0] = g.distal_m[1] = 0.15;
  return g;
}

constexpr int kCounts = 4096;
const double kCount = 2.0 * std::numbers::pi / kCounts;  // rad per count (ratio 1)

struct FiveBarRig {
  kinematics::FiveBarGeometry g = paddle_linkage();
  Eigen::Vector2d q_centre;  // both joints at the centre of a count
  Eigen::Vector2d home;      // the end point there

  FiveBarRig() {
    q_centre =
        Eigen::Vector2d(std::round(2.0 / kCount) * kCount, std::round(1.1 / kCount) * kCount);
    home = kinematics::forward(g, q_centre)->end_m;
  }
  // The sample of a device whose true joint angles are q.
  [[nodiscard]] AxisVector reading(const Eigen::Vector2d& q, bool quantize = true) const {
    SimDeviceAxesConfig c;
    c.plant = isotropic(2, 0.1, 0.5);
    c.kinematics = DeviceKinematics::kFiveBar;
    c.five_bar = g;
    c.five_bar_home_m = home;
    c.encoders.assign(2, sim::EncoderParams{kCounts, 1.0, 0.115});
    c.quantize_position = quantize;
    c.initial_position_m = kinematics::forward(g, q)->end_m - home;
    SimDeviceAxes dev(c);
    EXPECT_TRUE(dev.configure().ok());
    EXPECT_TRUE(dev.activate().ok());
    SampleAxes s;
    EXPECT_TRUE(dev.read(s).ok());
    EXPECT_EQ(s.flags, 0U);
    return s.position_m;
  }
};

TEST(SimDeviceAxes, FiveBarReadingStepsByTheJacobianTimesOneCount) {
  const FiveBarRig rig;
  // The Jacobian by central differences of the forward kinematics (h = 1e-6 rad).
  Eigen::Matrix2d jacobian;
  const double h = 1e-6;
  for (int i = 0; i < 2; ++i) {
    const Eigen::Vector2d dq = Eigen::Vector2d::Unit(i) * h;
    jacobian.col(i) = (kinematics::forward(rig.g, rig.q_centre + dq)->end_m -
                       kinematics::forward(rig.g, rig.q_centre - dq)->end_m) /
                      (2.0 * h);
  }
  // Within a count the reading does not move: 0.4 count off the centre still reads the centre.
  const AxisVector centre = rig.reading(rig.q_centre);
  EXPECT_LT(centre.norm(), 1e-15);
  EXPECT_EQ(rig.reading(rig.q_centre + Eigen::Vector2d(0.4 * kCount, -0.4 * kCount)), centre);
  // Quantisation off: the true position.
  const Eigen::Vector2d q_off = rig.q_centre + Eigen::Vector2d(0.4 * kCount, 0.0);
  const Eigen::Vector2d true_off = kinematics::forward(rig.g, q_off)->end_m - rig.home;
  EXPECT_LT((rig.reading(q_off, false) - AxisVector(true_off)).norm(), 1e-15);
  for (int i = 0; i < 2; ++i) {
    // 1.2 counts up reads one count up, 1.2 down one down (the joint's count in the middle).
    const Eigen::Vector2d e = Eigen::Vector2d::Unit(i);
    const AxisVector up = rig.reading(rig.q_centre + 1.2 * kCount * e);
    const AxisVector down = rig.reading(rig.q_centre - 1.2 * kCount * e);
    const Eigen::Vector2d expected = jacobian.col(i) * kCount;
    // One count: |J e_i| * count to first order (the curvature adds ~3e-4 relative here).
    EXPECT_NEAR(up.norm(), expected.norm(), 2e-3 * expected.norm()) << "joint " << i;
    EXPECT_NEAR(down.norm(), expected.norm(), 2e-3 * expected.norm()) << "joint " << i;
    // The symmetric difference is J e_i * count to third order.
    const Eigen::Vector2d half_span = (up - down).head<2>() / 2.0;
    EXPECT_LT((half_span - expected).norm(), 1e-5 * expected.norm()) << "joint " << i;
  }
}

TEST(SimDeviceAxes, FiveBarReadingStaysWithinHalfACountOfEachJointWhileMoving) {
  // A PD drags the end point round a 2 cm circle; at each sample the reading is the forward
  // kinematics of joint angles each within half a count of the true ones, so it is within
  // (|J e_0| + |J e_1|) count / 2 of the true position, J at the true pose by central
  // differences (plus a second-order allowance of 1 %).
  const FiveBarRig rig;
  SimDeviceAxesConfig c;
  c.plant = isotropic(2, 0.1, 0.5);
  c.kinematics = DeviceKinematics::kFiveBar;
  c.five_bar = rig.g;
  c.five_bar_home_m = rig.home;
  c.encoders.assign(2, sim::EncoderParams{kCounts, 1.0, 0.115});
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  double worst_ratio = 0.0;
  double travel = 0.0;
  for (int k = 0; k < 1000; ++k) {
    SampleAxes s;
    ASSERT_TRUE(dev.read(s).ok());
    ASSERT_EQ(s.flags, 0U) << "period " << k;
    const Eigen::Vector2d x = dev.truth().state.position_m;
    const Eigen::Vector2d q = *kinematics::inverse(rig.g, rig.home + x);
    double bound = 0.0;
    for (int i = 0; i < 2; ++i) {
      const Eigen::Vector2d dq = Eigen::Vector2d::Unit(i) * 1e-6;
      bound +=
          (kinematics::forward(rig.g, q + dq)->end_m - kinematics::forward(rig.g, q - dq)->end_m)
              .norm() /
          2e-6 * kCount / 2.0;
    }
    const double error = (Eigen::Vector2d(s.position_m) - x).norm();
    ASSERT_LE(error, 1.01 * bound) << "period " << k;
    worst_ratio = std::max(worst_ratio, error / bound);
    travel = std::max(travel, x.norm());
    const double t = 1e-3 * k;
    const AxisVector target = vec({0.02 * std::cos(6.0 * t) - 0.02, 0.02 * std::sin(6.0 * t)});
    ASSERT_TRUE(dev.write({200.0 * (target - s.position_m)}).ok());
    ASSERT_TRUE(dev.tick(c.period).ok());
  }
  EXPECT_GT(worst_ratio, 0.3);  // the quantisation is there to see
  EXPECT_GT(travel, 0.03);      // and it went round (the circle's diameter is 4 cm)
}

// ---- n = 3 with quantisation off: PlantAxes driven directly with the same forces ---------------

TEST(SimDeviceAxes, ThreeAxesFollowPlantAxesDrivenDirectly) {
  SimDeviceAxesConfig c;
  c.plant.device.mass_kg.resize(3, 3);
  c.plant.device.mass_kg << 0.5, 0.1, 0.0, 0.1, 0.6, 0.05, 0.0, 0.05, 0.4;
  c.plant.device.damping_Ns_per_m = Eigen::Vector3d(0.3, 0.4, 0.5);
  sim::ContactPlane plane;
  plane.normal = Eigen::Vector3d(1.0, 1.0, 0.0).normalized();
  plane.offset_m = 0.004;
  plane.stiffness_N_per_m = 2000.0;
  plane.damping_Ns_per_m = 5.0;
  c.plant.planes = {plane};
  c.quantize_position = false;
  c.load_cell.range_N = 1e3;
  c.amplifier.max_force_N = 1e3;
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  sim::PlantAxes alone(c.plant, c.period);
  alone.reset({AxisVector::Zero(3), AxisVector::Zero(3)});
  bool touched = false;
  for (int k = 0; k < 1500; ++k) {
    const double t = 1e-3 * k;
    const AxisVector target =
        vec({0.01 * std::sin(6.0 * t), 0.008 * std::sin(4.0 * t + 1.0), 0.005 * std::cos(3.0 * t)});
    SampleAxes s;
    ASSERT_TRUE(dev.read(s).ok());
    ASSERT_EQ(s.axes, 3);
    const AxisVector x_ref = alone.state().position_m;
    ASSERT_EQ(s.position_m, x_ref) << "period " << k;
    // The load cell: the force on the plane, -environment_force_N of the plant.
    const AxisVector f_ref = -alone.output().environment_force_N;
    ASSERT_LE((s.force_N - f_ref).cwiseAbs().maxCoeff(), 1e-15) << "period " << k;
    touched = touched || alone.output().contact_mask != 0;
    const AxisVector u = 80.0 * (target - s.position_m);
    const AxisVector u_ref = 80.0 * (target - x_ref);
    ASSERT_TRUE(dev.write({u}).ok());
    ASSERT_TRUE(dev.tick(c.period).ok());
    alone.step(u_ref);
  }
  EXPECT_TRUE(touched);  // the plane was entered: the comparison covers contact
}

TEST(SimDeviceAxes, ThreeAxisMasterFollowsPlantAxesWithTheHumansForce) {
  // The human's exogenous force F_h* = d f(t) + K_h x_h over each period (first-order hold:
  // value and slope), computed here from the profile and handed to PlantAxes directly.
  SimDeviceAxesConfig c;
  c.plant.device.mass_kg.resize(3, 3);
  c.plant.device.mass_kg << 0.5, 0.1, 0.0, 0.1, 0.6, 0.05, 0.0, 0.05, 0.4;
  c.plant.device.damping_Ns_per_m = Eigen::Vector3d(0.3, 0.4, 0.5);
  SimHumanAxes h;
  h.impedance.mass_kg = Eigen::Vector3d(0.1, 0.12, 0.08).asDiagonal();
  h.impedance.damping_Ns_per_m.resize(3, 3);
  h.impedance.damping_Ns_per_m << 2.0, 0.3, 0.0, 0.3, 2.5, 0.0, 0.0, 0.0, 1.5;
  h.impedance.stiffness_N_per_m = Eigen::Vector3d(40.0, 60.0, 50.0).asDiagonal();
  h.set_point_m = Eigen::Vector3d(0.01, -0.005, 0.002);
  h.direction = Eigen::Vector3d(2.0, -1.0, 2.0) / 3.0;
  h.profile = sim::ForceProfile::sinusoid(0.5, 1.5, 1.5, 0.2);
  h.sampling = sim::ProfileSampling::kFirstOrderHold;
  c.human = h;
  c.quantize_position = false;
  c.load_cell.range_N = 1e3;
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  sim::PlantAxesParams params = c.plant;
  params.human = h.impedance;
  sim::PlantAxes alone(params, c.period);
  alone.reset({AxisVector::Zero(3), AxisVector::Zero(3)});
  const AxisVector hold = h.impedance.stiffness_N_per_m * h.set_point_m;
  const AxisVector d = h.direction;
  double travel = 0.0;
  for (int k = 0; k < 1500; ++k) {
    SampleAxes s;
    ASSERT_TRUE(dev.read(s).ok());
    const AxisVector x_ref = alone.state().position_m;
    ASSERT_LE((s.position_m - x_ref).cwiseAbs().maxCoeff(), 1e-15) << "period " << k;
    // The load cell reads the human's force on the device.
    ASSERT_LE((s.force_N - alone.output().human_force_N).cwiseAbs().maxCoeff(), 1e-12)
        << "period " << k;
    travel = std::max(travel, x_ref.norm());
    const AxisVector u = -30.0 * s.position_m;
    ASSERT_TRUE(dev.write({u}).ok());
    ASSERT_TRUE(dev.tick(c.period).ok());
    const double t = 1e-3 * k;
    const double f0 = h.profile.at(t);
    const double slope = (h.profile.at(t + 1e-3) - f0) / 1e-3;
    const AxisVector push = d * f0 + hold;
    const AxisVector ramp = d * slope;
    alone.step(-30.0 * x_ref, push, ramp);
  }
  EXPECT_GT(travel, 0.005);
}

// ---- n = 1 equals the one-axis SimDevice -----------------------------------------------------

TEST(SimDeviceAxes, OneAxisEqualsSimDevice) {
  // The paper's master paddle held by a human pushing a sinusoid (first-order hold), the scene
  // held until engagement at period 300, with friction.
  sim::HumanParams human;
  human.profile = sim::ForceProfile::sinusoid(0.5, 1.0, 2.0, 0.3);
  human.impedance = HumanImpedance{0.1, 2.0, 30.0};
  human.sampling = sim::ProfileSampling::kFirstOrderHold;
  SimDeviceConfig one = SimDeviceConfig::paddle_master(human);
  one.plant.coulomb_friction_N = 0.02;
  one.quantize_position = false;
  one.hold_scene_until_engaged = true;
  SimDevice a(one);

  SimDeviceAxesConfig c;
  c.plant.device.mass_kg = Eigen::MatrixXd::Constant(1, 1, 0.040);
  c.plant.device.damping_Ns_per_m = Eigen::VectorXd::Constant(1, 0.41);
  c.plant.device.coulomb_N = Eigen::VectorXd::Constant(1, 0.02);
  SimHumanAxes h;
  h.impedance.mass_kg = Eigen::MatrixXd::Constant(1, 1, 0.1);
  h.impedance.damping_Ns_per_m = Eigen::MatrixXd::Constant(1, 1, 2.0);
  h.impedance.stiffness_N_per_m = Eigen::MatrixXd::Constant(1, 1, 30.0);
  h.direction = Eigen::VectorXd::Ones(1);
  h.profile = human.profile;
  h.sampling = human.sampling;
  c.human = h;
  c.quantize_position = false;
  c.hold_scene_until_engaged = true;
  SimDeviceAxes b(c);

  ASSERT_TRUE(a.configure().ok());
  ASSERT_TRUE(b.configure().ok());
  ASSERT_TRUE(a.activate().ok());
  ASSERT_TRUE(b.activate().ok());
  double travel = 0.0;
  for (int k = 0; k < 2000; ++k) {
    if (k == 300) {
      a.on_engaged();
      b.on_engaged();
    }
    Sample sa;
    SampleAxes sb;
    ASSERT_TRUE(a.read(sa).ok());
    ASSERT_TRUE(b.read(sb).ok());
    ASSERT_NEAR(sb.position_m(0), sa.position_m, 1e-12) << "period " << k;
    ASSERT_NEAR(sb.force_N(0), sa.force_N, 1e-9) << "period " << k;
    ASSERT_EQ(sb.flags, sa.flags) << "period " << k;
    travel = std::max(travel, std::abs(sa.position_m));
    // A spring to a moving target, each on its own reading; saturates now and then (16.5 N).
    const double target = 0.02 * std::sin(0.01 * k);
    ASSERT_TRUE(a.write({-400.0 * (sa.position_m - target)}).ok());
    ASSERT_TRUE(b.write({AxisVector::Constant(1, -400.0 * (sb.position_m(0) - target))}).ok());
    ASSERT_TRUE(a.advance(one.period).ok());
    ASSERT_TRUE(b.tick(c.period).ok());
  }
  EXPECT_GT(travel, 0.005);  // it moved
}

TEST(SimDeviceAxes, OneAxisSlaveOnTissueEqualsSimDevice) {
  SimDeviceConfig one = SimDeviceConfig::paddle_slave(sim::Environment::tissue(3000.0, 2.0, 0.01));
  one.quantize_position = false;
  SimDevice a(one);
  SimDeviceAxesConfig c;
  c.plant = isotropic(1, 0.036, 0.49);
  sim::ContactPlane tissue;
  tissue.normal = Eigen::VectorXd::Ones(1);
  tissue.offset_m = 0.01;
  tissue.stiffness_N_per_m = 3000.0;
  tissue.damping_Ns_per_m = 2.0;
  c.plant.planes = {tissue};
  c.quantize_position = false;
  SimDeviceAxes b(c);
  ASSERT_TRUE(a.configure().ok());
  ASSERT_TRUE(b.configure().ok());
  ASSERT_TRUE(a.activate().ok());
  ASSERT_TRUE(b.activate().ok());
  double most_force = 0.0;
  for (int k = 0; k < 2000; ++k) {
    Sample sa;
    SampleAxes sb;
    ASSERT_TRUE(a.read(sa).ok());
    ASSERT_TRUE(b.read(sb).ok());
    ASSERT_NEAR(sb.position_m(0), sa.position_m, 1e-12) << "period " << k;
    ASSERT_NEAR(sb.force_N(0), sa.force_N, 1e-9) << "period " << k;
    most_force = std::max(most_force, sa.force_N);
    const double u = 3.0 * std::sin(0.005 * k) + 1.0;
    ASSERT_TRUE(a.write({u}).ok());
    ASSERT_TRUE(b.write({AxisVector::Constant(1, u)}).ok());
    ASSERT_TRUE(a.advance(one.period).ok());
    ASSERT_TRUE(b.tick(c.period).ok());
  }
  EXPECT_GT(most_force, 1.0);  // pressed into the tissue
}

// ---- Flags -----------------------------------------------------------------------------------

TEST(SimDeviceAxes, SaturationAndRefusedCommandsAreFlaggedPerAxis) {
  SimDeviceAxesConfig c;
  c.plant = isotropic(3, 0.1, 0.5);
  c.amplifier.max_force_N = 5.0;
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  SampleAxes s;
  // Axis 1 beyond the amplifier: clipped to -5 N, the others as commanded.
  ASSERT_TRUE(dev.write({vec({1.0, -7.0, 3.0})}).ok());
  ASSERT_TRUE(dev.tick(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, SampleFlags::kAmplifierSaturated);
  EXPECT_EQ(dev.truth().applied_force_N, vec({1.0, -5.0, 3.0}));
  // Within range: no flag.
  ASSERT_TRUE(dev.write({vec({1.0, -4.0, 3.0})}).ok());
  ASSERT_TRUE(dev.tick(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, 0U);
  // A NaN on one axis refuses the whole command: 0 N on every axis, flagged once.
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(dev.write({vec({1.0, nan, 3.0})}).code, StatusCode::kInvalidArgument);
  ASSERT_TRUE(dev.tick(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, SampleFlags::kCommandRejected);
  EXPECT_EQ(dev.truth().applied_force_N, AxisVector::Zero(3));
  ASSERT_TRUE(dev.tick(c.period).ok());  // 0 N held, the flag gone
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, 0U);
  EXPECT_EQ(dev.truth().applied_force_N, AxisVector::Zero(3));
  // Infinity, and the wrong number of axes, likewise.
  EXPECT_EQ(dev.write({vec({std::numeric_limits<double>::infinity(), 0.0, 0.0})}).code,
            StatusCode::kInvalidArgument);
  ASSERT_TRUE(dev.write({vec({1.0, 2.0, 3.0})}).ok());
  EXPECT_EQ(dev.write({vec({1.0, 2.0})}).code, StatusCode::kInvalidArgument);
  ASSERT_TRUE(dev.tick(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, SampleFlags::kCommandRejected);
  EXPECT_EQ(dev.truth().applied_force_N, AxisVector::Zero(3));
}

TEST(SimDeviceAxes, LoadCellClipsPerAxis) {
  // Resting 10 mm into a 1000 N/m plane along axis 2: 10 N on a 4 N cell.
  SimDeviceAxesConfig c;
  c.plant = isotropic(3, 0.1, 0.5);
  sim::ContactPlane wall;
  wall.normal = Eigen::Vector3d(0.0, 0.0, 1.0);
  wall.stiffness_N_per_m = 1000.0;
  c.plant.planes = {wall};
  c.load_cell.range_N = 4.0;
  c.initial_position_m = Eigen::Vector3d(0.0, 0.0, 0.01);
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  // The plant's forces are those of its last step (none yet after configure): one period.
  ASSERT_TRUE(dev.tick(c.period).ok());
  SampleAxes s;
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.flags, SampleFlags::kLoadCellClipped);
  EXPECT_EQ(s.force_N, vec({0.0, 0.0, 4.0}));
}

// ---- E-stop: no force, the plant decays by its own damping ------------------------------------

TEST(SimDeviceAxes, EstopLeavesOnlyTheDampingDecay) {
  const double m = 0.2;
  const double b = 0.5;
  SimDeviceAxesConfig c;
  c.plant = isotropic(3, m, b);
  c.quantize_position = false;
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  for (int k = 0; k < 50; ++k) {
    ASSERT_TRUE(dev.write({vec({1.0, -2.0, 0.5})}).ok());
    ASSERT_TRUE(dev.tick(c.period).ok());
  }
  const sim::PlantAxesState at_press = dev.truth().state;
  ASSERT_GT(at_press.velocity_m_per_s.norm(), 0.1);
  dev.set_estop(true);
  for (int k = 1; k <= 400; ++k) {
    ASSERT_TRUE(dev.write({vec({3.0, 3.0, 3.0})}).ok());  // ignored while the e-stop holds
    ASSERT_TRUE(dev.tick(c.period).ok());
    SampleAxes s;
    ASSERT_TRUE(dev.read(s).ok());
    EXPECT_EQ(s.flags & SampleFlags::kFault, SampleFlags::kFault);
    const SimTruthAxes t = dev.truth();
    EXPECT_EQ(t.applied_force_N, AxisVector::Zero(3));
    // m v' = -b v: v = v0 exp(-b t / m), x = x0 + v0 (m / b) (1 - exp(-b t / m)).
    const double decay = std::exp(-b * 1e-3 * k / m);
    for (int i = 0; i < 3; ++i) {
      const double v0 = at_press.velocity_m_per_s(i);
      const double x0 = at_press.position_m(i);
      ASSERT_NEAR(t.state.velocity_m_per_s(i), v0 * decay, 1e-12 * std::abs(v0)) << k;
      ASSERT_NEAR(t.state.position_m(i), x0 + v0 * (m / b) * (1.0 - decay), 1e-13) << k;
    }
  }
  dev.set_estop(false);
  ASSERT_TRUE(dev.write({vec({3.0, 3.0, 3.0})}).ok());
  ASSERT_TRUE(dev.tick(c.period).ok());
  EXPECT_EQ(dev.truth().applied_force_N, vec({3.0, 3.0, 3.0}));
}

// ---- The human's first push: F / (M + M_h) ----------------------------------------------------

TEST(SimDeviceAxes, HumanPushAcceleratesAFreeDeviceByForceOverTotalMass) {
  SimDeviceAxesConfig c;
  c.period = nanoseconds{20000};  // 20 us: "the first instant" against 0.1 s time constants
  c.plant.device.mass_kg.resize(3, 3);
  c.plant.device.mass_kg << 0.30, 0.05, 0.00, 0.05, 0.25, 0.02, 0.00, 0.02, 0.20;
  c.plant.device.damping_Ns_per_m = Eigen::Vector3d(0.4, 0.5, 0.3);
  SimHumanAxes h;
  h.impedance.mass_kg.resize(3, 3);
  h.impedance.mass_kg << 0.10, 0.02, 0.0, 0.02, 0.12, 0.0, 0.0, 0.0, 0.08;
  h.impedance.damping_Ns_per_m = Eigen::Matrix3d::Identity() * 2.0;
  h.impedance.stiffness_N_per_m = Eigen::Vector3d(40.0, 60.0, 50.0).asDiagonal();
  const Eigen::Vector3d start(0.01, -0.02, 0.005);
  h.set_point_m = start;  // the hand holds the handle where it is
  h.direction = Eigen::Vector3d(1.0, 2.0, 2.0) / 3.0;
  const double push_N = 2.0;
  h.profile = sim::ForceProfile::constant(push_N);
  c.human = h;
  c.initial_position_m = start;
  c.quantize_position = false;
  c.load_cell.range_N = 100.0;
  c.hold_scene_until_engaged = true;
  SimDeviceAxes dev(c);
  ASSERT_TRUE(dev.configure().ok());
  ASSERT_TRUE(dev.activate().ok());
  // Held until engaged: no push, the hand at its set point, nothing moves.
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(dev.tick(c.period).ok());
  SampleAxes s;
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_LT((s.position_m - AxisVector(start)).norm(), 1e-15);
  EXPECT_LT(s.force_N.norm(), 1e-12);
  dev.on_engaged();
  ASSERT_TRUE(dev.tick(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  // (M + M_h) a = F d at rest: x(T) - x0 = a T^2 / 2 + O(T^3 (B / M) a).
  const Eigen::Matrix3d total = c.plant.device.mass_kg + h.impedance.mass_kg;
  const Eigen::Vector3d force = push_N * h.direction;
  const Eigen::Vector3d a = total.partialPivLu().solve(force);
  const double period_s = 20e-6;
  const Eigen::Vector3d a_seen = 2.0 * (s.position_m - AxisVector(start)) / (period_s * period_s);
  EXPECT_LT((a_seen - a).norm(), 1e-3 * a.norm()) << a_seen.transpose() << " vs " << a.transpose();
  // The load cell reads the hand's force F d - M_h a = M (M + M_h)^-1 F d at that instant.
  const Eigen::Vector3d felt = c.plant.device.mass_kg * a;
  EXPECT_LT((Eigen::Vector3d(s.force_N) - felt).norm(), 2e-3 * felt.norm());
}

// ---- Validation -------------------------------------------------------------------------------

// The message of configure() (it points into the device: copied before the device goes).
struct Outcome {
  StatusCode code{StatusCode::kOk};
  std::string message{};
  [[nodiscard]] bool ok() const { return code == StatusCode::kOk; }
};

Outcome configure(const SimDeviceAxesConfig& c) {
  SimDeviceAxes dev(c);
  const Status st = dev.configure();
  return {st.code, st.message};
}

bool contains(const Outcome& o, const char* what) {
  return o.message.find(what) != std::string::npos;
}

TEST(SimDeviceAxes, ValidationNamesTheField) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  SimDeviceAxesConfig base;
  base.plant = isotropic(3, 0.1, 0.5);
  ASSERT_TRUE(configure(base).ok());
  {
    SimDeviceAxesConfig c = base;
    c.initial_position_m = Eigen::Vector2d(0.0, 0.0);  // 2 entries for 3 axes
    const Outcome st = configure(c);
    EXPECT_EQ(st.code, StatusCode::kInvalidArgument);
    EXPECT_TRUE(contains(st, "initial_position_m")) << st.message;
  }
  {
    SimDeviceAxesConfig c = base;
    c.initial_position_m = Eigen::Vector3d(0.0, nan, 0.0);
    EXPECT_TRUE(contains(configure(c), "initial_position_m"));
  }
  {
    SimDeviceAxesConfig c = base;
    c.encoders.assign(2, sim::EncoderParams{});
    EXPECT_TRUE(contains(configure(c), "encoders"));
    c.encoders.assign(3, sim::EncoderParams{});
    c.encoders[1].counts_per_rev = 0;
    const Outcome st = configure(c);
    EXPECT_TRUE(contains(st, "encoders[1].counts_per_rev")) << st.message;
    c.encoders[1].counts_per_rev = -5;
    EXPECT_TRUE(contains(configure(c), "encoders[1].counts_per_rev"));
  }
  {
    SimDeviceAxesConfig c = base;
    c.plant.device.mass_kg(1, 1) = nan;
    EXPECT_TRUE(contains(configure(c), "device.mass_kg"));
  }
  {
    SimDeviceAxesConfig c = base;
    c.plant.device.damping_Ns_per_m = Eigen::Vector2d(0.5, 0.5);
    EXPECT_TRUE(contains(configure(c), "device.damping_Ns_per_m"));
  }
  {
    SimHumanAxes h;
    h.direction = Eigen::Vector2d(1.0, 0.0);
    SimDeviceAxesConfig c = base;
    c.human = h;
    EXPECT_TRUE(contains(configure(c), "human.direction"));
    h.direction = Eigen::Vector3d(nan, 0.0, 0.0);
    c.human = h;
    EXPECT_TRUE(contains(configure(c), "human.direction"));
    h.direction = Eigen::Vector3d(1.0, 0.0, 0.0);
    h.set_point_m = Eigen::Vector3d(0.0, 0.0, nan);
    c.human = h;
    EXPECT_TRUE(contains(configure(c), "human.set_point_m"));
    h.set_point_m = Eigen::VectorXd();
    h.impedance.stiffness_N_per_m = Eigen::Matrix2d::Identity();
    c.human = h;
    EXPECT_TRUE(contains(configure(c), "human.impedance.stiffness_N_per_m"));
  }
  {
    SimDeviceAxesConfig c = base;
    c.kinematics = DeviceKinematics::kFiveBar;
    c.five_bar = paddle_linkage();
    c.five_bar_home_m = Eigen::Vector2d(0.0, 0.2);
    ASSERT_TRUE(configure(c).ok());
    c.five_bar.proximal_m[1] = -0.1;
    const Outcome st = configure(c);
    EXPECT_TRUE(contains(st, "five_bar")) << st.message;
    EXPECT_TRUE(contains(st, "proximal")) << st.message;
    c.five_bar = paddle_linkage();
    c.five_bar.distal_m[0] = nan;
    EXPECT_TRUE(contains(configure(c), "five_bar"));
    c.five_bar = paddle_linkage();
    c.five_bar_home_m = Eigen::Vector2d(0.0, 1.0);  // out of reach
    EXPECT_TRUE(contains(configure(c), "initial_position_m"));
    SimDeviceAxesConfig one = c;
    one.plant = isotropic(1, 0.1, 0.5);
    EXPECT_TRUE(contains(configure(one), "kinematics"));
  }
  {
    SimDeviceAxesConfig c = base;
    c.period = nanoseconds{0};
    EXPECT_TRUE(contains(configure(c), "period"));
  }
}

TEST(SimDeviceAxes, LifecycleAndPeriodAreChecked) {
  SimDeviceAxesConfig c;
  c.plant = isotropic(2, 0.1, 0.5);
  SimDeviceAxes dev(c);
  EXPECT_EQ(dev.axes(), 2);
  SampleAxes s;
  EXPECT_EQ(dev.read(s).code, StatusCode::kNotActive);
  EXPECT_EQ(dev.tick(c.period).code, StatusCode::kNotConfigured);
  EXPECT_EQ(dev.activate().code, StatusCode::kNotConfigured);
  ASSERT_TRUE(dev.configure().ok());
  EXPECT_EQ(dev.write({vec({1.0, 1.0})}).code, StatusCode::kNotActive);
  ASSERT_TRUE(dev.activate().ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_EQ(s.axes, 2);
  EXPECT_EQ(s.sequence, 2U);  // configure's sample and activate's
  EXPECT_EQ(dev.tick(milliseconds{2}).code, StatusCode::kInvalidArgument);
  ASSERT_TRUE(dev.tick(c.period).ok());
  ASSERT_TRUE(dev.read(s).ok());
  EXPECT_DOUBLE_EQ(s.time_s, 1e-3);
  ASSERT_TRUE(dev.deactivate().ok());
  EXPECT_EQ(dev.read(s).code, StatusCode::kNotActive);
}

}  // namespace
}  // namespace teleop::device
