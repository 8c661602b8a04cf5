// Issue 7 "Numbers at the edges", the short CI campaign: the analyser on seeded random and
// adversarial configurations (100 Hz-100 kHz, 1 g-10 kg, stiffness up to 1e6 N/m, near-critical
// damping, marginal modes at z = 1, round trips of 0-10 samples) against the independent
// 50-digit reference. Expected values come only from the reference (campaign.hpp); the engine's
// own error bounds decide what "agrees" means. The long campaign and its report table are
// bench/campaign_analyser.cpp, whose first cases these are (same seed).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <iostream>

#include "campaign.hpp"

namespace teleop::campaign {
namespace {

// The bench's default seed: these cases are the first ones of its report.
constexpr std::uint64_t kSeed = 20260807;
// 50-digit roots cost ~10 ms per case (degree up to 16) and a reference stiffness search
// ~50 ms: about 3 s in all here, about 10 s under ASan.
constexpr int kCases = 160;
constexpr int kSearches = 16;

TEST(Campaign, EigenvaluesDampingAndVerdictsAgreeWithTheReferenceWithinTheEngineBounds) {
  std::array<int, 6> checks{};
  std::array<int, kClassCount> per_class{};
  int stable = 0;
  int unstable = 0;
  int marginal = 0;
  int zeta_compared = 0;
  double worst_dz_over_bound = 0.0;
  for (int i = 0; i < kCases; ++i) {
    const Case c = make_case(kSeed, i);
    const CaseResult r = run_case(c);
    const std::string what = describe(c);
    ++per_class[static_cast<std::size_t>(c.cls)];
    ++checks[static_cast<std::size_t>(r.check)];
    (r.ref_marginal ? marginal : (r.ref_verdict == Verdict::kStable ? stable : unstable))++;

    // The reference polynomial is picked by docs/analyze.md's structure rule.
    EXPECT_EQ(r.engine_structure, r.expected) << what;
    EXPECT_EQ(r.engine.verdict, r.engine.spectrum.verdict) << what;  // one human
    // Every engine mode is a root of the reference; what is left over is structural (0).
    EXPECT_FALSE(r.count_mismatch) << what;
    EXPECT_FALSE(r.ref_self_check_failed) << what;
    EXPECT_LE(r.leftover_root_abs, 1e-12) << what;
    // Each eigenvalue within the engine's own stated bound, each damping ratio within what
    // that bound allows (first order, twice over) where it resolves zeta at all.
    for (const ModeComparison& m : r.modes) {
      EXPECT_LE(m.dz, m.error_bound) << what << "\n  z " << m.engine << " reference " << m.ref;
      worst_dz_over_bound = std::max(worst_dz_over_bound, m.dz / m.error_bound);
      if (m.zeta_resolved) {
        ++zeta_compared;
        EXPECT_LE(m.dzeta, m.zeta_bound) << what << "\n  z " << m.engine << " reference " << m.ref;
      }
    }
    if (r.min_zeta_resolved) {
      EXPECT_LE(r.dzeta_min, r.dzeta_min_bound) << what;
    }
    // Outside the bound the verdict is right; within it, uncertain (or right).
    EXPECT_FALSE(is_defect(r.check)) << what << "\n  " << to_string(r.check);
    EXPECT_FALSE(is_defect(r.fast_check)) << what << "\n  fast path " << to_string(r.fast_check);
    // Uncertain only where the bound could matter: never farther than twice it.
    if (r.check == VerdictCheck::kUncertainOutside) {
      EXPECT_FALSE(r.outside_twice_bound) << what;
    }
  }
  std::cout << "campaign " << kCases << " cases: reference stable " << stable << ", unstable "
            << unstable << ", marginal " << marginal << "; outside the bound: "
            << checks[static_cast<std::size_t>(VerdictCheck::kAgreeOutside)] << " agree, "
            << checks[static_cast<std::size_t>(VerdictCheck::kUncertainOutside)]
            << " uncertain; within: "
            << checks[static_cast<std::size_t>(VerdictCheck::kUncertainInside)] << " uncertain, "
            << checks[static_cast<std::size_t>(VerdictCheck::kAgreeInside)]
            << " agree; worst |dz|/bound " << worst_dz_over_bound << "; " << zeta_compared
            << " damping ratios compared\n";
  // The campaign exercises what it claims to.
  for (const int n : per_class) EXPECT_GT(n, 0);
  EXPECT_GT(stable, kCases / 5);
  EXPECT_GT(unstable, kCases / 10);
  EXPECT_GT(marginal, 5);
  EXPECT_GT(checks[static_cast<std::size_t>(VerdictCheck::kUncertainInside)], 10);
  EXPECT_GT(checks[static_cast<std::size_t>(VerdictCheck::kAgreeOutside)], kCases / 2);
}

TEST(Campaign, MaximumStableStiffnessAgreesWithTheReferenceCrossing) {
  int searched = 0;
  int finite = 0;
  int justified = 0;
  double worst_rel = 0.0;
  for (int i = 0; searched < kSearches && i < 10 * kSearches; ++i) {
    const Case c = make_case(kSeed, i);
    if (!c.search) continue;
    ++searched;
    // The reference scans x1.05 (finer than the engine's x1.2) and bisects to 1e-12.
    const LimitResult l = run_limit(c, 1.05, 1e-12);
    const std::string what = describe(c) + (c.side == Side::kMaster ? "\n  master" : "\n  slave") +
                             " limit: engine " +
                             (l.engine.max_stable_stiffness_N_per_m
                                  ? std::to_string(*l.engine.max_stable_stiffness_N_per_m)
                                  : "none (" + l.engine.reason + ")") +
                             ", reference " + std::to_string(l.ref.pass);
    // A limit on one side only is allowed where the engine's lower end (K = 0, or the tolerance
    // after a marginal K = 0) is within its error bound of the circle.
    if (l.kind_mismatch) {
      EXPECT_TRUE(l.kind_mismatch_justified) << what;
      ++justified;
    }
    // Never stable where the reference is unstable outside the bound, never stopped far below
    // the crossing, never above an unstable window (the fine reference scan would see it).
    EXPECT_FALSE(l.engine_stable_where_ref_unstable) << what;
    EXPECT_FALSE(l.stopped_early) << what;
    EXPECT_FALSE(l.window_missed) << what;
    if (l.both_finite) {
      ++finite;
      EXPECT_GT(l.ref_margin_at_engine, 0.0) << what;  // the engine's limit is stable
      worst_rel = std::max(worst_rel, std::abs(l.rel_error));
    }
  }
  std::cout << "maximum stable stiffness: " << searched << " searches, " << finite
            << " finite on both sides, " << justified
            << " without a limit on one side only (lower end within the bound); worst relative "
               "difference "
            << worst_rel << "\n";
  EXPECT_EQ(searched, kSearches);
  EXPECT_GT(finite, kSearches / 3);
}

TEST(Campaign, TheExtendedReferenceZohKeepsItsDigitsWhereThePlainSeriesLosesThem) {
  // 1 g behind 10 Ns/m at 100 Hz: ||A T|| = 100. The exact phi(1,1) is e^{-100}; the plain
  // series sums terms up to 1e42 to get it, the scaled one stays at 50 digits.
  const Real m("0.001");
  const Real b(10);
  const Real t("0.01");
  const Real exact = exp(-b / m * t);
  const reference::Zoh scaled = scaled_zoh(m, b, Real(0), t);
  EXPECT_LT(static_cast<double>(abs(scaled.phi[1][1] - exact) / exact), 1e-30);
  const reference::Zoh plain = reference::zoh(m, b, Real(0), t);
  EXPECT_GT(static_cast<double>(abs(plain.phi[1][1] - exact) / exact), 1e-3);
  // And where both work they agree (a paper paddle at 1 kHz).
  const reference::Zoh a = scaled_zoh(Real("0.05"), Real("2.41"), Real(300), Real("0.001"));
  const reference::Zoh p = reference::zoh(Real("0.05"), Real("2.41"), Real(300), Real("0.001"));
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) {
      EXPECT_LT(static_cast<double>(abs(a.phi[i][j] - p.phi[i][j])), 1e-45);
    }
    EXPECT_LT(static_cast<double>(abs(a.gamma[i] - p.gamma[i])), 1e-45);
  }
}

TEST(Campaign, SchurCohnAgreesWithTheRoots) {
  // The stiffness search's reference test against the reference's own roots, on the
  // campaign's polynomials away from the circle.
  for (int i = 0; i < 24; ++i) {
    const Case c = make_case(kSeed + 1, i);
    const RefLoop loop(c.params, structure_of(c.params));
    const Poly poly = loop.reduced_polynomial(c.params.master_fixture.stiffness_N_per_m,
                                              c.params.slave_fixture.stiffness_N_per_m);
    const RefSpectrum sp = analyse_roots(reference::roots(poly));
    if (std::abs(sp.radius_margin) < 1e-20) continue;
    EXPECT_EQ(schur_stable(poly), sp.radius_margin > 0.0) << describe(c);
  }
}

}  // namespace
}  // namespace teleop::campaign
