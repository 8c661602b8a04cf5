// Issue 14: a model that is not a number is "invalid", never "stable". kps = 1e308 used to
// overflow the spectral radius to NaN, which every `margin <= error` test passed, and the
// damping ratio printed 1.0000 (std::min drops NaNs).
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <limits>

#include "common/stability/analyzer.hpp"
#include "common/stability/spectrum.hpp"
#include "common/stability/stiffness_search.hpp"

namespace teleop::stability {
namespace {

// The live example (examples/live.textproto): the paper's paddles at 1 kHz, one sample of
// round trip, a fixed human, a slave fixture.
TeleopParams live() {
  TeleopParams p;
  p.sample_rate_hz = 1000.0;
  p.round_trip_delay_samples = 1;
  p.master_device = {0.040, 0.41};
  p.slave_device = {0.036, 0.49};
  p.slave_fixture = {1500.0, 0.006};
  p.gains = {600.0, 600.0, 2.0, 2.0, 0.0, 0.0, 0.0};
  p.velocity_cutoff_hz = 200.0;
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {0.012, 0.76, 70.0};
  return p;
}

void expect_invalid(const AnalysisResult& r, const char* what) {
  EXPECT_EQ(r.verdict, Verdict::kInvalid) << what << ": " << to_string(r.verdict);
  EXPECT_FALSE(r.invalid_reason.empty()) << what;
  EXPECT_TRUE(std::isnan(r.min_damping_ratio)) << what << ": zeta " << r.min_damping_ratio;
  EXPECT_TRUE(std::isnan(r.spectral_radius)) << what << ": radius " << r.spectral_radius;
}

TEST(StabilityInvalid, AGainOf1e308IsAnInvalidModelNeverStable) {
  ASSERT_EQ(analyze(live()).verdict, Verdict::kStable);  // the example itself
  TeleopParams p = live();
  p.gains.kps = 1e308;
  const AnalysisResult r = analyze(p);
  expect_invalid(r, "kps 1e308");
  EXPECT_NE(r.invalid_reason.find("not finite"), std::string::npos) << r.invalid_reason;
  EXPECT_EQ(to_string(r.verdict), "invalid");
}

// Siblings: every input that makes the matrices or the eigenvalues non-finite.
TEST(StabilityInvalid, OverflowingMassesGainsAndFixturesAreInvalid) {
  {
    // A denormal slave mass: the model stays finite here (T / m ~ 1e307) and says unstable, as
    // physics does (k T^2 / m >> 4: a discrete spring on no mass). Never stable.
    TeleopParams p = live();
    p.slave_device.mass_kg = 1e-310;
    EXPECT_EQ(analyze(p).verdict, Verdict::kUnstable);
  }
  {
    TeleopParams p = live();
    p.slave_fixture.stiffness_N_per_m = 1e308;
    expect_invalid(analyze(p), "slave fixture 1e308");
  }
  {
    TeleopParams p = live();
    p.gains.kpm = std::numeric_limits<double>::infinity();
    expect_invalid(analyze(p), "kpm inf");
  }
  {
    TeleopParams p = live();
    p.gains.kds = std::nan("");
    expect_invalid(analyze(p), "kds nan");
  }
  {
    // A band of humans: the sweep finds the invalid member.
    TeleopParams p = live();
    p.human.kind = HumanKind::kBand;
    p.human.band = default_human_band();
    p.gains.kps = 1e308;
    expect_invalid(analyze(p), "band, kps 1e308");
  }
}

TEST(StabilityInvalid, ASpectrumOfANonFiniteMatrixIsInvalidAndMergesAsInvalid) {
  Eigen::MatrixXd a = Eigen::MatrixXd::Identity(3, 3) * 0.5;
  EXPECT_EQ(compute_spectrum(a, 1e-3, 0, true).verdict, Verdict::kStable);
  a(1, 2) = std::nan("");
  const Spectrum bad = compute_spectrum(a, 1e-3, 0, false);
  EXPECT_EQ(bad.verdict, Verdict::kInvalid);
  EXPECT_FALSE(bad.invalid_reason.empty());
  EXPECT_TRUE(std::isnan(bad.min_damping_ratio));
  a(1, 2) = std::numeric_limits<double>::infinity();
  EXPECT_EQ(compute_spectrum(a, 1e-3, 0, true).verdict, Verdict::kInvalid);
  const Spectrum good = compute_spectrum(Eigen::MatrixXd::Identity(2, 2) * 0.5, 1e-3, 0, false);
  EXPECT_EQ(merge({good, bad}).verdict, Verdict::kInvalid);
  EXPECT_EQ(merge({bad, good}).verdict, Verdict::kInvalid);
}

// The stiffness search never counts a non-finite point as stable: no limit, flagged invalid.
TEST(StabilityInvalid, TheStiffnessSearchOfAnInvalidModelGivesNoLimit) {
  TeleopParams p = live();
  p.gains.kps = 1e308;
  const StiffnessLimit l = max_stable_stiffness(p, Side::kSlave);
  EXPECT_FALSE(l.max_stable_stiffness_N_per_m.has_value());
  EXPECT_TRUE(l.invalid);
  EXPECT_NE(l.reason.find("invalid model"), std::string::npos) << l.reason;
}

}  // namespace
}  // namespace teleop::stability
