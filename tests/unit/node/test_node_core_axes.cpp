// NodeCoreAxes, the RT step of an n-axis node, with simulated n-axis devices (n = 3, Cartesian,
// exact positions) and a fake clock: peer states handed over by hand as the link threads would.
// Expected values come from statics solved here (Eigen's linear solver on the equilibrium
// equations written out below, and a hand derivation), the timeout and linear safe
// ramp, and the one-axis NodeCore at n = 1, never from the code under test.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <cstring>
#include <tuple>
#include <vector>

#include "common/device/sim_device.hpp"
#include "common/device/sim_device_axes.hpp"
#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"

namespace teleop::node {
namespace {

using namespace std::chrono_literals;
using control::AxisMatrix;
using control::AxisVector;
using transport::Role;

constexpr int kN = 3;
constexpr double kT = 1e-3;
constexpr double kAlpha = 2.0;  // slave moves twice the master's motion
constexpr double kBeta = 0.5;   // master feels half the slave's force
constexpr double kKp = 600.0;   // K_pm = K_ps = kKp I
constexpr double kKd = 2.0;     // K_dm = K_ds = kKd I
constexpr double kHumanK = 70.0;
constexpr double kPush = 1.5;  // N along the tilted direction d

Eigen::Vector3d tilted() { return Eigen::Vector3d(1.0, 2.0, 2.0) / 3.0; }

control::LawAxesParams law(int n, const control::PlaneSet& slave_planes) {
  control::LawAxesParams p;
  p.axes = n;
  p.period_s = kT;
  const AxisMatrix eye = AxisMatrix::Identity(n, n);
  const AxisMatrix zero = AxisMatrix::Zero(n, n);
  p.gains = control::LawGainsAxes{kKp * eye, kKp * eye, kKd * eye, kKd * eye, zero, zero, zero};
  p.scaling = Scaling{kAlpha, kBeta};
  p.slave_planes = slave_planes;
  p.master_actuator = control::no_actuator_limits(n);
  p.slave_actuator = control::no_actuator_limits(n);
  p.slave_limits = control::no_slave_limits(n);
  return p;
}

NodeAxesSettings settings(Role role, int n, const control::PlaneSet& planes = {}) {
  NodeAxesSettings s;
  s.role = role;
  s.period = 1ms;
  s.law = law(n, planes);
  s.machine.peer_timeout = 30ms;
  s.machine.engage_ramp = 20ms;
  s.safe_ramp = 10ms;
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;
  return s;
}

sim::PlantAxesParams plant(int n, double mass_kg, double damping_Ns_per_m) {
  sim::PlantAxesParams p;
  p.device.mass_kg = Eigen::MatrixXd::Identity(n, n) * mass_kg;
  p.device.damping_Ns_per_m = Eigen::VectorXd::Constant(n, damping_Ns_per_m);
  p.device.coulomb_N = Eigen::VectorXd::Zero(n);
  return p;
}

device::SimDeviceAxesConfig master_config(int n, const Eigen::VectorXd& start_m) {
  device::SimDeviceAxesConfig c;
  c.plant = plant(n, 0.05, 0.3);
  device::SimHumanAxes h;
  h.impedance.mass_kg = Eigen::MatrixXd::Identity(n, n) * 0.012;
  h.impedance.damping_Ns_per_m = Eigen::MatrixXd::Identity(n, n) * 0.76;
  h.impedance.stiffness_N_per_m = Eigen::MatrixXd::Identity(n, n) * kHumanK;
  h.set_point_m = Eigen::VectorXd::Zero(n);  // the hand's rest: the origin
  h.direction = Eigen::VectorXd::Zero(n);
  h.direction.head(std::min(n, 3)) = tilted().head(std::min(n, 3));
  h.direction.normalize();
  h.profile = sim::ForceProfile::constant(kPush);
  c.human = h;
  c.quantize_position = false;
  c.hold_scene_until_engaged = true;
  c.initial_position_m = start_m;
  return c;
}

device::SimDeviceAxesConfig slave_config(int n) {
  device::SimDeviceAxesConfig c;
  c.plant = plant(n, 0.1, 0.5);
  c.quantize_position = false;
  return c;
}

template <typename Device>
Device& init(Device& d) {
  EXPECT_TRUE(d.configure().ok());
  EXPECT_TRUE(d.activate().ok());
  return d;
}

// Two joined nodes: each cycle hands each side the state the other sent last cycle (arrived
// 0.3 ms after it was sent) unless that direction is silenced.
struct PairAxes {
  explicit PairAxes(int n = kN, const control::PlaneSet& planes = {},
                    Eigen::VectorXd master_start = {})
      : master_dev(
            master_config(n, master_start.size() == 0 ? Eigen::VectorXd::Zero(n) : master_start)),
        slave_dev(slave_config(n)),
        master(settings(Role::kMaster, n), init(master_dev)),
        slave(settings(Role::kSlave, n, planes), init(slave_dev)) {}

