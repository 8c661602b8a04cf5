// The law, inside both fixtures with no limit active, is the stability engine's linear model
// (common/stability/discrete_model.cpp, docs/architecture.md §2.5: the paper's eqs. 26-29). The
// expected forces are written here the way the engine's realisation forms them: fixtures lumped
// into the position gains, and ONE filtered differentiator per side applied to the combined
// velocity signal
//   e_m = (beta K_dm + K_vm) x_m - (beta K_dm / alpha) x_s
//   e_s = -(K_ds + K_vs) x_s + alpha K_ds x_m(k - d)
// (the engine's round-trip delay d sits on the master -> slave path), whereas the law filters
// each velocity on its own side and the slave uses the master's transmitted filtered
// velocity. The two agree because the filter is linear and time-invariant.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/unit/control/control_test_util.hpp"

namespace teleop::control {
namespace {

// H(z) = a (z - 1) / (T (z - r)) as a recursion: y(k) = y(k-1) + a ((e(k) - e(k-1)) / T - y(k-1)),
// starting at rest on the first sample.
class FilteredDifferentiator {
 public:
  FilteredDifferentiator(double period_s, double cutoff_hz)
      : t_(period_s),
        a_(cutoff_hz > 0.0 ? 1.0 - std::exp(-2.0 * std::numbers::pi * cutoff_hz * period_s) : 1.0) {
  }
  double operator()(double e) {
    if (!started_) {
      started_ = true;
      last_ = e;
      return y_;
    }
    y_ += a_ * ((e - last_) / t_ - y_);
    last_ = e;
    return y_;
  }

