// Each term of the three-channel law alone, with hand-picked numbers, against
// docs/architecture.md §2.3:
//   F_am = beta [K_pm (x_m - x_s/alpha) + K_dm (v_m - v_s/alpha) + K_fm F_e] + K_vm v_m + F_mVF
//   F_as = K_ps (alpha x_m - x_s) + K_ds (alpha v_m - v_s) - K_vs v_s - F_sVF
// The master plant is pushed by -F_am, the slave plant by +F_as. T = 1 ms throughout; a
// velocity is made by reset(x0) then step(x0 + dx): v = dx / T.
#include <gtest/gtest.h>

#include <limits>

#include "common/control/law_params.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/unit/control/control_test_util.hpp"

namespace teleop::control {
namespace {

using test::bare_params;
using test::peer;

constexpr double kTol = 1e-9;

TEST(MasterLawTerms, PositionCoupling) {
  LawParams p = bare_params();
  p.gains.kpm = 200.0;
  MasterLaw m(p);
  // Master ahead of the slave: positive F_am, so the master is pushed back (-F_am) toward it.
  EXPECT_NEAR(m.step(0.010, peer(0.004)).force_N, 200.0 * 0.006, kTol);  // 1.2 N
  m.reset(0.010);
  EXPECT_NEAR(m.step(0.010, peer(0.016)).force_N, -1.2, kTol);
}

TEST(MasterLawTerms, PositionCouplingWithScaling) {
  LawParams p = bare_params();
  p.gains.kpm = 200.0;
  p.scaling.position = 2.0;  // slave moves 2 x_m
  p.scaling.force = 0.5;     // master feels half
  MasterLaw m(p);
  // 0.5 * 200 * (0.010 - 0.004 / 2) = 0.8 N
  EXPECT_NEAR(m.step(0.010, peer(0.004)).force_N, 0.8, kTol);
}

TEST(MasterLawTerms, VelocityCoupling) {
  LawParams p = bare_params();
  p.gains.kdm = 10.0;
  p.scaling.position = 2.0;
  p.scaling.force = 0.5;
  MasterLaw m(p);
  m.reset(0.010);
  // v_m = 0.0002 / 0.001 = 0.2 m/s; v_s = 0.1 m/s: 0.5 * 10 * (0.2 - 0.1 / 2) = 0.75 N
  EXPECT_NEAR(m.step(0.0102, peer(0.0, 0.1)).force_N, 0.75, kTol);
}

TEST(MasterLawTerms, OwnDamping) {
  LawParams p = bare_params();
  p.gains.kvm = 3.0;
  p.scaling.force = 0.5;  // K_vm is not scaled by beta
  MasterLaw m(p);
  m.reset(0.010);
  EXPECT_NEAR(m.step(0.0102, peer(0.0, 0.1)).force_N, 3.0 * 0.2, kTol);
  m.reset(0.010);
  EXPECT_NEAR(m.step(0.0098, peer(0.0, 0.1)).force_N, -0.6, kTol);
}

TEST(MasterLawTerms, ForceFeedForward) {
  LawParams p = bare_params();
  p.gains.kfm = 0.4;
  p.scaling.force = 0.5;
  MasterLaw m(p);
  // beta K_fm F_e = 0.5 * 0.4 * 2 = 0.4 N: the environment's push-back, felt on the master.
  EXPECT_NEAR(m.step(0.3, peer(-0.2, 0.0, 2.0)).force_N, 0.4, kTol);
}

TEST(MasterLawTerms, FixtureAtNonZeroPosition) {
  LawParams p = bare_params();
  p.master_fixture = {1000.0, 0.02};
  MasterLaw m(p);
  const Command inside = m.step(0.025, peer(0.0));
  // 1000 * (0.025 - 0.02) = 5 N, pushing the master back out (-F_am).
  EXPECT_NEAR(inside.force_N, 5.0, kTol);
  EXPECT_NEAR(inside.fixture_force_N, 5.0, kTol);
  EXPECT_NEAR(inside.penetration_m, 0.005, 1e-15);
  m.reset(0.015);
  const Command outside = m.step(0.015, peer(0.0));
  EXPECT_EQ(outside.force_N, 0.0);
  EXPECT_EQ(outside.fixture_force_N, 0.0);
  EXPECT_EQ(outside.penetration_m, 0.0);
}

TEST(MasterLawTerms, NoFixtureReportsNoPenetration) {
  LawParams p = bare_params();
  p.master_fixture = {0.0, -1.0};
  MasterLaw m(p);
  const Command c = m.step(0.5, peer(0.5));
  EXPECT_EQ(c.penetration_m, 0.0);
  EXPECT_EQ(c.fixture_force_N, 0.0);
}

TEST(MasterLawTerms, AllTermsTogether) {
  LawParams p = bare_params();
  p.gains = {.kpm = 150.0, .kps = 0.0, .kdm = 4.0, .kds = 0.0, .kvm = 1.5, .kvs = 0.0, .kfm = 0.3};
  p.scaling = {.position = 1.5, .force = 0.8};
  p.master_fixture = {800.0, 0.01};
  MasterLaw m(p);
  m.reset(0.012);
  // x_m = 0.0125, v_m = 0.5; x_s = 0.015, v_s = 0.3, F_e = 1.25
  const double coupling = 150.0 * (0.0125 - 0.015 / 1.5) + 4.0 * (0.5 - 0.3 / 1.5) + 0.3 * 1.25;
  const double expected = 0.8 * coupling + 1.5 * 0.5 + 800.0 * 0.0025;
  // = 0.8 * (0.375 + 1.2 + 0.375) + 0.75 + 2 = 4.31
  EXPECT_NEAR(expected, 4.31, 1e-12);
  EXPECT_NEAR(m.step(0.0125, peer(0.015, 0.3, 1.25)).force_N, 4.31, kTol);
}

TEST(MasterLawTerms, PublishesOwnState) {
  LawParams p = bare_params();
  p.velocity_cutoff_hz = 0.0;
  MasterLaw m(p);
  EXPECT_FALSE(m.peer_state().valid);
  m.reset(0.010);
  static_cast<void>(m.step(0.0102, peer(0.0)));
  const PeerState s = m.peer_state();
  EXPECT_TRUE(s.valid);
  EXPECT_FALSE(s.clutched);
  EXPECT_EQ(s.position_m, 0.0102);
  EXPECT_NEAR(s.velocity_m_per_s, 0.2, kTol);
  EXPECT_EQ(s.force_N, 0.0);
}

TEST(SlaveLawTerms, PositionTracking) {
  LawParams p = bare_params();
  p.gains.kps = 300.0;
  p.scaling.position = 2.0;
  SlaveLaw s(p);
  // 300 * (2 * 0.010 - 0.015) = 1.5 N, pushing the slave toward its reference.
  EXPECT_NEAR(s.step(0.015, 0.0, peer(0.010)).force_N, 1.5, kTol);
  s.reset(0.025);
  EXPECT_NEAR(s.step(0.025, 0.0, peer(0.010)).force_N, -1.5, kTol);
}

TEST(SlaveLawTerms, VelocityTrackingUsesTransmittedMasterVelocity) {
  LawParams p = bare_params();
  p.gains.kds = 5.0;
  p.scaling.position = 2.0;
  SlaveLaw s(p);
  s.reset(0.020);
  // v_s = 0.0003 / 0.001 = 0.3; alpha v_m = 0.2: 5 * (0.2 - 0.3) = -0.5 N
  EXPECT_NEAR(s.step(0.0203, 0.0, peer(123.0, 0.1)).force_N, -0.5, kTol);
}

TEST(SlaveLawTerms, OwnDamping) {
  LawParams p = bare_params();
  p.gains.kvs = 2.0;
  SlaveLaw s(p);
  s.reset(0.020);
  EXPECT_NEAR(s.step(0.0203, 0.0, peer(0.0, 5.0)).force_N, -0.6, kTol);
}

TEST(SlaveLawTerms, FixtureAtNonZeroPosition) {
  LawParams p = bare_params();
  p.slave_fixture = {2000.0, 0.005};
  SlaveLaw s(p);
  const Command inside = s.step(0.008, 0.0, peer(0.0));
  // The fixture pushes the slave back out: -2000 * 0.003 = -6 N.
  EXPECT_NEAR(inside.force_N, -6.0, kTol);
  EXPECT_NEAR(inside.fixture_force_N, 6.0, kTol);
  EXPECT_NEAR(inside.penetration_m, 0.003, 1e-15);
  s.reset(0.004);
  EXPECT_EQ(s.step(0.004, 0.0, peer(0.0)).force_N, 0.0);
}

TEST(SlaveLawTerms, AllTermsTogether) {
  LawParams p = bare_params();
  p.gains = {.kpm = 0.0, .kps = 250.0, .kdm = 0.0, .kds = 3.0, .kvm = 0.0, .kvs = 0.5, .kfm = 0.0};
  p.scaling = {.position = 1.5, .force = 0.8};
  p.slave_fixture = {600.0, 0.01};
  SlaveLaw s(p);
  s.reset(0.0118);
  // x_s = 0.012, v_s = 0.2; x_m = 0.01, v_m = 0.4
  // 250 (0.015 - 0.012) + 3 (0.6 - 0.2) - 0.5 * 0.2 - 600 * 0.002 = 0.75 + 1.2 - 0.1 - 1.2
  EXPECT_NEAR(s.step(0.012, 0.0, peer(0.01, 0.4)).force_N, 0.65, kTol);
}

TEST(SlaveLawTerms, PublishesOwnStateAndMeasuredForce) {
  LawParams p = bare_params();
  SlaveLaw s(p);
  EXPECT_FALSE(s.peer_state().valid);
  s.reset(0.020);
  static_cast<void>(s.step(0.0203, 1.75, peer(0.0)));
  const PeerState st = s.peer_state();
  EXPECT_TRUE(st.valid);
  EXPECT_EQ(st.position_m, 0.0203);
  EXPECT_NEAR(st.velocity_m_per_s, 0.3, kTol);
  EXPECT_EQ(st.force_N, 1.75);
  EXPECT_FALSE(st.clutched);
}

TEST(LawParams, FromTeleopParamsCopiesTheLawAndHasNoLimits) {
  TeleopParams t;
  t.sample_rate_hz = 2000.0;
  t.gains.kpm = 1.0;
  t.gains.kfm = 0.25;
  t.scaling = {.position = 3.0, .force = 0.5};
  t.master_fixture = {100.0, 0.1};
  t.slave_fixture = {200.0, 0.2};
  t.velocity_cutoff_hz = 150.0;
  const LawParams p = from_teleop_params(t);
  EXPECT_EQ(p.period_s, 0.0005);
  EXPECT_EQ(p.gains.kpm, 1.0);
  EXPECT_EQ(p.gains.kfm, 0.25);
  EXPECT_EQ(p.scaling.position, 3.0);
  EXPECT_EQ(p.scaling.force, 0.5);
  EXPECT_EQ(p.master_fixture.position_m, 0.1);
  EXPECT_EQ(p.slave_fixture.stiffness_N_per_m, 200.0);
  EXPECT_EQ(p.velocity_cutoff_hz, 150.0);
  constexpr double inf = std::numeric_limits<double>::infinity();
  EXPECT_EQ(p.master_actuator.max_force_N, inf);
  EXPECT_EQ(p.master_actuator.max_rate_N_per_s, inf);
  EXPECT_EQ(p.slave_actuator.max_force_N, inf);
  EXPECT_EQ(p.slave_actuator.max_rate_N_per_s, inf);
  EXPECT_EQ(p.slave_limits.min_position_m, -inf);
  EXPECT_EQ(p.slave_limits.max_position_m, inf);
  EXPECT_EQ(p.slave_limits.max_velocity_m_per_s, inf);
  EXPECT_EQ(p.slave_limits.max_force_N, inf);
  EXPECT_NO_THROW(validate(p));
}

}  // namespace
}  // namespace teleop::control