  void cycle() {
    now += 1ms;
    if (!master_silent && to_master.state.sequence != 0) {
      master.peer_in().write(to_master);
      master_last_arrival_ns = to_master.arrival_ns;
    }
    if (to_slave.state.sequence != 0) slave.peer_in().write(to_slave);
    master.step(now);
    slave.step(now);
    (void)master.state_out().read(to_slave.state);
    to_slave.arrival_ns = (now + 300us).count();
    (void)slave.state_out().read(to_master.state);
    to_master.arrival_ns = (now + 300us).count();
    while (auto r = master.telemetry_out().try_pop()) master_records.push_back(*r);
    while (auto r = slave.telemetry_out().try_pop()) slave_records.push_back(*r);
  }
  void command_both(Command c) {
    ASSERT_TRUE(master.post_command(c));
    ASSERT_TRUE(slave.post_command(c));
    cycle();
  }
  void engage() {
    for (int i = 0; i < 3; ++i) cycle();
    command_both(Command::kArm);
    command_both(Command::kEngage);
    for (int i = 0;
         i < 3000 && !(master.mode() == Mode::kEngaged && slave.mode() == Mode::kEngaged); ++i) {
      cycle();
    }
    ASSERT_EQ(master.mode(), Mode::kEngaged);
    ASSERT_EQ(slave.mode(), Mode::kEngaged);
  }
  [[nodiscard]] Eigen::Vector3d master_x() const {
    return master_dev.truth().state.position_m.head(3);
  }
  [[nodiscard]] Eigen::Vector3d slave_x() const {
    return slave_dev.truth().state.position_m.head(3);
  }

