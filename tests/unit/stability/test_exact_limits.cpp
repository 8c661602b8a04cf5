// Issue 15: the maximum fixture stiffness is the first crossing of the admissible boundary,
// exact, whatever lies below it. Expected values come only from the 50-digit reference
// (reference.hpp through campaign.hpp's RefLoop: the loop as a transfer-function polynomial,
// Schur-Cohn for "every root inside the unit circle", Aberth-Ehrlich roots for the damping
// ratio), never from the engine.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>
#include <string>

#include "campaign.hpp"
#include "common/stability/crossings.hpp"
#include "common/stability/stiffness_search.hpp"
#include "tests/unit/stability/window_example.hpp"

namespace teleop::stability {
namespace {

using campaign::RefLoop;
using campaign::Rng;

using test::window_example;

struct Reference {
  TeleopParams p;
  Side side;
  RefLoop loop;
  Reference(const TeleopParams& params, Side s)
      : p(params),
        side(s),
        loop(params, DiscreteModel(params, s == Side::kMaster, s == Side::kSlave).structure()) {}
  [[nodiscard]] campaign::Poly poly(double k) const {
    const double other = side == Side::kMaster ? p.slave_fixture.stiffness_N_per_m
                                               : p.master_fixture.stiffness_N_per_m;
    return side == Side::kMaster ? loop.reduced_polynomial(k, other)
                                 : loop.reduced_polynomial(other, k);
  }
  // Every root inside the region: Schur-Cohn for zeta = 0, the roots' damping ratios else.
  // Schur-Cohn loses its digits on long polynomials (it calls the 200-sample loop below
  // unstable at a spectral radius of 0.99364 by the roots), so past degree 60 the roots decide.
  [[nodiscard]] bool admissible(double k, double zeta) const {
    const campaign::Poly q = poly(k);
    if (zeta == 0.0 && q.size() <= 61) return campaign::schur_stable(q);
    const campaign::RefSpectrum s = campaign::analyse_roots(reference::roots(q));
    return s.radius_margin > 0.0 && s.min_damping_ratio >= zeta;
  }
  // The first exit by a geometric scan from `from` (x growth), then bisection to 1e-13.
  [[nodiscard]] std::optional<double> first_exit(double from, double growth, double cap,
                                                 double zeta) const {
    double pass = from;
    double fail = -1.0;
    for (double k = from; k < cap; k *= growth) {
      if (!admissible(k, zeta)) {
        fail = k;
        break;
      }
      pass = k;
    }
    if (fail < 0.0) return std::nullopt;
    while (fail - pass > 1e-13 * fail) {
      const double mid = 0.5 * (pass + fail);
      if (mid <= pass || mid >= fail) break;
      (admissible(mid, zeta) ? pass : fail) = mid;
    }
    return pass;
  }
};

TEST(ExactLimit, TheIssuesWindowExampleIsTheFirstCrossingNotTheScansAnswer) {
  const TeleopParams p = window_example();
  const Reference ref(p, Side::kSlave);
  // The window, by the reference alone: stable below, unstable inside, stable again above.
  EXPECT_TRUE(ref.admissible(1300.0, 0.0));
  EXPECT_FALSE(ref.admissible(1340.0, 0.0));
  EXPECT_TRUE(ref.admissible(2000.0, 0.0));
  const std::optional<double> exit = ref.first_exit(1.0, 1.002, 1e7, 0.0);
  ASSERT_TRUE(exit.has_value());
  EXPECT_NEAR(*exit, 1325.0, 1.0);
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  ASSERT_TRUE(l.max_stable_stiffness_N_per_m.has_value()) << l.reason;
  EXPECT_NEAR(*l.max_stable_stiffness_N_per_m, *exit, 1e-9 * *exit);
  EXPECT_LE(*l.max_stable_stiffness_N_per_m, *exit * (1.0 + 1e-13));
  EXPECT_EQ(l.fallbacks, 0);
  // The old scan steps over the window (the defect the issue reports).
  const StiffnessLimit scanned = max_stable_stiffness_scan(p, Side::kSlave);
  ASSERT_TRUE(scanned.max_stable_stiffness_N_per_m.has_value());
  EXPECT_GT(*scanned.max_stable_stiffness_N_per_m, 2000.0);
}

// The margins the console and status show: inside the window (1340 N/m) the nearest crossing
// below is the limit, and the one above is where the reference becomes stable again.
TEST(ExactLimit, TheNearestCrossingsAboutAValueInsideTheWindowBoundIt) {
  TeleopParams p = window_example();
  const Reference ref(p, Side::kSlave);
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  const NearestCrossings n = nearest_crossings(l, 1340.0);
  ASSERT_TRUE(n.below_N_per_m.has_value());
  ASSERT_TRUE(n.above_N_per_m.has_value());
  EXPECT_TRUE(ref.admissible(*n.below_N_per_m * (1 - 1e-9), 0.0));
  EXPECT_FALSE(ref.admissible(*n.below_N_per_m * (1 + 1e-9), 0.0));
  EXPECT_FALSE(ref.admissible(*n.above_N_per_m * (1 - 1e-9), 0.0));
  EXPECT_TRUE(ref.admissible(*n.above_N_per_m * (1 + 1e-9), 0.0));
  EXPECT_NEAR(*n.above_N_per_m, 1357.0, 5.0);  // the issue's "about 1357"
  // At a value inside [0, limit] nothing lies below, and the limit is the next above.
  const NearestCrossings inside = nearest_crossings(l, 1000.0);
  EXPECT_FALSE(inside.below_N_per_m.has_value());
  ASSERT_TRUE(inside.above_N_per_m.has_value());
  EXPECT_NEAR(*inside.above_N_per_m, *l.max_stable_stiffness_N_per_m, 1e-8 * 1325.0);
  // ... and it is the reference's first exit to 1e-9.
  EXPECT_TRUE(ref.admissible(*inside.above_N_per_m * (1 - 1e-9), 0.0));
  EXPECT_FALSE(ref.admissible(*inside.above_N_per_m * (1 + 1e-9), 0.0));
}

TEST(ExactLimit, EveryCrossingOfTheWindowExampleAgreesWithTheReference) {
  const TeleopParams p = window_example();
  const Reference ref(p, Side::kSlave);
  const LoopEvaluator ev(p, false, true);
  const ZohPlant plant = ev.model().master_plant(p.human.fixed);
  const ModelBlock a0 = ev.model().build(plant, 0.0, 0.0).front();
  const ModelBlock a1 = ev.model().build(plant, 0.0, 1.0).front();
  const RankOneLoop loop(a0, a1, a0.slave_position);
  const CrossingSearch cs = loop.crossings(0.0, 1e7);
  ASSERT_GE(cs.crossings.size(), 3u);
  // Each crossing changes the reference's count of roots outside the unit circle.
  auto outside = [&](double k) {
    int n = 0;
    for (const campaign::RefRoot& r :
         campaign::analyse_roots(reference::roots(ref.poly(k))).roots) {
      n += r.margin < 0.0 ? 1 : 0;
    }
    return n;
  };
  for (const Crossing& c : cs.crossings) {
    const double k = c.stiffness_N_per_m;
    EXPECT_NE(outside(k * (1 - 1e-9)), outside(k * (1 + 1e-9)))
        << "no root crosses the circle about " << k << " N/m, z = " << c.z;
    EXPECT_NEAR(std::abs(c.z), 1.0, 1e-12);
  }
}

// Random teleoperators with a fixed human: masses, damping, gains and rates over the range
// labs use, filter, force scaling, delays 0-20, both sides.
TeleopParams random_loop(Rng& rng) {
  TeleopParams p;
  p.sample_rate_hz = rng.log_uniform(200.0, 5000.0);
  p.master_device = {rng.log_uniform(0.01, 0.5), rng.log_uniform(0.05, 5.0)};
  p.slave_device = {rng.log_uniform(0.01, 0.5), rng.log_uniform(0.05, 5.0)};
  p.gains.kpm = rng.log_uniform(50.0, 3000.0);
  p.gains.kps = rng.log_uniform(50.0, 3000.0);
  p.gains.kdm = rng.log_uniform(0.1, 8.0);
  p.gains.kds = rng.log_uniform(0.1, 8.0);
  p.scaling = {rng.uniform(0.5, 2.0), rng.chance(0.2) ? 0.0 : rng.uniform(0.5, 3.0)};
  p.velocity_cutoff_hz = rng.chance(0.5) ? 0.0 : rng.log_uniform(20.0, 0.4 * p.sample_rate_hz);
  p.round_trip_delay_samples = rng.integer(0, 20);
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {rng.log_uniform(0.005, 0.5), rng.log_uniform(0.5, 10.0),
                   rng.log_uniform(10.0, 1000.0)};
  return p;
}

TEST(ExactLimit, SeededRandomLoopsAgreeWithTheReferenceWithinOnePartInABillion) {
  Rng rng(15);
  int compared = 0;
  int windows = 0;
  for (int i = 0; i < 40; ++i) {
    const TeleopParams p = random_loop(rng);
    const Side side = rng.chance(0.5) ? Side::kSlave : Side::kMaster;
    const StiffnessLimit l = max_stable_stiffness(p, side);
    const Reference ref(p, side);
    const std::string what = "case " + std::to_string(i) + " " +
                             (side == Side::kSlave ? "slave" : "master") + ": " + l.reason;
    if (!ref.admissible(1e-6, 0.0)) {
      EXPECT_FALSE(l.max_stable_stiffness_N_per_m.has_value()) << what;
      continue;
    }
    ASSERT_TRUE(l.max_stable_stiffness_N_per_m.has_value()) << what;
    const double k = *l.max_stable_stiffness_N_per_m;
    // Admissible at the answer, the crossing under it an exit of the reference's to 1e-9 ...
    ASSERT_TRUE(l.limit_crossing_N_per_m.has_value());
    const double crossing = *l.limit_crossing_N_per_m;
    EXPECT_LE(k, crossing);
    EXPECT_TRUE(ref.admissible(k, 0.0)) << what << " at " << k;
    EXPECT_TRUE(ref.admissible(crossing * (1 - 1e-9), 0.0)) << what << " at " << crossing;
    EXPECT_FALSE(ref.admissible(crossing * (1 + 1e-9), 0.0)) << what << " at " << crossing;
    // ... and no exit below it (a scan finer than the old x1.2).
    const std::optional<double> scanned = ref.first_exit(1e-3, 1.05, k, 0.0);
    EXPECT_FALSE(scanned.has_value()) << what << ": the reference leaves at " << *scanned;
    // Where the reference is admissible again somewhere above, the answer sat below a window.
    for (double f : {1.1, 1.5, 2.0}) {
      if (ref.admissible(k * f, 0.0)) {
        ++windows;
        break;
      }
    }
    EXPECT_EQ(l.fallbacks, 0) << what;
    ++compared;
  }
  std::cout << compared << " limits compared, " << windows << " with stable stiffness above\n";
  EXPECT_GT(compared, 20);
}

TEST(ExactLimit, ARequiredDampingRatioIsTheFirstCrossingOfTheConstantZetaSpiral) {
  Rng rng(1515);
  int compared = 0;
  for (int i = 0; i < 12; ++i) {
    TeleopParams p = random_loop(rng);
    p.round_trip_delay_samples = rng.integer(0, 4);
    p.analysis.required_damping_ratio = rng.uniform(0.02, 0.3);
    const double zeta = p.analysis.required_damping_ratio;
    const Side side = rng.chance(0.5) ? Side::kSlave : Side::kMaster;
    const StiffnessLimit l = max_stable_stiffness(p, side);
    const Reference ref(p, side);
    const std::string what =
        "case " + std::to_string(i) + " zeta " + std::to_string(zeta) + ": " + l.reason;
    if (!ref.admissible(1e-6, zeta)) {
      EXPECT_FALSE(l.max_stable_stiffness_N_per_m.has_value()) << what;
      continue;
    }
    ASSERT_TRUE(l.max_stable_stiffness_N_per_m.has_value()) << what;
    const double k = *l.max_stable_stiffness_N_per_m;
    ASSERT_TRUE(l.limit_crossing_N_per_m.has_value());
    const double crossing = *l.limit_crossing_N_per_m;
    EXPECT_TRUE(ref.admissible(k, zeta)) << what << " at " << k;
    EXPECT_TRUE(ref.admissible(crossing * (1 - 1e-9), zeta)) << what << " at " << crossing;
    EXPECT_FALSE(ref.admissible(crossing * (1 + 1e-9), zeta)) << what << " at " << crossing;
    const std::optional<double> scanned = ref.first_exit(1e-3, 1.3, k, zeta);
    EXPECT_FALSE(scanned.has_value()) << what << ": the reference leaves at " << *scanned;
    ++compared;
  }
  EXPECT_GT(compared, 5);
}

// Soft paddles at 1 kHz, stable however long the round trip (the gains 20 N/m, 1 Ns/m).
TeleopParams slow_delayed_loop(int round_trip_samples) {
  TeleopParams p = window_example();
  p.sample_rate_hz = 1000.0;
  p.scaling = {1.0, 1.0};
  p.master_device = {0.04, 2.0};
  p.slave_device = {0.036, 2.0};
  p.velocity_cutoff_hz = 0.0;
  p.human.fixed = {0.01, 3.0, 300.0};
  p.gains = Gains{20, 20, 1, 1, 0, 0, 0};
  p.round_trip_delay_samples = round_trip_samples;
  return p;
}

TEST(ExactLimit, TwoHundredSamplesOfRoundTripAreExactToo) {
  const TeleopParams p = slow_delayed_loop(200);
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  const Reference ref(p, Side::kSlave);
  ASSERT_TRUE(ref.admissible(1e-6, 0.0)) << "the delayed loop is stable without a wall";
  ASSERT_TRUE(l.max_stable_stiffness_N_per_m.has_value()) << l.reason;
  const double k = *l.max_stable_stiffness_N_per_m;
  // Degree 206: the reference's roots take about a second each, so three points. Past 24
  // states the limit is 1e-6 under its crossing (no per-mode error bound to step by).
  ASSERT_TRUE(l.limit_crossing_N_per_m.has_value());
  const double crossing = *l.limit_crossing_N_per_m;
  EXPECT_NEAR(k, crossing * (1 - 1e-6), 1e-9 * crossing);
  EXPECT_TRUE(ref.admissible(k, 0.0));
  EXPECT_FALSE(ref.admissible(crossing * (1 + 1e-9), 0.0));
  EXPECT_TRUE(ref.admissible(0.5 * k, 0.0));
}

// A round trip of 400 samples with a required damping ratio of 0.5: |z|^-d along the spiral
// reaches e^725 at theta = pi, past the largest double. The delay's column is scaled by z^d
// instead, so the analysis stays finite: such a long loop cannot give every mode a damping ratio
// of 0.5 (its delay modes lie near |z| = 1 all around the circle), and it says so, as the
// spectrum of the whole 406-state loop at zero stiffness does.
TEST(ExactLimit, ALongRoundTripWithARequiredDampingRatioStaysFinite) {
  TeleopParams p = slow_delayed_loop(400);
  p.analysis.required_damping_ratio = 0.5;
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  EXPECT_FALSE(l.max_stable_stiffness_N_per_m.has_value());
  EXPECT_NE(l.reason.find("below the required 0.5"), std::string::npos) << l.reason;
  const LoopEvaluator ev(p, false, true);
  const Spectrum s = ev.spectrum(0, 0.0, 0.0, false);
  EXPECT_LT(s.min_damping_ratio, 0.5);
  EXPECT_TRUE(std::isfinite(s.min_damping_ratio));
}

}  // namespace
}  // namespace teleop::stability
