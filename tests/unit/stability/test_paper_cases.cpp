// The Abbott-Okamura paper's cases and the physics they rest on. Expected values come from
// the paper's text, from physics (Colgate-Schenkel) or from the 50-digit transfer-function
// reference in reference.hpp, never from the engine itself.
#include <gtest/gtest.h>

#include <cmath>

#include "common/stability/analyzer.hpp"
#include "common/stability/stiffness_search.hpp"
#include "reference.hpp"

namespace teleop::stability {
namespace {

TeleopParams paddles(double rate_hz) {
  TeleopParams p;
  p.sample_rate_hz = rate_hz;
  p.master_device = {0.040, 0.41};
  p.slave_device = {0.036, 0.49};
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {0.010, 2.0, 300.0};
  return p;
}

reference::LoopSpec spec_of(const TeleopParams& p) {
  reference::LoopSpec s;
  s.t = p.period_s();
  s.mm = p.master_device.mass_kg;
  s.bm = p.master_device.damping_Ns_per_m;
  s.ms = p.slave_device.mass_kg;
  s.bs = p.slave_device.damping_Ns_per_m;
  if (p.human.kind == HumanKind::kFixed) {
    s.mh = p.human.fixed.mass_kg;
    s.bh = p.human.fixed.damping_Ns_per_m;
    s.kh = p.human.fixed.stiffness_N_per_m;
  }
  s.kpm = p.gains.kpm;
  s.kps = p.gains.kps;
  s.kdm = p.gains.kdm;
  s.kds = p.gains.kds;
  s.kvm = p.gains.kvm;
  s.kvs = p.gains.kvs;
  s.alpha = p.scaling.position;
  s.beta = p.scaling.force;
  s.kmvf = p.master_fixture.stiffness_N_per_m;
  s.ksvf = p.slave_fixture.stiffness_N_per_m;
  s.cutoff_hz = p.velocity_cutoff_hz;
  s.delay = p.round_trip_delay_samples;
  return s;
}

TEST(PaperCases, Fig2GainsAreUnstableAt500Hz) {
  // Fig. 2: K_ps = 600 N/m, K_vs = 2 Ns/m, K_sVF = 3000 N/m, all other gains zero, 500 Hz:
  // the slave vibrates. The master is unactuated, so the slave stands alone.
  TeleopParams p = paddles(500.0);
  p.gains.kps = 600.0;
  p.gains.kvs = 2.0;
  p.slave_fixture.stiffness_N_per_m = 3000.0;
  const AnalysisResult r = analyze(p);
  EXPECT_EQ(r.verdict, Verdict::kUnstable);
  EXPECT_EQ(r.structure, Structure::kSlaveOnly);
  EXPECT_FALSE(r.worst_human.has_value());
  EXPECT_LT(r.min_damping_ratio, 0.0);
  const double ref =
      reference::spectral_radius(reference::roots(reference::slave_polynomial(spec_of(p))));
  EXPECT_GT(ref, 1.0);
  EXPECT_NEAR(r.spectral_radius, ref, 1e-12);
}

TEST(PaperCases, Fig6GainsStableAt500AndUnstableAt6000ForTheFixedHuman) {
  // Fig. 6: T = 2 ms, K_p = 800 N/m, K_d = 6 Ns/m; human 10 g, 2 Ns/m, 300 N/m.
  TeleopParams p = paddles(500.0);
  p.gains = {800.0, 800.0, 6.0, 6.0, 0.0, 0.0, 0.0};
  p.slave_fixture.stiffness_N_per_m = 500.0;
  EXPECT_EQ(analyze(p).verdict, Verdict::kStable);
  EXPECT_LT(
      reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
      1.0);
  p.slave_fixture.stiffness_N_per_m = 6000.0;
  EXPECT_EQ(analyze(p).verdict, Verdict::kUnstable);
  EXPECT_GT(
      reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
      1.0);
}

TEST(PaperCases, Fig6SlaveLimitLiesWhereTheReferenceCrossesTheUnitCircle) {
  // The paper's Fig. 6 arrows end near K_sVF = 5500 N/m, where eigenvalues reach the axis.
  TeleopParams p = paddles(500.0);
  p.gains = {800.0, 800.0, 6.0, 6.0, 0.0, 0.0, 0.0};
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  ASSERT_TRUE(l.max_stable_stiffness_N_per_m.has_value()) << l.reason;
  const double k = *l.max_stable_stiffness_N_per_m;
  EXPECT_GT(k, 4500.0);
  EXPECT_LT(k, 6000.0);
  p.slave_fixture.stiffness_N_per_m = k;
  EXPECT_LT(
      reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
      1.0);
  p.slave_fixture.stiffness_N_per_m = k + 2.0 * p.analysis.stiffness_tolerance_N_per_m;
  EXPECT_GT(
      reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
      1.0);
}

TEST(PaperCases, MasterWallWithoutHumanApproachesColgateSchenkelAsTShrinks) {
  // Unilateral (Fig. 14 gains: K_ps = 1000, K_ds = 6, master feels nothing), no human: a
  // haptic virtual wall. The passivity bound b > KT/2 gives K < 2b/T; the exact stability
  // limit of the sampled wall tends to it as T -> 0.
  double previous_gap = 1.0;
  for (const double rate : {500.0, 5000.0, 50000.0}) {
    TeleopParams p = paddles(rate);
    p.human.kind = HumanKind::kNone;
    p.gains.kps = 1000.0;
    p.gains.kds = 6.0;
    const StiffnessLimit l = max_stable_stiffness(p, Side::kMaster);
    ASSERT_TRUE(l.max_stable_stiffness_N_per_m.has_value()) << l.reason;
    const double bound = 2.0 * 0.41 * rate;
    const double gap = std::abs(*l.max_stable_stiffness_N_per_m / bound - 1.0);
    EXPECT_LT(gap, previous_gap) << rate;
    previous_gap = gap;
    EXPECT_FALSE(l.worst_human.has_value());
    ASSERT_TRUE(l.passivity_limit_N_per_m.has_value());
    EXPECT_NEAR(*l.passivity_limit_N_per_m, bound, 1e-9 * bound);
  }
  EXPECT_LT(previous_gap, 1e-3);
}

TEST(PaperCases, HumanDampingRaisesTheMasterWallAboveTheBareWall) {
  // Fig. 14: with a human the eigenvalue prediction is less conservative than passivity; the
  // human's damping adds to the device's, so the wall takes more than with no human at all.
  TeleopParams p = paddles(1000.0);
  p.gains.kps = 1000.0;
  p.gains.kds = 6.0;
  const StiffnessLimit with_human = max_stable_stiffness(p, Side::kMaster);
  p.human.kind = HumanKind::kNone;
  const StiffnessLimit bare = max_stable_stiffness(p, Side::kMaster);
  ASSERT_TRUE(with_human.max_stable_stiffness_N_per_m.has_value()) << with_human.reason;
  ASSERT_TRUE(bare.max_stable_stiffness_N_per_m.has_value()) << bare.reason;
  EXPECT_GT(*with_human.max_stable_stiffness_N_per_m, 1.5 * *bare.max_stable_stiffness_N_per_m);
  EXPECT_GT(*with_human.max_stable_stiffness_N_per_m, *with_human.passivity_limit_N_per_m);
}

TEST(PaperCases, UnilateralSlaveLimitDoesNotDependOnTheHuman) {
  // Fig. 10: master unactuated (all master gains zero), K_ps = 1000, K_ds = 6.
  TeleopParams p = paddles(500.0);
  p.gains.kps = 1000.0;
  p.gains.kds = 6.0;
  std::vector<double> limits;
  for (const HumanImpedance h :
       {HumanImpedance{0.003, 0.6, 50.0}, HumanImpedance{0.02, 7.0, 1000.0}}) {
    p.human.kind = HumanKind::kFixed;
    p.human.fixed = h;
    limits.push_back(max_stable_stiffness(p, Side::kSlave).max_stable_stiffness_N_per_m.value());
  }
  p.human.kind = HumanKind::kBand;
  p.human.band = default_human_band();
  const StiffnessLimit band = max_stable_stiffness(p, Side::kSlave);
  limits.push_back(band.max_stable_stiffness_N_per_m.value());
  EXPECT_FALSE(band.worst_human.has_value());
  p.human.kind = HumanKind::kNone;
  limits.push_back(max_stable_stiffness(p, Side::kSlave).max_stable_stiffness_N_per_m.value());
  for (const double k : limits) EXPECT_EQ(k, limits.front());

  // And the whole loop, master and human included, crosses the unit circle there for every
  // human alike (the full reference polynomial, not the slave's alone).
  for (const HumanImpedance h :
       {HumanImpedance{0.003, 0.6, 50.0}, HumanImpedance{0.02, 7.0, 1000.0}}) {
    p.human.kind = HumanKind::kFixed;
    p.human.fixed = h;
    p.slave_fixture.stiffness_N_per_m = limits.front();
    EXPECT_LT(
        reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
        1.0);
    p.slave_fixture.stiffness_N_per_m = limits.front() + 2.0;
    EXPECT_GT(
        reference::spectral_radius(reference::roots(reference::bilateral_polynomial(spec_of(p)))),
        1.0);
  }
}

TEST(PaperCases, SlaveLimitRisesWithSampleRate) {
  // Fig. 7 (K_p = 600, K_d = 2): the stiffness limit goes up with the sampling rate.
  TeleopParams p = paddles(250.0);
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  p.human.kind = HumanKind::kBand;
  p.human.band = default_human_band();
  double previous = 0.0;
  for (const double rate : {250.0, 500.0, 1000.0, 2000.0}) {
    p.sample_rate_hz = rate;
    const double k = max_stable_stiffness(p, Side::kSlave).max_stable_stiffness_N_per_m.value();
    EXPECT_GT(k, previous * 1.5) << rate;
    previous = k;
  }
}

TEST(PaperCases, DelayAndVelocityFilterLowerTheLimits) {
  // Both add phase lag inside the loop.
  TeleopParams p = paddles(1000.0);
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  for (const Side side : {Side::kSlave, Side::kMaster}) {
    const double plain = max_stable_stiffness(p, side).max_stable_stiffness_N_per_m.value();
    TeleopParams delayed = p;
    delayed.round_trip_delay_samples = 2;
    const double with_delay =
        max_stable_stiffness(delayed, side).max_stable_stiffness_N_per_m.value();
    TeleopParams filtered = p;
    filtered.velocity_cutoff_hz = 200.0;
    const double with_filter =
        max_stable_stiffness(filtered, side).max_stable_stiffness_N_per_m.value();
    EXPECT_LT(with_delay, plain);
    EXPECT_LT(with_filter, plain);
  }
}

}  // namespace
}  // namespace teleop::stability