  device::SimDeviceAxes master_dev;
  device::SimDeviceAxes slave_dev;
  NodeCoreAxes master;
  NodeCoreAxes slave;
  std::chrono::nanoseconds now{1s};
  PeerSample to_master{};
  PeerSample to_slave{};
  std::int64_t master_last_arrival_ns{0};
  bool master_silent{false};
  std::vector<CycleRecordAxes> master_records;
  std::vector<CycleRecordAxes> slave_records;
};

// Statics of the engaged pair (velocities 0, weights 1, K_fm = 0, no friction), unknowns x_m and
// x_s (3 each), with the planes listed in contact:
//   master: d f - K_h x_m - beta K_pm (x_m - x_s / alpha) = 0   (hand set point at 0)
//   slave:  K_ps (alpha x_m - x_s) - sum_j K_j n_j (n_j^T x_s - p_j) = 0
struct Statics {
  Eigen::Vector3d x_m;
  Eigen::Vector3d x_s;
};
Statics solve_statics(const std::vector<control::Plane>& contact) {
  const Eigen::Matrix3d eye = Eigen::Matrix3d::Identity();
  Eigen::Matrix<double, 6, 6> a = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  a.block<3, 3>(0, 0) = -kHumanK * eye - kBeta * kKp * eye;
  a.block<3, 3>(0, 3) = kBeta * kKp / kAlpha * eye;
  b.head<3>() = -kPush * tilted();
  a.block<3, 3>(3, 0) = kKp * kAlpha * eye;
  a.block<3, 3>(3, 3) = -kKp * eye;
  for (const control::Plane& p : contact) {
    const Eigen::Vector3d n = p.normal.head(3);
    a.block<3, 3>(3, 3) -= p.stiffness_N_per_m * n * n.transpose();
    b.tail<3>() -= p.stiffness_N_per_m * p.offset_m * n;
  }
  const Eigen::Matrix<double, 6, 1> x = a.fullPivLu().solve(b);
  return Statics{x.head<3>(), x.tail<3>()};
}

// While aligning, every master record's command: F = -k (x_m - x_s / alpha) - b v_m, scaled as
// a whole to norm F_max when above it; the alignment error |alpha x_m - x_s|.
void check_centring(const std::vector<CycleRecordAxes>& records, std::size_t first,
                    bool& saw_clamp) {
  const AlignmentParams a{};
  for (std::size_t i = first; i < records.size(); ++i) {
    const CycleRecordAxes& r = records[i];
    if (r.mode != Mode::kAligning) continue;
    Eigen::Vector3d f;
    for (std::size_t j = 0; j < static_cast<std::size_t>(kN); ++j) {
      f(static_cast<Eigen::Index>(j)) =
          -a.centring_stiffness_N_per_m * (r.position_m[j] - r.peer_position_m[j] / kAlpha) -
          a.centring_damping_Ns_per_m * r.velocity_m_per_s[j];
    }
    if (f.norm() > a.centring_max_force_N) {
      f *= a.centring_max_force_N / f.norm();
      saw_clamp = true;
    }
    for (int j = 0; j < kN; ++j)
      ASSERT_NEAR(r.command_N[static_cast<std::size_t>(j)], f(j), 1e-12) << i;
    const Eigen::Vector3d gap =
        kAlpha * Eigen::Vector3d(r.position_m.data()) - Eigen::Vector3d(r.peer_position_m.data());
    ASSERT_NEAR(r.alignment_error_m, gap.norm(), 1e-15);
  }
}

TEST(NodeCoreAxes, AFarMasterFeelsTheCentringForceClampedInNormNotPerAxis) {
  // 30 mm off along (1, 1, 0)/sqrt 2: 30 N/m * 30 mm = 0.9 N > 0.5 N; clamped as a vector it is
  // 0.354 N on axes 0 and 1 (a per-axis clamp would leave 0.5 N on each).
  Eigen::VectorXd start = Eigen::Vector3d(1.0, 1.0, 0.0).normalized() * 0.030;
  PairAxes p(kN, {}, start);
  for (int i = 0; i < 3; ++i) p.cycle();
  p.command_both(Command::kArm);
  p.command_both(Command::kEngage);
  ASSERT_EQ(p.master.mode(), Mode::kAligning);
  const std::size_t first = p.master_records.size() - 1;
  for (int i = 0; i < 5000 && p.master.mode() != Mode::kEngaged; ++i) p.cycle();
  ASSERT_EQ(p.master.mode(), Mode::kEngaged);
  bool saw_clamp = false;
  ASSERT_NO_FATAL_FAILURE(check_centring(p.master_records, first, saw_clamp));
  EXPECT_TRUE(saw_clamp);
  const CycleRecordAxes& r = p.master_records[first + 1];
  EXPECT_NEAR(r.command_N[0], -0.5 / std::sqrt(2.0), 1e-3);
  EXPECT_NEAR(r.command_N[1], -0.5 / std::sqrt(2.0), 1e-3);
  EXPECT_NEAR(r.command_N[2], 0.0, 1e-12);
}

TEST(NodeCoreAxes, AlignsWithTheVectorCentringSpringThenTheSlaveFollowsAlphaTimesATiltedPush) {
  // The master starts 4 mm off along (1, 1, 0)/sqrt 2: |alpha x_m - x_s| = 8 mm > 2 mm.
  Eigen::VectorXd start = Eigen::Vector3d(1.0, 1.0, 0.0).normalized() * 0.004;
  PairAxes p(kN, {}, start);
  for (int i = 0; i < 3; ++i) p.cycle();
  p.command_both(Command::kArm);
  p.command_both(Command::kEngage);
  ASSERT_EQ(p.master.mode(), Mode::kAligning);
  const std::size_t first = p.master_records.size() - 1;
  for (int i = 0; i < 5000 && p.master.mode() != Mode::kEngaged; ++i) p.cycle();
  ASSERT_EQ(p.master.mode(), Mode::kEngaged);
  const AlignmentParams a{};
  bool saw_clamp = false;
  ASSERT_NO_FATAL_FAILURE(check_centring(p.master_records, first, saw_clamp));
  // 30 N/m * 4 mm = 0.12 N toward the slave (0.085 N on axis 0): weak, not clamped.
  EXPECT_FALSE(saw_clamp);
  EXPECT_GT(p.master_records[first + 1].command_N[0], -0.13);
  EXPECT_LT(p.master_records[first + 1].command_N[0], -0.05);
  // Engaged only within the tolerance.
  for (const CycleRecordAxes& r : p.master_records) {
    if (r.mode == Mode::kEngaged) {
      EXPECT_LE(r.alignment_error_m, a.tolerance_m);
      break;
    }
  }
  // The slave engages on the master's engaged state (one cycle later). The scene starts at
  // engagement: the push along d; 1.5 s to settle.
  p.cycle();
  ASSERT_EQ(p.slave.mode(), Mode::kEngaged);
  for (int i = 0; i < 1500; ++i) p.cycle();
  ASSERT_EQ(p.master.mode(), Mode::kEngaged);
  // The statics (no contact; the hand's set point at the origin): x_s = alpha x_m and
  // x_m = d f / K_h (the coupling carries no static force without friction).
  const Statics s = solve_statics({});
  EXPECT_NEAR((s.x_m - kPush / kHumanK * tilted()).norm(), 0.0, 1e-12);
  const Eigen::Vector3d x_m = p.master_x();
  const Eigen::Vector3d x_s = p.slave_x();
  EXPECT_LT((x_m - s.x_m).norm(), 2e-5) << x_m.transpose();
  // The slave sits at alpha x_m; its displacement is along d.
  EXPECT_LT((x_s - kAlpha * x_m).norm(), 2e-5) << x_s.transpose();
  EXPECT_NEAR(x_s.normalized().dot(tilted()), 1.0, 1e-6);
  EXPECT_NEAR(x_s.norm(), kAlpha * kPush / kHumanK, 2e-5);
  // The published state carries the three axes.
  const transport::NodeStateRecord& sent = p.to_master.state;
  EXPECT_EQ(sent.axes, kN);
  EXPECT_EQ(sent.positions_m[0], sent.position_m);
}

control::PlaneSet one_plane(const control::Plane& plane) {
  control::PlaneSet set;
  set.add(plane);
  return set;
}

// A plane the free slave would cross: normal (0, 0.6, 0.8); the free slave is at alpha d f / K_h
// = 42.9 mm along d, n^T d = 14/15, so 40 mm along n: a plane at 20 mm is crossed by 20 mm.
control::Plane slave_plane() {
  control::Plane plane;
  plane.normal = AxisVector::Zero(kN);
  plane.normal << 0.0, 0.6, 0.8;
  plane.offset_m = 0.020;
  plane.stiffness_N_per_m = 2000.0;
  return plane;
}

TEST(NodeCoreAxes, TheSlaveStopsAtItsPlaneWithTheStaticPenetration) {
  const control::Plane plane = slave_plane();
  PairAxes p(kN, one_plane(plane));
  ASSERT_NO_FATAL_FAILURE(p.engage());
  for (int i = 0; i < 1500; ++i) p.cycle();
  ASSERT_EQ(p.slave.mode(), Mode::kEngaged);
  const Statics s = solve_statics({plane});
  const Eigen::Vector3d n = plane.normal.head(3);
  const double expected_pen = n.dot(s.x_s) - plane.offset_m;
  // By hand, with isotropic gains: the slave's spring balances the plane, x_s = alpha x_m -
  // (K pen / k_ps) n, and the master's hand the coupling, x_m = (d f - c pen n) / K_h with
  // c = beta k_pm K / (alpha k_ps); so pen (1 + beta k_pm K / (k_ps K_h) + K / k_ps) =
  // alpha f n^T d / K_h - p.
  const double k = plane.stiffness_N_per_m;
  const double by_hand = (kAlpha * kPush * n.dot(tilted()) / kHumanK - plane.offset_m) /
                         (1.0 + kBeta * kKp * k / (kKp * kHumanK) + k / kKp);
  EXPECT_NEAR(expected_pen, by_hand, 1e-12);
  EXPECT_GT(expected_pen, 0.001);  // in contact, some millimetres in
  const Eigen::Vector3d x_s = p.slave_x();
  EXPECT_NEAR(n.dot(x_s) - plane.offset_m, expected_pen, 2e-5);
  EXPECT_LT((x_s - s.x_s).norm(), 3e-5);
  EXPECT_LT((p.master_x() - s.x_m).norm(), 3e-5);
  // The slave reports its contact (telemetry and state).
  EXPECT_NEAR(p.slave_records.back().fixture_penetration_m, expected_pen, 2e-5);
  const transport::NodeStateRecord& sent = p.to_master.state;
  EXPECT_TRUE(sent.fixture_in_contact);
  EXPECT_NEAR(sent.fixture_penetration_m, expected_pen, 2e-5);
}

// The slave's static penetration into `plane` at stiffness k, by hand (the derivation in
// TheSlaveStopsAtItsPlaneWithTheStaticPenetration).
double penetration_by_hand(const control::Plane& plane, double k) {
  const Eigen::Vector3d n = plane.normal.head(3);
  return (kAlpha * kPush * n.dot(tilted()) / kHumanK - plane.offset_m) /
         (1.0 + kBeta * kKp * k / (kKp * kHumanK) + k / kKp);
}

// A guarded change to both nodes (the supervisor's RETUNE): nothing moves before the agreed
// master sequence, then every value ramps linearly over the ramp -- the plane from 2000 to
// 800 N/m, K_dm and K_ds from 2 I to 4 I -- on both nodes, each by the master sequence it sees;
// the pair then settles at the hand-solved penetration of the new plane.
TEST(NodeCoreAxes, AGuardedChangeAppliesAtTheMasterSequenceRampsLinearlyAndMovesTheStatics) {
  const control::Plane plane = slave_plane();
  PairAxes p(kN, one_plane(plane));
  ASSERT_NO_FATAL_FAILURE(p.engage());
  for (int i = 0; i < 1500; ++i) p.cycle();
  const double k_from = plane.stiffness_N_per_m;
  const double k_to = 800.0;
  EXPECT_NEAR(p.slave_records.back().fixture_penetration_m, penetration_by_hand(plane, k_from),
              2e-5);
  ActiveLawAxes master_active{};
  ActiveLawAxes slave_active{};
  ASSERT_TRUE(p.master.active_out().read(master_active));  // as built
  ASSERT_TRUE(p.slave.active_out().read(slave_active));
  EXPECT_EQ(master_active.change_id, 0U);
  EXPECT_EQ(slave_active.slave_planes, 1);
  EXPECT_EQ(slave_active.slave_planes_N_per_m[0], k_from);

  // By hand, row-major 3 x 3: kpm = kps = 600 I, kdm = kds = 4 I, the rest 0.
  RetuneAxes r;
  r.id = 7;
  for (int i = 0; i < kN; ++i) {
    const auto d = static_cast<std::size_t>(i * kN + i);
    r.gains[0][d] = kKp;
    r.gains[1][d] = kKp;
    r.gains[2][d] = 4.0;
    r.gains[3][d] = 4.0;
  }
  r.slave_planes_N_per_m[0] = k_to;
  const std::uint64_t at = p.master_records.back().sequence + 20;
  r.apply_at_master_sequence = at;
  r.ramp = 100ms;
  p.master.post_retune(r);
  p.slave.post_retune(r);
  // Each node's value in force at each master sequence it ran at.
  struct Seen {
    std::uint64_t master_sequence;
    ActiveLawAxes active;
  };
  std::vector<Seen> master_seen;
  std::vector<Seen> slave_seen;
  for (int i = 0; i < 200; ++i) {
    p.cycle();
    (void)p.master.active_out().read(master_active);
    (void)p.slave.active_out().read(slave_active);
    master_seen.push_back({p.master_records.back().master_sequence, master_active});
    slave_seen.push_back({p.slave_records.back().master_sequence, slave_active});
  }
  for (const std::vector<Seen>* seen : {&master_seen, &slave_seen}) {
    int ramped = 0;
    for (const Seen& s : *seen) {
      const ActiveLawAxes& a = s.active;
      // The slave's law has the plane (this test's master is built without it).
      const bool has_plane = a.slave_planes == 1;
      if (s.master_sequence < at) {
        ASSERT_EQ(a.change_id, 0U);
        if (has_plane) {
          ASSERT_EQ(a.slave_planes_N_per_m[0], k_from);
        }
        ASSERT_EQ(a.gains[3][0], kKd);
        continue;
      }
      // 1 ms a cycle: j cycles after the switch the ramp is j / 100 of the way.
      const double w = std::min(1.0, static_cast<double>(s.master_sequence - at) / 100.0);
      ASSERT_EQ(a.change_id, 7U);
      ASSERT_EQ(a.applied_at_master_sequence, at);
      if (has_plane) {
        ASSERT_NEAR(a.slave_planes_N_per_m[0], k_from + w * (k_to - k_from), 1e-9);
      }
      ASSERT_NEAR(a.gains[2][0], kKd + w * (4.0 - kKd), 1e-12);
      ASSERT_NEAR(a.gains[3][4], kKd + w * (4.0 - kKd), 1e-12);
      ASSERT_NEAR(a.gains[1][8], kKp, 1e-12);
      ASSERT_EQ(a.gains[1][1], 0.0);
      ASSERT_NEAR(a.ramp_progress, w, 1e-12);
      if (s.master_sequence == at + 25) {  // a quarter: 2000 - 300 N/m, 2.5 Ns/m
        if (has_plane) {
          EXPECT_NEAR(a.slave_planes_N_per_m[0], 1700.0, 1e-9);
        }
        EXPECT_NEAR(a.gains[3][8], 2.5, 1e-12);
        ++ramped;
      }
    }
    EXPECT_EQ(ramped, 1);
    EXPECT_EQ(seen->back().active.ramp_progress, 1.0);
  }
  EXPECT_EQ(p.master.active_change_id(), 7U);
  EXPECT_EQ(p.to_master.state.parameter_change_id, 7U);
  EXPECT_EQ(p.to_slave.state.parameter_change_id, 7U);
  for (int i = 0; i < 1500; ++i) p.cycle();
  ASSERT_EQ(p.slave.mode(), Mode::kEngaged);
  const double deeper = penetration_by_hand(plane, k_to);
  EXPECT_GT(deeper - penetration_by_hand(plane, k_from), 0.001);  // a softer plane: 1.4 mm deeper
  EXPECT_NEAR(p.slave_records.back().fixture_penetration_m, deeper, 2e-5);
}

TEST(NodeCoreAxes, ASilentPeerPutsTheMasterInSafeWithinTheTimeoutAndItsForceRampsToZero) {
  PairAxes p(kN, one_plane(slave_plane()));  // in contact: the master feels a force
  ASSERT_NO_FATAL_FAILURE(p.engage());
  for (int i = 0; i < 800; ++i) p.cycle();
  const std::size_t before = p.master_records.size();
  const Eigen::Vector3d last(p.master_records.back().command_N.data());
  ASSERT_GT(last.norm(), 0.1);
  p.master_silent = true;
  const std::int64_t last_arrival = p.master_last_arrival_ns;
  for (int i = 0; i < 100; ++i) p.cycle();
  const std::int64_t timeout_ns = std::chrono::nanoseconds(30ms).count();
  const std::int64_t ramp_ns = std::chrono::nanoseconds(10ms).count();
  std::size_t safe_at = 0;
  for (std::size_t i = before; i < p.master_records.size(); ++i) {
    const CycleRecordAxes& r = p.master_records[i];
    if (r.mode == Mode::kSafe) {
      safe_at = i;
      break;
    }
    // Coupled while the newest state is within the timeout.
    ASSERT_EQ(r.mode, Mode::kEngaged) << i;
    ASSERT_LE(r.clock_ns - last_arrival, timeout_ns) << i;
  }
  ASSERT_GT(safe_at, before);
  const CycleRecordAxes& first_safe = p.master_records[safe_at];
  EXPECT_GT(first_safe.clock_ns - last_arrival, timeout_ns);
  EXPECT_LE(first_safe.clock_ns - last_arrival, timeout_ns + 1'000'000);
  // Each axis ramps linearly from the last command written to 0 over the safe ramp.
  const Eigen::Vector3d from(p.master_records[safe_at - 1].command_N.data());
  ASSERT_GT(from.norm(), 0.1);
  for (std::size_t i = safe_at; i < p.master_records.size(); ++i) {
    const CycleRecordAxes& r = p.master_records[i];
    ASSERT_EQ(r.mode, Mode::kSafe);
    const double w = std::clamp(
        1.0 - static_cast<double>(r.clock_ns - first_safe.clock_ns) / static_cast<double>(ramp_ns),
        0.0, 1.0);
    for (int j = 0; j < kN; ++j) {
      ASSERT_NEAR(r.command_N[static_cast<std::size_t>(j)], from(j) * w, 1e-12) << i;
    }
  }
  EXPECT_EQ(Eigen::Vector3d(p.master_records.back().command_N.data()).norm(), 0.0);
  // The slave, seeing the master in safe, goes safe and holds where it is.
  EXPECT_EQ(p.slave.mode(), Mode::kSafe);
}

TEST(NodeCoreAxes, AnEStopOnTheSlaveFaultsItWithZeroForceAndPutsTheMasterInSafe) {
  PairAxes p(kN, one_plane(slave_plane()));
  ASSERT_NO_FATAL_FAILURE(p.engage());
  for (int i = 0; i < 300; ++i) p.cycle();
  const std::size_t before = p.slave_records.size();
  p.slave_dev.set_estop(true);
  for (int i = 0; i < 50; ++i) p.cycle();
  EXPECT_EQ(p.slave.mode(), Mode::kFault);
  EXPECT_EQ(p.master.mode(), Mode::kSafe);
  // From the first sample with the fault flag on, 0 N on every axis.
  for (std::size_t i = before + 1; i < p.slave_records.size(); ++i) {
    const CycleRecordAxes& r = p.slave_records[i];
    ASSERT_NE(r.flags & device::SampleFlags::kFault, 0U) << i;
    for (std::size_t j = 0; j < static_cast<std::size_t>(kN); ++j)
      ASSERT_EQ(r.command_N[j], 0.0) << i;
  }
}

TEST(NodeCoreAxes, AOneAxisPeerIsRejectedAndNeverEngages) {
  // A one-axis NodeCore master (one-axis simulated paddle) and a three-axis slave.
  NodeSettings ms;
  ms.role = Role::kMaster;
  ms.period = 1ms;
  ms.law.period_s = kT;
  ms.law.gains = Gains{600, 600, 2, 2, 0, 0, 0};
  ms.machine.peer_timeout = 30ms;
  ms.session_id = 11;
  ms.config_fingerprint = 0x5eed;
  sim::HumanParams h;
  h.impedance = HumanImpedance{0.012, 0.76, 70.0};
  device::SimDevice master_dev(device::SimDeviceConfig::paddle_master(h));
  NodeCore master(ms, init(master_dev));
  device::SimDeviceAxes slave_dev(slave_config(kN));
  NodeCoreAxes slave(settings(Role::kSlave, kN), init(slave_dev));
  PeerSample to_master{};
  PeerSample to_slave{};
  std::chrono::nanoseconds now = 1s;
  bool ever_coupled = false;
  auto cycle = [&] {
    now += 1ms;
    if (to_master.state.sequence != 0) master.peer_in().write(to_master);
    if (to_slave.state.sequence != 0) slave.peer_in().write(to_slave);
    master.step(now);
    slave.step(now);
    (void)master.state_out().read(to_slave.state);
    to_slave.arrival_ns = (now + 300us).count();
    (void)slave.state_out().read(to_master.state);
    to_master.arrival_ns = (now + 300us).count();
    ever_coupled = ever_coupled || slave.mode() == Mode::kEngaged ||
                   slave.mode() == Mode::kAligning || master.mode() == Mode::kEngaged;
    while (slave.telemetry_out().try_pop()) {
    }
    while (master.telemetry_out().try_pop()) {
    }
  };
  for (int i = 0; i < 3; ++i) cycle();
  ASSERT_EQ(to_slave.state.axes, 1);
  for (const Command c : {Command::kArm, Command::kEngage}) {
    ASSERT_TRUE(master.post_command(c));
    ASSERT_TRUE(slave.post_command(c));
    cycle();
  }
  for (int i = 0; i < 500; ++i) cycle();
  EXPECT_FALSE(ever_coupled);
  EXPECT_EQ(slave.mode(), Mode::kDisarmed);
  EXPECT_GE(slave.peer_wrong_axes(), 500U);
  EXPECT_GE(slave.coupling_refusals(), 1U);
  EXPECT_STREQ(slave.last_coupling_refusal(),
               "arm and engage refused: the peer has another number of task-space axes");
  // The slave never took a state: it published no peer sequence and wrote 0 N throughout.
  EXPECT_EQ(to_master.state.axes, kN);
  EXPECT_EQ(to_master.state.last_peer_sequence, 0U);
  EXPECT_EQ(slave_dev.truth().applied_force_N.norm(), 0.0);
}

TEST(NodeCoreAxes, RefusesALawOfAnotherAxisCountThanTheDevice) {
  device::SimDeviceAxes dev(slave_config(2));
  init(dev);
  try {
    NodeCoreAxes node(settings(Role::kSlave, kN), dev);
    FAIL() << "accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("law.axes"), std::string::npos) << e.what();
  }
}

// ---- n = 1: NodeCoreAxes is NodeCore, bit for bit ---------------------------------------------

// A one-axis body both fakes below share, so both nodes see the same physics: a mass with
// damping, pushed by the command, a hand's push from engagement on (master) or a wall at 6 mm
// (slave: the load cell reads the force the body puts on it). Semi-implicit Euler per period.
struct Body {
  bool master{true};
  double x_m{0.0};
  double v_m_per_s{0.0};
  double command_N{0.0};
  bool pushing{false};
  int steps{0};
  [[nodiscard]] double wall_N() const {
    return !master && x_m > 0.006 ? 800.0 * (x_m - 0.006) : 0.0;
  }
  void tick() {
    ++steps;
    const double push_N = master && pushing ? 0.8 * std::sin(2.0 * steps * kT) + 0.4 : 0.0;
    const double hold_N = master ? -40.0 * x_m : 0.0;  // the hand's own spring about 0
    const double a = (command_N + push_N + hold_N - wall_N() - 0.4 * v_m_per_s) / 0.06;
    v_m_per_s += a * kT;
    x_m += v_m_per_s * kT;
  }
};

class FakeDevice final : public device::HapticDevice {
 public:
  explicit FakeDevice(Body b) : body(b) {}
  device::Status configure() override { return device::Status::Ok(); }
  device::Status activate() override { return device::Status::Ok(); }
  device::Status deactivate() override { return device::Status::Ok(); }
  device::Status read(device::Sample& s) noexcept override {
    s.position_m = body.x_m;
    s.force_N = body.wall_N();
    return device::Status::Ok();
  }
  device::Status write(const device::Command& c) noexcept override {
    body.command_N = c.force_N;
    return device::Status::Ok();
  }
  device::Status tick(std::chrono::nanoseconds) noexcept override {
    body.tick();
    return device::Status::Ok();
  }
  void on_engaged() noexcept override { body.pushing = true; }
  Body body;
};

class FakeDeviceAxes final : public device::HapticDeviceAxes {
 public:
  explicit FakeDeviceAxes(Body b) : body(b) {}
  device::Status configure() override { return device::Status::Ok(); }
  device::Status activate() override { return device::Status::Ok(); }
  device::Status deactivate() override { return device::Status::Ok(); }
  [[nodiscard]] int axes() const noexcept override { return 1; }
  device::Status read(device::SampleAxes& s) noexcept override {
    s.axes = 1;
    s.position_m = device::AxisVector::Constant(1, body.x_m);
    s.force_N = device::AxisVector::Constant(1, body.wall_N());
    return device::Status::Ok();
  }
  device::Status write(const device::CommandAxes& c) noexcept override {
    body.command_N = c.force_N(0);
    return device::Status::Ok();
  }
  device::Status tick(std::chrono::nanoseconds) noexcept override {
    body.tick();
    return device::Status::Ok();
  }
  void on_engaged() noexcept override { body.pushing = true; }
  Body body;
};

NodeSettings one_axis_settings(Role role) {
  NodeSettings s;
  s.role = role;
  s.period = 1ms;
  s.law.period_s = kT;
  s.law.gains = Gains{500, 700, 2, 3, 0.1, 0.2, 0.3};
  s.law.scaling = Scaling{kAlpha, kBeta};
  s.law.slave_fixture = FixtureParams{1500.0, 0.004};
  s.law.velocity_cutoff_hz = 200.0;
  s.machine.peer_timeout = 30ms;
  s.machine.engage_ramp = 20ms;
  s.safe_ramp = 10ms;
  s.session_id = role == Role::kMaster ? 11 : 22;
  s.config_fingerprint = 0x5eed;
  return s;
}

NodeAxesSettings as_axes(const NodeSettings& one) {
  NodeAxesSettings s;
  s.role = one.role;
  s.period = one.period;
  s.law = control::to_law_axes(one.law);
  s.machine = one.machine;
  s.safe_ramp = one.safe_ramp;
  s.alignment = one.alignment;
  s.session_id = one.session_id;
  s.config_fingerprint = one.config_fingerprint;
  return s;
}

// Two pairs, one of NodeCore and one of NodeCoreAxes at n = 1, each on its own copy of the same
// bodies, through aligning (the master 5 mm off), engaged with the push and the slave on its
// fixture and wall, clutch and unclutch, and a silent link into safe: every command, mode and
// published state is the same double.
TEST(NodeCoreAxes, OneAxisIsNodeCoreBitForBit) {
  const Body master_body{true, 0.005};
  const Body slave_body{false, 0.0};
  FakeDevice m1(master_body);
  FakeDevice s1(slave_body);
  FakeDeviceAxes mn(master_body);
  FakeDeviceAxes sn(slave_body);
  NodeCore master1(one_axis_settings(Role::kMaster), m1);
  NodeCore slave1(one_axis_settings(Role::kSlave), s1);
  NodeCoreAxes master_n(as_axes(one_axis_settings(Role::kMaster)), mn);
  NodeCoreAxes slave_n(as_axes(one_axis_settings(Role::kSlave)), sn);
  PeerSample to_m1{}, to_s1{}, to_mn{}, to_sn{};
  std::chrono::nanoseconds now = 1s;
  bool silent = false;
  int engaged = 0, clutched = 0, safe = 0;
  auto cycle = [&] {
    now += 1ms;
    if (!silent && to_m1.state.sequence != 0) master1.peer_in().write(to_m1);
    if (!silent && to_mn.state.sequence != 0) master_n.peer_in().write(to_mn);
    if (to_s1.state.sequence != 0) slave1.peer_in().write(to_s1);
    if (to_sn.state.sequence != 0) slave_n.peer_in().write(to_sn);
    master1.step(now);
    slave1.step(now);
    master_n.step(now);
    slave_n.step(now);
    for (auto [one, n, to_one, to_n] : {std::tuple{&master1, &master_n, &to_s1, &to_sn},
                                        std::tuple{&slave1, &slave_n, &to_m1, &to_mn}}) {
      (void)one->state_out().read(to_one->state);
      (void)n->state_out().read(to_n->state);
      to_one->arrival_ns = to_n->arrival_ns = (now + 300us).count();
      const transport::NodeStateRecord& a = to_one->state;
      const transport::NodeStateRecord& b = to_n->state;
      ASSERT_EQ(a.mode, b.mode);
      ASSERT_EQ(a.position_m, b.position_m);
      ASSERT_EQ(a.velocity_m_per_s, b.velocity_m_per_s);
      ASSERT_EQ(a.force_N, b.force_N);
      ASSERT_EQ(a.clutched, b.clutched);
      ASSERT_EQ(a.fixture_in_contact, b.fixture_in_contact);
      ASSERT_EQ(a.fixture_penetration_m, b.fixture_penetration_m);
      ASSERT_EQ(a.fixture_force_N, b.fixture_force_N);
      const auto r1 = one->telemetry_out().try_pop();
      const auto rn = n->telemetry_out().try_pop();
      ASSERT_TRUE(r1 && rn);
      ASSERT_EQ(r1->command_N, rn->command_N[0]) << r1->sequence;
      ASSERT_EQ(r1->coupling_weight, rn->coupling_weight);
      ASSERT_EQ(r1->flags, rn->flags);
      ASSERT_EQ(std::abs(r1->alignment_error_m), rn->alignment_error_m);
    }
    engaged += master_n.mode() == Mode::kEngaged;
    clutched += master_n.mode() == Mode::kClutched;
    safe += master_n.mode() == Mode::kSafe;
  };
  auto all = [&](Command c) {
    for (bool ok : {master1.post_command(c), slave1.post_command(c), master_n.post_command(c),
                    slave_n.post_command(c)}) {
      ASSERT_TRUE(ok);
    }
  };
  for (int i = 0; i < 3; ++i) ASSERT_NO_FATAL_FAILURE(cycle());
  all(Command::kArm);
  ASSERT_NO_FATAL_FAILURE(cycle());
  all(Command::kEngage);
  for (int i = 0; i < 1500; ++i) ASSERT_NO_FATAL_FAILURE(cycle());
  ASSERT_TRUE(master1.post_command(Command::kClutch) && master_n.post_command(Command::kClutch));
  for (int i = 0; i < 200; ++i) ASSERT_NO_FATAL_FAILURE(cycle());
  ASSERT_TRUE(master1.post_command(Command::kUnclutch) &&
              master_n.post_command(Command::kUnclutch));
  for (int i = 0; i < 500; ++i) ASSERT_NO_FATAL_FAILURE(cycle());
  silent = true;
  for (int i = 0; i < 100; ++i) ASSERT_NO_FATAL_FAILURE(cycle());
  // Every phase was visited, and the bodies moved alike.
  EXPECT_GT(engaged, 1000);
  EXPECT_GT(clutched, 100);
  EXPECT_GT(safe, 50);
  EXPECT_GT(std::abs(s1.body.x_m), 0.004);  // on its fixture
  EXPECT_EQ(m1.body.x_m, mn.body.x_m);
  EXPECT_EQ(s1.body.x_m, sn.body.x_m);
}

}  // namespace
}  // namespace teleop::node
