// The simulator and the analyser agree (issue 3 "Proof"): random teleoperators, simulated
// under the analyser's assumptions from their equilibrium inside the fixtures, settle when the
// predicted minimum damping ratio is above 0.02 and oscillate when it is below -0.02. The
// expected verdicts come from the stability engine, which the stability tests check against
// the papers and an independent 50-digit reference; the simulator shares no code with it.
#include <gtest/gtest.h>

#include <cstdio>

#include "agreement.hpp"

namespace teleop::scene::testing {
namespace {

TEST(Agreement, SimulatorSettlesOrOscillatesAsTheAnalyserPredicts) {
  std::mt19937 rng(20261121);
  CampaignTally tally;
  for (int i = 0; i < 200; ++i) {
    const Case c = random_case(rng, true);
    const Outcome o = run_case(c);
    const double z = c.min_damping_ratio;
    if (CampaignTally::in_band(z)) {
      ++tally.inside_band;
      std::printf("  inside the band: case %d, zeta %.4f, sustained %d, amplitude %.3g m\n", i, z,
                  o.sustained ? 1 : 0, o.amplitude_m);
      continue;
    }
    EXPECT_TRUE(tally.add(z, o.settled, o.sustained))
        << "case " << i << ": predicted zeta " << z << ", spectral radius " << c.spectral_radius
        << ", simulated amplitude " << o.amplitude_m << " m, sustained " << o.sustained
        << ", duration " << c.setup.duration_s;
  }
  tally.print();
  // A campaign of only one kind would prove little.
  EXPECT_GE(tally.stable_cases, 40);
  EXPECT_GE(tally.unstable_cases, 40);
}

TEST(Agreement, TheDecayRateIsTheSpectralRadius) {
  // Inside the fixtures and the analyser's assumptions the simulator is the analysed linear
  // loop: the perturbation shrinks (or grows) like rho^k. Fit it over the run.
  std::mt19937 rng(7);
  int checked = 0;
  for (int i = 0; i < 40 && checked < 10; ++i) {
    Case c = random_case(rng, true);
    if (c.min_damping_ratio < 0.05 || c.spectral_radius > 0.995) continue;
    // Linear only while the perturbation stays inside the engaged fixtures.
    const Equilibrium eq = static_equilibrium(c.analysed, c.setup.equilibrium_push_N);
    const double margin = 10.0 * *c.setup.equilibrium_perturbation_m;
    if ((eq.slave_fixture_engaged && eq.slave_m - c.analysed.slave_fixture.position_m < margin) ||
        (eq.master_fixture_engaged &&
         eq.master_m - c.analysed.master_fixture.position_m < margin)) {
      continue;
    }
    // Long enough for a decay by 1e11: late in the run only the slowest modes remain.
    c.setup.duration_s = std::log(1e11) / -std::log(c.spectral_radius) / c.analysed.sample_rate_hz;
    const SimulationResult r = simulate(c.setup);
    const std::size_t n = r.columns.size();
    const std::size_t rows = r.rows.size() / n;
    // Slave deviation from the equilibrium, envelope over a window at 1/4 and 3/4 of the run.
    auto envelope = [&](std::size_t from, std::size_t to) {
      double m = 0.0;
      for (std::size_t k = from; k < to; ++k) {
        m = std::max(m, std::abs(r.rows[k * n + 2] - r.summary.equilibrium_slave_m));
      }
      return m;
    };
    // Windows of at least two periods of the slowest mode, so the envelope sees its peaks.
    const stability::AnalysisResult a = stability::analyze(c.analysed);
    const double angle = std::abs(std::arg(a.spectrum.modes.front().z));
    const auto period = static_cast<std::size_t>(angle > 0.0 ? 2.0 * 3.14159265 / angle : 1.0);
    const std::size_t w = std::max(rows / 10, 2 * period + 1);
    const std::size_t k1 = std::max(rows / 2, w / 2 + 1);
    const std::size_t k2 = std::min(9 * rows / 10, rows - w / 2 - 1);
    if (k2 <= k1 + w) continue;
    const double a1 = envelope(k1 - w / 2, k1 + w / 2);
    const double a2 = envelope(k2 - w / 2, k2 + w / 2);
    const double rho_fit = std::pow(a2 / a1, 1.0 / static_cast<double>(k2 - k1));
    // The envelope of a window locates its peak to half a period: a percent, not better.
    EXPECT_NEAR(rho_fit, c.spectral_radius, 1e-2) << "case " << i;
    ++checked;
  }
  EXPECT_GE(checked, 5);
}

}  // namespace
}  // namespace teleop::scene::testing
