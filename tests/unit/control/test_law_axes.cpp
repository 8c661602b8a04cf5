// The n-axis law (common/control/law_axes.hpp) at n = 3: diagonal gains and axis-aligned planes
// are three independent one-axis laws (each axis against a MasterLaw/SlaveLaw on that axis's
// numbers); full gain matrices against hand-computed products; per-axis limits; the clutch's
// vector offset; one bad component latching every axis; validation messages naming the field.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <string>

#include "common/control/law_axes.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"

namespace teleop::control {
namespace {

constexpr double kT = 1e-3;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

AxisVector vec3(double a, double b, double c) {
  AxisVector v(3);
  v << a, b, c;
  return v;
}

AxisMatrix mat3(std::array<double, 9> e) {
  AxisMatrix m(3, 3);
  m << e[0], e[1], e[2], e[3], e[4], e[5], e[6], e[7], e[8];
  return m;
}

AxisVector unit(int axis) {
  AxisVector v = AxisVector::Zero(3);
  v(axis) = 1.0;
  return v;
}

// Three axes, every gain 0, unit scaling, no planes, no limits, no fade, T = 1 ms.
LawAxesParams bare3() {
  LawAxesParams p;
  p.axes = 3;
  p.period_s = kT;
  const AxisMatrix z = AxisMatrix::Zero(3, 3);
  p.gains = {z, z, z, z, z, z, z};
  p.master_actuator = no_actuator_limits(3);
  p.slave_actuator = no_actuator_limits(3);
  p.slave_limits = no_slave_limits(3);
  p.clutch_fade_s = 0.0;
  return p;
}

PeerStateAxes peer3(const AxisVector& x, const AxisVector& v, const AxisVector& f) {
  return {x, v, f, false, true};
}

// One-axis laws, one per axis, with these numbers.
LawParams axis_params(int i) {
  const double s = 1.0 + 0.5 * i;
  LawParams p;
  p.period_s = kT;
  p.gains = {.kpm = 300.0 * s,
             .kps = 450.0 / s,
             .kdm = 3.0 * s,
             .kds = 4.0 + i,
             .kvm = 0.5 * i,
             .kvs = 1.0 + 0.25 * i,
             .kfm = 0.3 * s};
  p.scaling = {.position = 1.5, .force = 0.8};
  p.master_fixture = {700.0 + 100.0 * i, 0.003 * (i + 1)};
  p.slave_fixture = {i == 1 ? 0.0 : 900.0, -0.002 + 0.004 * i};
  p.velocity_cutoff_hz = 150.0;
  p.master_actuator = {3.0 + i, 1500.0 + 500.0 * i};
  p.slave_actuator = {5.0 - i, 2500.0};
  p.slave_limits.max_force_N = 3.5 + i;
  p.clutch_fade_s = 0.015;
  return p;
}

// The same three laws as one 3-axis law: diagonal gains, plane i with normal e_i.
LawAxesParams diagonal_params(const std::array<LawParams, 3>& one) {
  LawAxesParams p = bare3();
  p.scaling = one[0].scaling;
  p.velocity_cutoff_hz = one[0].velocity_cutoff_hz;
  p.clutch_fade_s = one[0].clutch_fade_s;
  const auto diag = [&](double Gains::*g) {
    AxisMatrix m = AxisMatrix::Zero(3, 3);
    for (int i = 0; i < 3; ++i) m(i, i) = one[static_cast<std::size_t>(i)].gains.*g;
    return m;
  };
  p.gains = {diag(&Gains::kpm), diag(&Gains::kps), diag(&Gains::kdm), diag(&Gains::kds),
             diag(&Gains::kvm), diag(&Gains::kvs), diag(&Gains::kfm)};
  for (std::size_t i = 0; i < 3; ++i) {
    const auto a = static_cast<Eigen::Index>(i);
    const int axis = static_cast<int>(i);
    p.master_planes.add(
        {unit(axis), one[i].master_fixture.position_m, one[i].master_fixture.stiffness_N_per_m});
    p.slave_planes.add(
        {unit(axis), one[i].slave_fixture.position_m, one[i].slave_fixture.stiffness_N_per_m});
    p.master_actuator.max_force_N(a) = one[i].master_actuator.max_force_N;
    p.master_actuator.max_rate_N_per_s(a) = one[i].master_actuator.max_rate_N_per_s;
    p.slave_actuator.max_force_N(a) = one[i].slave_actuator.max_force_N;
    p.slave_actuator.max_rate_N_per_s(a) = one[i].slave_actuator.max_rate_N_per_s;
    p.slave_limits.max_force_N(a) = one[i].slave_limits.max_force_N;
  }
  return p;
}

TEST(LawAxes, DiagonalGainsAreThreeIndependentAxes) {
  const std::array<LawParams, 3> one = {axis_params(0), axis_params(1), axis_params(2)};
  std::array<MasterLaw, 3> m1 = {MasterLaw(one[0]), MasterLaw(one[1]), MasterLaw(one[2])};
  std::array<SlaveLaw, 3> s1 = {SlaveLaw(one[0]), SlaveLaw(one[1]), SlaveLaw(one[2])};
  const LawAxesParams axes = diagonal_params(one);
  MasterLawAxes mn(axes);
  SlaveLawAxes sn(axes);

  std::mt19937_64 rng(3);
  std::normal_distribution<double> step(0.0, 3e-4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  AxisVector xm = AxisVector::Zero(3);
  AxisVector xs = vec3(0.002, -0.001, 0.004);
  std::array<PeerState, 3> to_s1{};
  std::array<PeerState, 3> to_m1{};
  PeerStateAxes to_sn;
  PeerStateAxes to_mn;
  bool link_down = false;
  int saturated = 0;
  int inside = 0;
  for (int k = 0; k < 6000; ++k) {
    for (int i = 0; i < 3; ++i) {
      xm(i) = 0.999 * xm(i) + step(rng);
      xs(i) = 0.999 * xs(i) + step(rng);
    }
    const AxisVector fe = vec3(u(rng) - 0.5, 2.0 * u(rng) - 1.0, 0.3);
    if (u(rng) < 1.0 / 250.0) {
      const bool engage = !mn.clutch_engaged();
      mn.set_clutch(engage);
      for (MasterLaw& m : m1) m.set_clutch(engage);
    }
    if (u(rng) < 1.0 / 400.0) link_down = !link_down;
    PeerStateAxes to_master = to_mn;
    if (link_down) to_master.valid = false;
    const CommandAxes cm = mn.step(xm, to_master);
    const CommandAxes cs = sn.step(xs, fe, to_sn);
    for (std::size_t i = 0; i < 3; ++i) {
      const auto a = static_cast<Eigen::Index>(i);
      PeerState to_master_i = to_m1[i];
      if (link_down) to_master_i.valid = false;
      const Command c1m = m1[i].step(xm(a), to_master_i);
      const Command c1s = s1[i].step(xs(a), fe(a), to_s1[i]);
      ASSERT_EQ(cm.force_N(a), c1m.force_N) << "master axis " << i << " step " << k;
      ASSERT_EQ(cm.fixture_force_N(a), c1m.fixture_force_N) << "axis " << i << " step " << k;
      ASSERT_EQ(((cm.saturated_axes >> i) & 1U) != 0, c1m.flags.saturated) << i << " " << k;
      ASSERT_EQ(((cm.rate_limited_axes >> i) & 1U) != 0, c1m.flags.rate_limited) << k;
      ASSERT_EQ(cs.force_N(a), c1s.force_N) << "slave axis " << i << " step " << k;
      ASSERT_EQ(cs.fixture_force_N(a), c1s.fixture_force_N) << "axis " << i << " step " << k;
      ASSERT_EQ(((cs.saturated_axes >> i) & 1U) != 0, c1s.flags.saturated) << i << " " << k;
      to_s1[i] = m1[i].peer_state();
      to_m1[i] = s1[i].peer_state();
      ASSERT_EQ(mn.peer_state().position_m(a), to_s1[i].position_m) << i << " " << k;
      ASSERT_EQ(sn.peer_state().velocity_m_per_s(a), to_m1[i].velocity_m_per_s) << i << " " << k;
      saturated += c1m.flags.saturated + c1s.flags.saturated;
      inside += c1m.penetration_m > 0.0;
    }
    to_sn = mn.peer_state();
    to_mn = sn.peer_state();
  }
  EXPECT_GT(saturated, 50);  // the per-axis limits did act
  EXPECT_GT(inside, 50);     // and the planes
}

TEST(LawAxes, FullPositionGainMatrixByHand) {
  // K_pm = [100 20 0; 20 200 -10; 0 -10 300] N/m, alpha = 2, beta = 0.5, x_m = (0.01, -0.02,
  // 0.03), x_s = (0.02, 0.02, -0.04): x_m - x_s/alpha = (0, -0.03, 0.05) m,
  // K_pm (..) = (20 (-0.03), 200 (-0.03) - 10 (0.05), -10 (-0.03) + 300 (0.05))
  //           = (-0.6, -6.5, 15.3) N, times beta: (-0.3, -3.25, 7.65) N.
  // Plus the master plane z > 0.02 (K = 500): penetration 0.01 m, F_mVF = (0, 0, 5) N. A second
  // plane (0.6, 0.8, 0)^T x > 0 is not entered (n^T x_m = -0.01). First sample: v_m = 0.
  LawAxesParams p = bare3();
  p.gains.kpm = mat3({100, 20, 0, 20, 200, -10, 0, -10, 300});
  p.scaling = {.position = 2.0, .force = 0.5};
  p.master_planes.add({unit(2), 0.02, 500.0});
  p.master_planes.add({vec3(0.6, 0.8, 0.0), 0.0, 1000.0});
  MasterLawAxes master(p);
  const CommandAxes c =
      master.step(vec3(0.01, -0.02, 0.03),
                  peer3(vec3(0.02, 0.02, -0.04), AxisVector::Zero(3), AxisVector::Zero(3)));
  EXPECT_NEAR(c.force_N(0), -0.3, 1e-12);
  EXPECT_NEAR(c.force_N(1), -3.25, 1e-12);
  EXPECT_NEAR(c.force_N(2), 7.65 + 5.0, 1e-12);
  EXPECT_NEAR(c.fixture_force_N(2), 5.0, 1e-12);
  EXPECT_EQ(c.fixture_force_N(0), 0.0);
  EXPECT_NEAR(c.penetration_m, 0.01, 1e-15);
  EXPECT_EQ(c.deepest_plane, 0);
}

TEST(LawAxes, FullDampingAndForceMatricesByHand) {
  // K_dm = [2 1 0; 0 3 0; 1 0 4] N s/m, K_fm = [0 0.5 0; 0 0 0; 0.5 0 0], alpha = 2,
  // beta = 0.5. The slave sits at alpha x_m (no position error). Sample 2 moves the master by
  // (0.001, 0, -0.001) m in T = 1 ms: v_m = (1, 0, -1) m/s; v_s = (0.2, 0.4, 0):
  // v_m - v_s/alpha = (0.9, -0.2, -1), K_dm (..) = (1.8 - 0.2, -0.6, 0.9 - 4) = (1.6, -0.6,
  // -3.1); F_e = (2, -4, 6): K_fm F_e = (-2, 0, 1). Sum (-0.4, -0.6, -2.1), times beta:
  // (-0.2, -0.3, -1.05) N.
  LawAxesParams p = bare3();
  p.gains.kdm = mat3({2, 1, 0, 0, 3, 0, 1, 0, 4});
  p.gains.kfm = mat3({0, 0.5, 0, 0, 0, 0, 0.5, 0, 0});
  p.scaling = {.position = 2.0, .force = 0.5};
  MasterLawAxes master(p);
  const AxisVector vs = vec3(0.2, 0.4, 0.0);
  const AxisVector fe = vec3(2.0, -4.0, 6.0);
  (void)master.step(AxisVector::Zero(3), peer3(AxisVector::Zero(3), vs, fe));
  const AxisVector x1 = vec3(0.001, 0.0, -0.001);
  const CommandAxes c = master.step(x1, peer3(2.0 * x1, vs, fe));
  EXPECT_NEAR(c.force_N(0), -0.2, 1e-12);
  EXPECT_NEAR(c.force_N(1), -0.3, 1e-12);
  EXPECT_NEAR(c.force_N(2), -1.05, 1e-12);
}

TEST(LawAxes, SlaveFullGainMatrixAndPlaneByHand) {
  // K_ps = [500 50 0; 50 400 0; 0 0 100] N/m, alpha = 2, x_m = (0.01, -0.02, 0.03):
  // x_r = (0.02, -0.04, 0.06); x_s = (0.02, 0.02, -0.04): x_r - x_s = (0, -0.06, 0.1),
  // K_ps (..) = (-3, -24, 10) N. Slave plane (0, 0.6, 0.8)^T x > -0.03 (K = 200):
  // n^T x_s = 0.012 - 0.032 = -0.02, penetration 0.01 m, F_sVF = 2 (0, 0.6, 0.8) =
  // (0, 1.2, 1.6) N, subtracted: (-3, -25.2, 8.4) N. No fade: the start-up mismatch is gone.
  LawAxesParams p = bare3();
  p.gains.kps = mat3({500, 50, 0, 50, 400, 0, 0, 0, 100});
  p.scaling = {.position = 2.0, .force = 1.0};
  p.slave_planes.add({vec3(0.0, 0.6, 0.8), -0.03, 200.0});
  SlaveLawAxes slave(p);
  const CommandAxes c =
      slave.step(vec3(0.02, 0.02, -0.04), AxisVector::Zero(3),
                 peer3(vec3(0.01, -0.02, 0.03), AxisVector::Zero(3), AxisVector::Zero(3)));
  EXPECT_NEAR(c.force_N(0), -3.0, 1e-12);
  EXPECT_NEAR(c.force_N(1), -25.2, 1e-12);
  EXPECT_NEAR(c.force_N(2), 8.4, 1e-12);
  EXPECT_NEAR(c.fixture_force_N(1), 1.2, 1e-12);
  EXPECT_NEAR(c.penetration_m, 0.01, 1e-15);
}

TEST(LawAxes, PerAxisLimits) {
  // K_pm = 1000 I, x_m - x_s = (0.01, -0.01, 0.01): requested (10, -10, 10) N. Saturation at
  // (1, 2, 3) N, then axis 1's rate limit 1000 N/s * 1 ms = 1 N from 0: (1, -1, 3).
  LawAxesParams p = bare3();
  p.gains.kpm = 1000.0 * AxisMatrix::Identity(3, 3);
  p.gains.kps = 100.0 * AxisMatrix::Identity(3, 3);
  p.master_actuator.max_force_N = vec3(1.0, 2.0, 3.0);
  p.master_actuator.max_rate_N_per_s = vec3(kNoLimit, 1000.0, kNoLimit);
  p.slave_limits.max_force_N = vec3(kNoLimit, 0.5, kNoLimit);
  MasterLawAxes master(p);
  const AxisVector zero = AxisVector::Zero(3);
  const CommandAxes c =
      master.step(vec3(0.01, -0.01, 0.01), peer3(AxisVector::Zero(3), zero, zero));
  EXPECT_EQ(c.force_N(0), 1.0);
  EXPECT_EQ(c.force_N(1), -1.0);
  EXPECT_EQ(c.force_N(2), 3.0);
  EXPECT_EQ(c.saturated_axes, 0b111U);
  EXPECT_EQ(c.rate_limited_axes, 0b010U);
  EXPECT_TRUE(c.flags.saturated);
  EXPECT_TRUE(c.flags.rate_limited);
  // Next sample, same request: axis 1 may move 1 N more, to -2 N.
  const CommandAxes c2 =
      master.step(vec3(0.01, -0.01, 0.01), peer3(AxisVector::Zero(3), zero, zero));
  EXPECT_EQ(c2.force_N(1), -2.0);
  EXPECT_EQ(c2.rate_limited_axes, 0U);  // exactly the allowed step

  // The slave force clamp on axis 1 only: K_ps (x_r - x_s) = 100 (0.002, 0.01, -0.003) =
  // (0.2, 1, -0.3) N, axis 1 clamped to 0.5 N.
  SlaveLawAxes slave(p);
  const CommandAxes s =
      slave.step(vec3(0.0, 0.0, 0.0), zero, peer3(vec3(0.002, 0.01, -0.003), zero, zero));
  EXPECT_NEAR(s.force_N(0), 0.2, 1e-15);
  EXPECT_EQ(s.force_N(1), 0.5);
  EXPECT_NEAR(s.force_N(2), -0.3, 1e-15);
  EXPECT_EQ(s.saturated_axes, 0b010U);
  EXPECT_TRUE(s.flags.saturated);
  EXPECT_FALSE(s.flags.rate_limited);
}

TEST(LawAxes, SlaveWorkspaceBox) {
  // Box [-0.01, 0.01] on every axis. The reference (0.004, 0.02, -0.003) leaves it on axis 1
  // only: clamped to 0.01 there, flags.reference_limited, K_ps = 100 I:
  // F = 100 ((0.004, 0.01, -0.003) - 0) = (0.4, 1, -0.3) N.
  LawAxesParams p = bare3();
  p.gains.kps = 100.0 * AxisMatrix::Identity(3, 3);
  p.gains.kds = 2.0 * AxisMatrix::Identity(3, 3);
  p.slave_limits.min_position_m = AxisVector::Constant(3, -0.01);
  p.slave_limits.max_position_m = AxisVector::Constant(3, 0.01);
  const AxisVector zero = AxisVector::Zero(3);
  SlaveLawAxes slave(p);
  const CommandAxes r = slave.step(zero, zero, peer3(vec3(0.004, 0.02, -0.003), zero, zero));
  EXPECT_TRUE(r.flags.reference_limited);
  EXPECT_FALSE(r.flags.limit_violation);
  EXPECT_NEAR(r.force_N(0), 0.4, 1e-15);
  EXPECT_NEAR(r.force_N(1), 1.0, 1e-15);
  EXPECT_NEAR(r.force_N(2), -0.3, 1e-15);

  // The slave itself outside on axis 2 (-0.012): the safe command on every axis,
  // K_ps (clamp(x) - x) - (K_ds + K_vs) v = (0, 0, 100 * 0.002) - 2 v, with
  // v = (x1 - x0)/T = (0.001, 0, -0.012)/1e-3 = (1, 0, -12) m/s: (-2, 0, 0.2 + 24) N.
  const CommandAxes v =
      slave.step(vec3(0.001, 0.0, -0.012), zero, peer3(vec3(0.004, 0.02, -0.003), zero, zero));
  EXPECT_TRUE(v.flags.limit_violation);
  EXPECT_NEAR(v.force_N(0), -2.0, 1e-12);
  EXPECT_NEAR(v.force_N(1), 0.0, 1e-12);
  EXPECT_NEAR(v.force_N(2), 24.2, 1e-12);
}

TEST(LawAxes, ClutchOffsetIsAVector) {
  LawAxesParams p = bare3();
  p.gains.kpm = 10.0 * AxisMatrix::Identity(3, 3);
  MasterLawAxes master(p);
  const AxisVector zero = AxisVector::Zero(3);
  const PeerStateAxes slave = peer3(zero, zero, zero);
  const AxisVector x0 = vec3(0.01, 0.02, 0.03);
  (void)master.step(x0, slave);
  EXPECT_EQ(master.peer_state().position_m, x0);
  master.set_clutch(true);
  (void)master.step(vec3(0.05, -0.01, 0.0), slave);
  EXPECT_EQ(master.peer_state().position_m, x0);  // held
  EXPECT_EQ(master.peer_state().velocity_m_per_s, zero);
  EXPECT_TRUE(master.peer_state().clutched);
  master.set_clutch(false);
  const AxisVector x2 = vec3(0.06, -0.01, 0.01);
  (void)master.step(x2, slave);
  EXPECT_NEAR((master.offset_m() - vec3(0.05, -0.03, -0.02)).norm(), 0.0, 1e-15);
  EXPECT_NEAR((master.peer_state().position_m - x0).norm(), 0.0, 1e-15);  // no jump
  EXPECT_FALSE(master.peer_state().clutched);
}

TEST(LawAxes, OneBadComponentLatchesEveryAxis) {
  LawAxesParams p = bare3();
  p.gains.kpm = 10.0 * AxisMatrix::Identity(3, 3);
  MasterLawAxes master(p);
  const AxisVector zero = AxisVector::Zero(3);
  PeerStateAxes slave = peer3(zero, zero, zero);
  slave.force_N(2) = kNaN;
  const CommandAxes c = master.step(vec3(0.01, 0.01, 0.01), slave);
  EXPECT_TRUE(c.flags.input_fault);
  EXPECT_EQ(c.force_N, zero);
  EXPECT_TRUE(master.faulted());
  EXPECT_FALSE(master.peer_state().valid);
  const CommandAxes latched = master.step(vec3(0.01, 0.01, 0.01), peer3(zero, zero, zero));
  EXPECT_TRUE(latched.flags.input_fault);
  master.reset();
  const CommandAxes after = master.step(vec3(0.01, 0.01, 0.01), peer3(zero, zero, zero));
  EXPECT_FALSE(after.flags.input_fault);
  EXPECT_NEAR(after.force_N(1), 0.1, 1e-15);
  // The wrong number of axes in a valid peer state is a fault too.
  PeerStateAxes short_peer = peer3(zero, zero, zero);
  short_peer.position_m = AxisVector::Zero(2);
  EXPECT_TRUE(master.step(vec3(0.0, 0.0, 0.0), short_peer).flags.input_fault);
}

TEST(LawAxes, RetuneTakesNewGainsAndPlanes) {
  LawAxesParams p = bare3();
  p.gains.kpm = 10.0 * AxisMatrix::Identity(3, 3);
  MasterLawAxes master(p);
  const AxisVector zero = AxisVector::Zero(3);
  EXPECT_NEAR(master.step(vec3(0.1, 0.0, 0.0), peer3(zero, zero, zero)).force_N(0), 1.0, 1e-15);
  LawGainsAxes g = p.gains;
  g.kpm = mat3({0, 0, 0, 20, 0, 0, 0, 0, 0});  // axis 0's error drives axis 1
  PlaneSet planes;
  planes.add({unit(0), 0.05, 100.0});
  master.retune(g, planes);
  const CommandAxes c = master.step(vec3(0.1, 0.0, 0.0), peer3(zero, zero, zero));
  EXPECT_NEAR(c.force_N(0), 5.0, 1e-12);  // plane only: 100 * 0.05
  EXPECT_NEAR(c.force_N(1), 2.0, 1e-12);  // 20 * 0.1
  EXPECT_EQ(master.params().gains.kpm(1, 0), 20.0);
}

void expect_invalid(const LawAxesParams& p, const std::string& field, const std::string& what) {
  try {
    validate(p);
    ADD_FAILURE() << "accepted, expected an error naming " << field;
  } catch (const std::invalid_argument& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("LawAxesParams." + field + ":"), std::string::npos) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
  }
  EXPECT_THROW(MasterLawAxes{p}, std::invalid_argument);
  EXPECT_THROW(SlaveLawAxes{p}, std::invalid_argument);
}

TEST(LawAxes, ValidationNamesTheField) {
  EXPECT_NO_THROW(validate(bare3()));
  LawAxesParams p = bare3();
  p.gains.kpm(1, 2) = kNaN;
  expect_invalid(p, "gains.kpm[1][2]", "must be finite");
  p = bare3();
  p.gains.kvs(0, 1) = std::numeric_limits<double>::infinity();
  expect_invalid(p, "gains.kvs[0][1]", "must be finite");
  p = bare3();
  p.gains.kds = AxisMatrix::Zero(2, 3);
  expect_invalid(p, "gains.kds", "must be 3 x 3");
  p = bare3();
  p.master_planes.add({vec3(1.0, 1.0, 0.0), 0.0, 100.0});
  expect_invalid(p, "master_planes[0].normal", "unit length");
  p = bare3();
  p.slave_planes.add({unit(0), 0.0, 100.0});
  p.slave_planes.add({vec3(kNaN, 0.0, 0.0), 0.0, 100.0});
  expect_invalid(p, "slave_planes[1].normal", "must be finite");
  p = bare3();
  p.master_planes.add({AxisVector::Constant(2, std::sqrt(0.5)), 0.0, 100.0});
  expect_invalid(p, "master_planes[0].normal", "3 (axes) entries");
  p = bare3();
  p.master_planes.add({unit(1), 0.0, -1.0});
  expect_invalid(p, "master_planes[0].stiffness_N_per_m", ">= 0");
  p = bare3();
  p.master_planes.add({unit(1), kNaN, 1.0});
  expect_invalid(p, "master_planes[0].offset_m", "must be finite");
  p = bare3();
  p.master_actuator.max_force_N = AxisVector::Constant(2, 1.0);
  expect_invalid(p, "master_actuator.max_force_N", "3 (axes) entries");
  p = bare3();
  p.slave_actuator.max_rate_N_per_s(2) = 0.0;
  expect_invalid(p, "slave_actuator.max_rate_N_per_s[2]", "must be > 0");
  p = bare3();
  p.slave_limits.max_position_m(1) = -1.0;
  p.slave_limits.min_position_m(1) = 0.0;
  expect_invalid(p, "slave_limits.max_position_m[1]", "greater than");
  p = bare3();
  p.slave_limits.max_velocity_m_per_s(0) = kNaN;
  expect_invalid(p, "slave_limits.max_velocity_m_per_s[0]", "must be > 0");
  p = bare3();
  p.axes = 7;
  expect_invalid(p, "axes", "1 to 6");
  p = bare3();
  p.period_s = 0.0;
  expect_invalid(p, "period_s", "> 0");
  p = bare3();
  p.scaling.position = 0.0;
  expect_invalid(p, "scaling.position", "non-zero");
  p = bare3();
  p.clutch_fade_s = -1.0;
  expect_invalid(p, "clutch_fade_s", ">= 0");
}

TEST(LawAxes, FromTeleopAxesParams) {
  TeleopParams one;
  one.sample_rate_hz = 1000.0;
  one.gains.kpm = 250.0;
  one.slave_fixture = {1200.0, 0.01};
  TeleopAxesParams t = to_axes(one);
  const LawAxesParams p = from_teleop_axes_params(t);
  EXPECT_EQ(p.axes, 1);
  EXPECT_EQ(p.period_s, 1e-3);
  EXPECT_EQ(p.gains.kpm(0, 0), 250.0);
  ASSERT_EQ(p.slave_planes.size(), 1);
  EXPECT_EQ(p.slave_planes.plane(0).stiffness_N_per_m, 1200.0);
  EXPECT_EQ(p.master_actuator.max_force_N(0), kNoLimit);
  EXPECT_NO_THROW(validate(p));

  t.master_planes.assign(kMaxPlanes + 1, t.master_planes.front());
  try {
    (void)from_teleop_axes_params(t);
    ADD_FAILURE() << "9 planes accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("LawAxesParams.master_planes:"), std::string::npos)
        << e.what();
  }
  t = to_axes(one);
  t.gains.kfm = Eigen::MatrixXd::Zero(2, 2);
  EXPECT_THROW((void)from_teleop_axes_params(t), std::invalid_argument);
}

}  // namespace
}  // namespace teleop::control
