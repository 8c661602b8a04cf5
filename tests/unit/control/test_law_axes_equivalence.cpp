// n = 1: MasterLawAxes and SlaveLawAxes (common/control/law_axes.hpp) against the one-axis
// MasterLaw and SlaveLaw, bit for bit, over 120k seeded random steps of a free-running
// master/slave pair that clutches, loses the link, faults (NaN and inf in its own and the
// peer's fields), resets and retunes, with fixtures, filter, force channel, every limit and the
// clutch fade on. Each pair runs on its own peer states, so any difference would propagate.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <limits>
#include <random>

#include "common/control/law_axes.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/unit/control/control_test_util.hpp"

namespace teleop::control {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

std::uint64_t bits(double v) { return std::bit_cast<std::uint64_t>(v); }

AxisVector one(double v) { return AxisVector::Constant(1, v); }

PeerStateAxes to_axes(const PeerState& p) {
  return {one(p.position_m), one(p.velocity_m_per_s), one(p.force_N), p.clutched, p.valid};
}

LawGainsAxes to_axes(const Gains& g) {
  const auto m = [](double v) { return AxisMatrix::Constant(1, 1, v); };
  return {m(g.kpm), m(g.kps), m(g.kdm), m(g.kds), m(g.kvm), m(g.kvs), m(g.kfm)};
}

PlaneSet to_axes(const FixtureParams& f) {
  PlaneSet s;
  s.add({one(1.0), f.position_m, f.stiffness_N_per_m});
  return s;
}

void expect_same(const Command& a, const CommandAxes& b, int k, const char* side) {
  ASSERT_EQ(b.force_N.size(), 1) << side << " step " << k;
  ASSERT_EQ(bits(a.force_N), bits(b.force_N(0)))
      << side << " step " << k << ": " << a.force_N << " vs " << b.force_N(0);
  ASSERT_EQ(bits(a.fixture_force_N), bits(b.fixture_force_N(0))) << side << " step " << k;
  ASSERT_EQ(bits(a.penetration_m), bits(b.penetration_m)) << side << " step " << k;
  ASSERT_EQ(a.flags.saturated, b.flags.saturated) << side << " step " << k;
  ASSERT_EQ(a.flags.saturated, b.saturated_axes == 1U) << side << " step " << k;
  ASSERT_EQ(a.flags.rate_limited, b.flags.rate_limited) << side << " step " << k;
  ASSERT_EQ(a.flags.limit_violation, b.flags.limit_violation) << side << " step " << k;
  ASSERT_EQ(a.flags.reference_limited, b.flags.reference_limited) << side << " step " << k;
  ASSERT_EQ(a.flags.input_fault, b.flags.input_fault) << side << " step " << k;
}

void expect_same(const PeerState& a, const PeerStateAxes& b, int k, const char* side) {
  ASSERT_EQ(bits(a.position_m), bits(b.position_m(0))) << side << " peer, step " << k;
  ASSERT_EQ(bits(a.velocity_m_per_s), bits(b.velocity_m_per_s(0))) << side << " peer " << k;
  ASSERT_EQ(bits(a.force_N), bits(b.force_N(0))) << side << " peer, step " << k;
  ASSERT_EQ(a.clutched, b.clutched) << side << " peer, step " << k;
  ASSERT_EQ(a.valid, b.valid) << side << " peer, step " << k;
}

struct Counts {
  int faults{0};
  int saturated{0};
  int rate_limited{0};
  int violations{0};
  int reference_limited{0};
  int inside_fixture{0};
};

// Random gains around `base` (some exactly 0, so the skipped terms are exercised).
Gains random_gains(std::mt19937_64& rng, const Gains& base) {
  std::uniform_real_distribution<double> scale(0.0, 2.0);
  std::bernoulli_distribution zero(0.15);
  const auto g = [&](double v) { return zero(rng) ? 0.0 : v * scale(rng); };
  return {g(base.kpm), g(base.kps), g(base.kdm), g(base.kds),
          g(base.kvm), g(base.kvs), g(base.kfm)};
}

// One run of `steps` steps; `c` counts what happened (to show the paths ran).
void run(const LawParams& params, std::uint64_t seed, int steps, Counts& c) {
  MasterLaw m1(params);
  SlaveLaw s1(params);
  const LawAxesParams axes = to_law_axes(params);
  MasterLawAxes mn(axes);
  SlaveLawAxes sn(axes);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> step_m(0.0, 4e-4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  double xm = 0.0;
  double xs = 0.003;
  PeerState m_to_s1;
  PeerState s_to_m1;
  PeerStateAxes m_to_sn = to_axes(m_to_s1);
  PeerStateAxes s_to_mn = to_axes(s_to_m1);
  bool master_link_down = false;
  bool slave_link_down = false;
  for (int k = 0; k < steps; ++k) {
    xm = 0.999 * xm + step_m(rng) + (u(rng) < 0.002 ? 0.02 * (u(rng) - 0.5) : 0.0);
    xs = 0.999 * xs + step_m(rng) + (u(rng) < 0.002 ? 0.05 * (u(rng) - 0.5) : 0.0);
    double fe = 2.0 * (u(rng) - 0.5);
    if (u(rng) < 1.0 / 300.0) {
      const bool engage = !m1.clutch_engaged();
      m1.set_clutch(engage);
      mn.set_clutch(engage);
    }
    if (u(rng) < 1.0 / 400.0) master_link_down = !master_link_down;
    if (u(rng) < 1.0 / 400.0) slave_link_down = !slave_link_down;
    double xm_in = xm;
    double xs_in = xs;
    const double r = u(rng);
    if (r < 2e-4) xm_in = kNaN;
    if (r >= 2e-4 && r < 4e-4) xs_in = -kInf;
    if (r >= 4e-4 && r < 6e-4) fe = kNaN;
    PeerState to_master = s_to_m1;
    PeerState to_slave = m_to_s1;
    if (master_link_down) to_master.valid = false;
    if (slave_link_down) to_slave.valid = false;
    if (r >= 6e-4 && r < 8e-4) to_master.velocity_m_per_s = kNaN;
    if (r >= 8e-4 && r < 1e-3) to_slave.position_m = kInf;
    PeerStateAxes to_master_n = to_axes(to_master);
    PeerStateAxes to_slave_n = to_axes(to_slave);
    // The axes pair's own peer states carry everything the link did to the one-axis pair's.
    ASSERT_NO_FATAL_FAILURE(expect_same(s_to_m1, s_to_mn, k, "slave->master"));
    ASSERT_NO_FATAL_FAILURE(expect_same(m_to_s1, m_to_sn, k, "master->slave"));

    const Command cm1 = m1.step(xm_in, to_master);
    const CommandAxes cmn = mn.step(one(xm_in), to_master_n);
    const Command cs1 = s1.step(xs_in, fe, to_slave);
    const CommandAxes csn = sn.step(one(xs_in), one(fe), to_slave_n);
    ASSERT_NO_FATAL_FAILURE(expect_same(cm1, cmn, k, "master"));
    ASSERT_NO_FATAL_FAILURE(expect_same(cs1, csn, k, "slave"));
    ASSERT_EQ(bits(m1.coupling_weight()), bits(mn.coupling_weight())) << k;
    ASSERT_EQ(bits(m1.offset_m()), bits(mn.offset_m()(0))) << k;
    ASSERT_EQ(bits(s1.reference_m()), bits(sn.reference_m()(0))) << k;
    ASSERT_EQ(bits(s1.reference_weight()), bits(sn.reference_weight())) << k;
    ASSERT_EQ(s1.holding(), sn.holding()) << k;
    ASSERT_EQ(m1.faulted(), mn.faulted()) << k;
    ASSERT_EQ(s1.faulted(), sn.faulted()) << k;
    m_to_s1 = m1.peer_state();
    s_to_m1 = s1.peer_state();
    m_to_sn = mn.peer_state();
    s_to_mn = sn.peer_state();

    c.faults += cm1.flags.input_fault + cs1.flags.input_fault;
    c.saturated += cm1.flags.saturated + cs1.flags.saturated;
    c.rate_limited += cm1.flags.rate_limited + cs1.flags.rate_limited;
    c.violations += cs1.flags.limit_violation;
    c.reference_limited += cs1.flags.reference_limited;
    c.inside_fixture += (cm1.penetration_m > 0.0) + (cs1.penetration_m > 0.0);

    const double q = u(rng);
    if (q < 1.0 / 1500.0) {
      m1.reset();
      mn.reset();
      s1.reset(xs);
      sn.reset(one(xs));
    } else if (q < 2.0 / 1500.0) {
      m1.reset(xm);
      mn.reset(one(xm));
      s1.reset();
      sn.reset();
    } else if (q < 2.5 / 1500.0) {
      m1.reset(kNaN);  // a non-finite position: at rest at the next sample
      mn.reset(one(kNaN));
    } else if (q < 4.0 / 1500.0) {
      const Gains g = random_gains(rng, params.gains);
      const FixtureParams mf{u(rng) < 0.2 ? 0.0 : 2000.0 * u(rng), 0.02 * (u(rng) - 0.5)};
      const FixtureParams sf{u(rng) < 0.2 ? 0.0 : 2000.0 * u(rng), 0.02 * (u(rng) - 0.5)};
      m1.retune(g, mf);
      mn.retune(to_axes(g), to_axes(mf));
      s1.retune(g, sf);
      sn.retune(to_axes(g), to_axes(sf));
    }
  }
}

// test::busy_params() with the fixtures and the workspace nearer, so that the run visits them.
LawParams busy_params() {
  LawParams p = test::busy_params();
  p.master_fixture = {800.0, 0.004};
  p.slave_fixture = {1000.0, 0.006};
  p.slave_limits = {-0.012, 0.015, 0.5, 5.0};
  return p;
}

TEST(LawAxesEquivalence, BusyLawBitForBit) {
  Counts c;
  ASSERT_NO_FATAL_FAILURE(run(busy_params(), 1, 60000, c));
  EXPECT_GT(c.faults, 20);
  EXPECT_GT(c.saturated, 100);
  EXPECT_GT(c.rate_limited, 100);
  EXPECT_GT(c.violations, 100);
  EXPECT_GT(c.reference_limited, 100);
  EXPECT_GT(c.inside_fixture, 1000);
}

TEST(LawAxesEquivalence, NoLimitsNoFadeNoFilterBitForBit) {
  LawParams p = busy_params();
  p.master_actuator = {};
  p.slave_actuator = {};
  p.slave_limits = {};
  p.clutch_fade_s = 0.0;
  p.velocity_cutoff_hz = 0.0;
  p.scaling = {.position = 1.0, .force = 1.0};
  Counts c;
  ASSERT_NO_FATAL_FAILURE(run(p, 2, 30000, c));
  EXPECT_EQ(c.violations, 0);
  EXPECT_GT(c.faults, 10);
  EXPECT_GT(c.inside_fixture, 1000);
}

TEST(LawAxesEquivalence, NegativeScalingZeroBetaBitForBit) {
  LawParams p = busy_params();
  p.scaling = {.position = -0.7, .force = 0.0};
  p.clutch_fade_s = 0.005;
  Counts c;
  ASSERT_NO_FATAL_FAILURE(run(p, 3, 30000, c));
  EXPECT_GT(c.faults, 10);
}

TEST(LawAxesEquivalence, ParamsConversionKeepsEveryField) {
  const LawParams p = busy_params();
  const LawAxesParams a = to_law_axes(p);
  EXPECT_EQ(a.axes, 1);
  EXPECT_EQ(a.gains.kfm(0, 0), 0.5);
  EXPECT_EQ(a.master_planes.size(), 1);
  EXPECT_EQ(a.master_planes.plane(0).offset_m, 0.004);
  EXPECT_EQ(a.slave_planes.plane(0).stiffness_N_per_m, 1000.0);
  EXPECT_EQ(a.slave_actuator.max_rate_N_per_s(0), 3000.0);
  EXPECT_EQ(a.slave_limits.min_position_m(0), -0.012);
  EXPECT_EQ(a.slave_limits.max_force_N(0), 5.0);
  EXPECT_EQ(a.clutch_fade_s, 0.02);
  EXPECT_NO_THROW(validate(a));
}

}  // namespace
}  // namespace teleop::control