 private:
  double t_;
  double a_;
  bool started_{false};
  double last_{0.0};
  double y_{0.0};
};

struct Case {
  LawParams params;
  int delay{0};  // round trip, on the master -> slave path as in the engine
};

[[nodiscard]] Case random_case(std::mt19937_64& rng, int delay, double cutoff_hz) {
  std::uniform_real_distribution<double> gain(0.0, 1.0);
  Case c;
  LawParams& p = c.params;
  p.period_s = std::uniform_real_distribution<double>(2e-4, 2e-3)(rng);
  p.gains.kpm = 50.0 + 500.0 * gain(rng);
  p.gains.kps = 50.0 + 500.0 * gain(rng);
  p.gains.kdm = 5.0 * gain(rng);
  p.gains.kds = 5.0 * gain(rng);
  p.gains.kvm = 2.0 * gain(rng);
  p.gains.kvs = 2.0 * gain(rng);
  p.gains.kfm = gain(rng);
  p.scaling.position = 0.5 + 2.0 * gain(rng);
  p.scaling.force = 0.2 + 1.5 * gain(rng);
  p.master_fixture = {100.0 + 3000.0 * gain(rng), -0.03 + 0.01 * gain(rng)};  // x_m > -0.02
  p.slave_fixture = {100.0 + 3000.0 * gain(rng), -0.07 + 0.01 * gain(rng)};   // x_s > -0.06
  p.velocity_cutoff_hz = cutoff_hz;
  p.clutch_fade_s = 0.0;
  c.delay = delay;
  return c;
}

// Drives both laws with arbitrary position and force sequences that stay inside both
// fixtures and returns the largest force mismatch relative to the force scale, from sample
// `first_compared` on.
double max_relative_mismatch(const Case& c, std::mt19937_64& rng, int samples, int first_compared) {
  const LawParams& p = c.params;
  const Gains& g = p.gains;
  const double alpha = p.scaling.position;
  const double beta = p.scaling.force;
  const double t = p.period_s;

  // Random walks inside the fixtures (x > p) and an environment force.
  std::normal_distribution<double> step(0.0, 2e-4);
  std::vector<double> xm(static_cast<std::size_t>(samples));
  std::vector<double> xs(xm.size());
  std::vector<double> fe(xm.size());
  double a = 0.0;
  double b = 0.0;
  for (std::size_t k = 0; k < xm.size(); ++k) {
    a = std::clamp(a + step(rng), -0.015, 0.015);
    b = std::clamp(b + step(rng), -0.015, 0.015);
    xm[k] = a;
    xs[k] = alpha * a + b;
    fe[k] = 2.0 * std::sin(0.01 * static_cast<double>(k)) + step(rng) * 1e3;
  }
  for (std::size_t k = 0; k < xm.size(); ++k) {
    EXPECT_GT(xm[k], p.master_fixture.position_m);
    EXPECT_GT(xs[k], p.slave_fixture.position_m);
  }

  MasterLaw master(p);
  SlaveLaw slave(p);
  // What each side transmits, from the test's own per-side filters: the master's state at
  // k - d reaches the slave (the master before sample 0 rested at xm[0]); the slave's state at
  // k reaches the master.
  FilteredDifferentiator own_m(t, p.velocity_cutoff_hz);
  FilteredDifferentiator own_s(t, p.velocity_cutoff_hz);
  std::vector<double> vm(xm.size());
  std::vector<double> vs(xm.size());
  for (std::size_t k = 0; k < xm.size(); ++k) {
    vm[k] = own_m(xm[k]);
    vs[k] = own_s(xs[k]);
  }
  // The engine's combined signals through one differentiator per side.
  FilteredDifferentiator comb_m(t, p.velocity_cutoff_hz);
  FilteredDifferentiator comb_s(t, p.velocity_cutoff_hz);
  const double kpmm = beta * g.kpm + p.master_fixture.stiffness_N_per_m;  // K_pmm
  const double kpss = g.kps + p.slave_fixture.stiffness_N_per_m;          // K_pss

  double worst = 0.0;
  const std::size_t delay = static_cast<std::size_t>(c.delay);
  for (std::size_t k = 0; k < xm.size(); ++k) {
    const std::size_t kd = k >= delay ? k - delay : 0;
    const double xm_d = xm[kd];
    const double vm_d = k >= delay ? vm[kd] : 0.0;

    const Command cm = master.step(xm[k], test::peer(xs[k], vs[k], fe[k]));
    const Command cs = slave.step(xs[k], fe[k], test::peer(xm_d, vm_d));

    const double em = (beta * g.kdm + g.kvm) * xm[k] - (beta * g.kdm / alpha) * xs[k];
    const double es = -(g.kds + g.kvs) * xs[k] + alpha * g.kds * xm_d;
    const double fam = kpmm * xm[k] - (beta * g.kpm / alpha) * xs[k] -
                       p.master_fixture.stiffness_N_per_m * p.master_fixture.position_m +
                       beta * g.kfm * fe[k] + comb_m(em);
    const double fas = -kpss * xs[k] + alpha * g.kps * xm_d +
                       p.slave_fixture.stiffness_N_per_m * p.slave_fixture.position_m + comb_s(es);

    // Master and slave publish what the engine's loop carries.
    EXPECT_EQ(master.peer_state().position_m, xm[k]);
    EXPECT_NEAR(master.peer_state().velocity_m_per_s, vm[k], 1e-9 * (1.0 + std::abs(vm[k])));
    EXPECT_EQ(slave.peer_state().position_m, xs[k]);
    EXPECT_NEAR(slave.peer_state().velocity_m_per_s, vs[k], 1e-9 * (1.0 + std::abs(vs[k])));
    EXPECT_FALSE(cm.flags.saturated || cm.flags.rate_limited || cm.flags.input_fault);
    EXPECT_FALSE(cs.flags.saturated || cs.flags.rate_limited || cs.flags.input_fault ||
                 cs.flags.limit_violation || cs.flags.reference_limited);

    if (k < static_cast<std::size_t>(first_compared)) continue;
    const double scale_m = 1.0 + std::abs(fam) + kpmm * 0.05;
    const double scale_s = 1.0 + std::abs(fas) + kpss * 0.05;
    worst = std::max(worst, std::abs(cm.force_N - fam) / scale_m);
    worst = std::max(worst, std::abs(cs.force_N - fas) / scale_s);
  }
  return worst;
}

TEST(LinearEquivalence, MatchesEngineModelInsideBothFixtures) {
  std::mt19937_64 rng(20240611);
  int cases = 0;
  for (const int delay : {0, 1, 2}) {
    for (const double fc : {0.0, 35.0, 200.0, 2000.0}) {
      for (int rep = 0; rep < 5; ++rep) {
        const Case c = random_case(rng, delay, fc);
        const double worst = max_relative_mismatch(c, rng, 3000, 0);
        EXPECT_LT(worst, 1e-10) << "delay " << delay << " fc " << fc << " rep " << rep;
        ++cases;
      }
    }
  }
  EXPECT_EQ(cases, 60);
}

// With the default clutch fade the coupling fades in at start-up; once faded in (20 ms) the
// law is the engine's again.
TEST(LinearEquivalence, MatchesAfterStartUpFade) {
  std::mt19937_64 rng(7);
  Case c = random_case(rng, 1, 200.0);
  c.params.period_s = 1e-3;
  c.params.clutch_fade_s = 0.02;
  EXPECT_LT(max_relative_mismatch(c, rng, 2000, 21), 1e-10);
  // ... and not before: the fade is real.
  std::mt19937_64 rng2(7);
  Case d = random_case(rng2, 1, 200.0);
  d.params.period_s = 1e-3;
  d.params.clutch_fade_s = 0.02;
  EXPECT_GT(max_relative_mismatch(d, rng2, 2000, 0), 1e-6);
}

}  // namespace
}  // namespace teleop::control
