// Actuator saturation and rate limit, the slave's workspace limits, non-finite inputs and
// parameter validation, against the behaviour documented in master_law.hpp / slave_law.hpp.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/unit/control/control_test_util.hpp"

namespace teleop::control {
namespace {

using test::bare_params;
using test::peer;

constexpr double kTol = 1e-9;
constexpr double kInf = std::numeric_limits<double>::infinity();
const double kNaN = std::numeric_limits<double>::quiet_NaN();

TEST(ActuatorLimits, MasterSaturatesBothWays) {
  LawParams p = bare_params();
  p.gains.kpm = 1000.0;
  p.master_actuator.max_force_N = 2.0;
  MasterLaw m(p);
  Command c = m.step(0.001, peer(0.0));  // 1 N: inside the limit
  EXPECT_NEAR(c.force_N, 1.0, kTol);
  EXPECT_FALSE(c.flags.saturated);
  c = m.step(0.01, peer(0.0));  // 10 N requested
  EXPECT_EQ(c.force_N, 2.0);
  EXPECT_TRUE(c.flags.saturated);
  c = m.step(0.01, peer(0.02));  // -10 N requested
  EXPECT_EQ(c.force_N, -2.0);
  EXPECT_TRUE(c.flags.saturated);
}

TEST(ActuatorLimits, RateLimitIsMaxRateTimesPeriodPerSample) {
  LawParams p = bare_params();
  p.gains.kps = 500.0;
  p.slave_actuator.max_rate_N_per_s = 1000.0;  // 1 N per 1 ms sample
  SlaveLaw s(p);
  // 500 * 0.01 = 5 N requested from rest (the limiter starts at 0 N).
  const std::vector<double> up{1.0, 2.0, 3.0, 4.0, 5.0, 5.0};
  for (std::size_t i = 0; i < up.size(); ++i) {
    const Command c = s.step(0.0, 0.0, peer(0.01));
    EXPECT_NEAR(c.force_N, up[i], kTol) << i;
    EXPECT_EQ(c.flags.rate_limited, i < 4) << i;
    EXPECT_FALSE(c.flags.saturated);
  }
  // -5 N requested: ten samples of -1 N.
  for (int i = 1; i <= 12; ++i) {
    const Command c = s.step(0.0, 0.0, peer(-0.01));
    EXPECT_NEAR(c.force_N, std::max(5.0 - i, -5.0), kTol) << i;
    EXPECT_EQ(c.flags.rate_limited, i < 10) << i;
  }
}

TEST(ActuatorLimits, SaturationAndRateTogetherHonourBoth) {
  LawParams p = bare_params();
  p.gains.kpm = 1000.0;
  p.master_actuator = {3.0, 1000.0};
  MasterLaw m(p);
  const std::vector<double> expected{1.0, 2.0, 3.0, 3.0};
  for (std::size_t i = 0; i < expected.size(); ++i) {
    const Command c = m.step(0.01, peer(0.0));  // 10 N requested
    EXPECT_NEAR(c.force_N, expected[i], kTol);
    EXPECT_TRUE(c.flags.saturated);
    EXPECT_EQ(c.flags.rate_limited, i < 2);
  }
}

TEST(SlaveLimits, ForceLimitClampsTheCommand) {
  LawParams p = bare_params();
  p.gains.kps = 300.0;
  p.slave_limits.max_force_N = 1.0;
  SlaveLaw s(p);
  Command c = s.step(0.0, 0.0, peer(0.01));  // 3 N requested
  EXPECT_EQ(c.force_N, 1.0);
  EXPECT_TRUE(c.flags.saturated);
  s.reset();
  c = s.step(0.0, 0.0, peer(0.002));  // 0.6 N
  EXPECT_NEAR(c.force_N, 0.6, kTol);
  EXPECT_FALSE(c.flags.saturated);
}

[[nodiscard]] LawParams limited_slave_params() {
  LawParams p = bare_params();
  p.gains.kps = 300.0;
  p.gains.kds = 4.0;
  p.gains.kvs = 1.0;
  p.slave_fixture = {2000.0, 0.06};
  p.slave_limits.min_position_m = -0.05;
  p.slave_limits.max_position_m = 0.05;
  p.slave_limits.max_velocity_m_per_s = 0.5;
  return p;
}

TEST(SlaveLimits, BeyondMaxPositionSpringsBackToTheBoundWithDamping) {
  SlaveLaw s(limited_slave_params());
  s.reset(0.061);
  // x_s = 0.0612, v_s = 0.2 (inside the velocity limit); the master is ignored.
  const Command c = s.step(0.0612, 0.0, peer(0.0, 3.0));
  EXPECT_TRUE(c.flags.limit_violation);
  // 300 (0.05 - 0.0612) - (4 + 1) 0.2 - 2000 (0.0612 - 0.06) = -3.36 - 1 - 2.4
  EXPECT_NEAR(c.force_N, -6.76, kTol);
  EXPECT_NEAR(c.fixture_force_N, 2.4, kTol);
}

TEST(SlaveLimits, BelowMinPositionSpringsBackToTheBound) {
  SlaveLaw s(limited_slave_params());
  s.reset(-0.0605);
  const Command c = s.step(-0.0603, 0.0, peer(-1.0));
  EXPECT_TRUE(c.flags.limit_violation);
  // 300 (-0.05 + 0.0603) - 5 * 0.2
  EXPECT_NEAR(c.force_N, 3.09 - 1.0, kTol);
}

TEST(SlaveLimits, OverspeedGivesDampingOnlyAndResumesInside) {
  SlaveLaw s(limited_slave_params());
  s.reset(0.0);
  const Command fast = s.step(0.001, 0.0, peer(0.04, 0.1));  // v_s = 1 m/s > 0.5
  EXPECT_TRUE(fast.flags.limit_violation);
  EXPECT_NEAR(fast.force_N, -(4.0 + 1.0) * 1.0, kTol);
  const Command slow = s.step(0.0011, 0.0, peer(0.04, 0.1));  // v_s = 0.1: the law again
  EXPECT_FALSE(slow.flags.limit_violation);
  EXPECT_NEAR(slow.force_N, 300.0 * (0.04 - 0.0011) + 4.0 * (0.1 - 0.1) - 1.0 * 0.1, kTol);
}

TEST(SlaveLimits, ReferenceOutsideWorkspaceIsClampedWithoutViolation) {
  LawParams p = limited_slave_params();
  p.scaling.position = 2.0;
  SlaveLaw s(p);
  s.reset(0.0399);
  // alpha x_m = 0.06 > 0.05: reference 0.05, reference velocity 0; v_s = 0.1.
  const Command c = s.step(0.04, 0.0, peer(0.03, 0.2));
  EXPECT_TRUE(c.flags.reference_limited);
  EXPECT_FALSE(c.flags.limit_violation);
  EXPECT_NEAR(c.force_N, 300.0 * (0.05 - 0.04) + 4.0 * (0.0 - 0.1) - 1.0 * 0.1, kTol);
  EXPECT_NEAR(s.reference_m(), 0.06, kTol);
}

// One input made non-finite at a time; returns the command of that step.
struct FaultCase {
  std::string name;
  std::function<Command(MasterLaw&, SlaveLaw&, double)> inject;
  bool master_side;
};

[[nodiscard]] std::vector<FaultCase> fault_cases() {
  return {
      {"master position",
       [](MasterLaw& m, SlaveLaw&, double bad) { return m.step(bad, peer(0.0)); }, true},
      {"master peer position",
       [](MasterLaw& m, SlaveLaw&, double bad) { return m.step(0.01, peer(bad)); }, true},
      {"master peer velocity",
       [](MasterLaw& m, SlaveLaw&, double bad) { return m.step(0.01, peer(0.0, bad)); }, true},
      {"master peer force",
       [](MasterLaw& m, SlaveLaw&, double bad) { return m.step(0.01, peer(0.0, 0.0, bad)); }, true},
      {"slave position",
       [](MasterLaw&, SlaveLaw& s, double bad) { return s.step(bad, 0.0, peer(0.0)); }, false},
      {"slave measured force",
       [](MasterLaw&, SlaveLaw& s, double bad) { return s.step(0.0, bad, peer(0.0)); }, false},
      {"slave peer position",
       [](MasterLaw&, SlaveLaw& s, double bad) { return s.step(0.0, 0.0, peer(bad)); }, false},
      {"slave peer velocity",
       [](MasterLaw&, SlaveLaw& s, double bad) { return s.step(0.0, 0.0, peer(0.0, bad)); }, false},
      {"slave peer force",
       [](MasterLaw&, SlaveLaw& s, double bad) { return s.step(0.0, 0.0, peer(0.0, 0.0, bad)); },
       false},
  };
}

TEST(Faults, NonFiniteInputGivesZeroAndLatchesUntilReset) {
  LawParams p = bare_params();
  p.gains = {
      .kpm = 200.0, .kps = 300.0, .kdm = 2.0, .kds = 3.0, .kvm = 1.0, .kvs = 1.0, .kfm = 0.5};
  p.master_fixture = {1000.0, -0.1};  // always inside: a non-zero force everywhere
  p.slave_fixture = {1000.0, -0.1};
  p.master_actuator.max_rate_N_per_s = 1000.0;  // a fault must bypass the rate limit
  p.slave_actuator.max_rate_N_per_s = 1000.0;
  for (const FaultCase& fc : fault_cases()) {
    for (const double bad : {kNaN, kInf, -kInf}) {
      SCOPED_TRACE(fc.name + " = " + std::to_string(bad));
      MasterLaw m(p);
      SlaveLaw s(p);
      // Build up a non-zero command first (the rate limit makes it 1 N per sample).
      for (int i = 0; i < 3; ++i) {
        EXPECT_NE(m.step(0.01, peer(0.0, 0.0, 1.0)).force_N, 0.0);
        EXPECT_NE(s.step(0.0, 1.0, peer(0.01)).force_N, 0.0);
      }
      const Command c = fc.inject(m, s, bad);
      EXPECT_EQ(c.force_N, 0.0);
      EXPECT_TRUE(c.flags.input_fault);
      EXPECT_TRUE(std::isfinite(c.fixture_force_N) && std::isfinite(c.penetration_m));
      // Latched: good inputs still give 0 N.
      for (int i = 0; i < 5; ++i) {
        const Command later =
            fc.master_side ? m.step(0.01, peer(0.0, 0.0, 1.0)) : s.step(0.0, 1.0, peer(0.01));
        EXPECT_EQ(later.force_N, 0.0);
        EXPECT_TRUE(later.flags.input_fault);
      }
      EXPECT_EQ(fc.master_side ? m.faulted() : s.faulted(), true);
      EXPECT_FALSE(fc.master_side ? m.peer_state().valid : s.peer_state().valid);
      // reset() clears the latch; the law is back (rate limit restarting from 0 N).
      if (fc.master_side) {
        m.reset(0.01);
        const Command back = m.step(0.01, peer(0.0));
        EXPECT_FALSE(back.flags.input_fault);
        EXPECT_NEAR(back.force_N, 1.0, kTol);  // rate limited from 0 N
        EXPECT_TRUE(m.peer_state().valid);
      } else {
        s.reset(0.0);
        const Command back = s.step(0.0, 1.0, peer(0.01));
        EXPECT_FALSE(back.flags.input_fault);
        EXPECT_NEAR(back.force_N, -1.0, kTol);  // -97 N requested, rate limited from 0 N
        EXPECT_TRUE(s.peer_state().valid);
      }
    }
  }
}

TEST(Faults, InvalidPeerIsNotReadSoItsGarbageIsNoFault) {
  LawParams p = bare_params();
  p.gains.kpm = 200.0;
  p.gains.kps = 300.0;
  MasterLaw m(p);
  SlaveLaw s(p);
  PeerState garbage{kNaN, kInf, -kInf, false, false};
  const Command cm = m.step(0.01, garbage);
  const Command cs = s.step(0.02, 0.0, garbage);
  EXPECT_FALSE(cm.flags.input_fault || cs.flags.input_fault);
  EXPECT_EQ(cm.force_N, 0.0);  // no slave ever seen: no coupling
  EXPECT_EQ(cs.force_N, 0.0);  // no master ever seen: holds where it is
  EXPECT_TRUE(std::isfinite(m.peer_state().position_m));
}

TEST(Faults, OverflowingComputationIsAFault) {
  LawParams p = bare_params();
  p.gains.kpm = 1e10;
  p.gains.kps = 1e10;
  MasterLaw m(p);
  SlaveLaw s(p);
  const Command cm = m.step(1e300, peer(-1e300));
  const Command cs = s.step(-1e300, 0.0, peer(1e300));
  EXPECT_TRUE(cm.flags.input_fault);
  EXPECT_TRUE(cs.flags.input_fault);
  EXPECT_EQ(cm.force_N, 0.0);
  EXPECT_EQ(cs.force_N, 0.0);
}

void expect_rejected(const LawParams& p, const std::string& field) {
  try {
    validate(p);
    ADD_FAILURE() << "accepted bad " << field;
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
  EXPECT_THROW(MasterLaw{p}, std::invalid_argument) << field;
  EXPECT_THROW(SlaveLaw{p}, std::invalid_argument) << field;
}

TEST(Validation, NamesTheOffendingField) {
  const LawParams good = bare_params();
  EXPECT_NO_THROW(validate(good));
  LawParams p = good;
  p.period_s = 0.0;
  expect_rejected(p, "period_s");
  p = good;
  p.gains.kdm = kInf;
  expect_rejected(p, "gains.kdm");
  p = good;
  p.scaling.position = 0.0;
  expect_rejected(p, "scaling.position");
  p = good;
  p.scaling.force = kNaN;
  expect_rejected(p, "scaling.force");
  p = good;
  p.slave_fixture.stiffness_N_per_m = -1.0;
  expect_rejected(p, "slave_fixture.stiffness_N_per_m");
  p = good;
  p.velocity_cutoff_hz = kNaN;
  expect_rejected(p, "velocity_cutoff_hz");
  p = good;
  p.master_actuator.max_force_N = 0.0;
  expect_rejected(p, "master_actuator.max_force_N");
  p = good;
  p.slave_actuator.max_rate_N_per_s = kNaN;
  expect_rejected(p, "slave_actuator.max_rate_N_per_s");
  p = good;
  p.slave_limits.min_position_m = 0.1;
  p.slave_limits.max_position_m = -0.1;
  expect_rejected(p, "slave_limits.max_position_m");
  p = good;
  p.slave_limits.max_velocity_m_per_s = -1.0;
  expect_rejected(p, "slave_limits.max_velocity_m_per_s");
  p = good;
  p.clutch_fade_s = -0.01;
  expect_rejected(p, "clutch_fade_s");
}

}  // namespace
}  // namespace teleop::control
