// Shared by the agreement test and its bench: random teleoperators simulated from their
// equilibrium inside the fixtures, next to the analyser's prediction for the same loop.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "common/scene/lockstep.hpp"
#include "common/stability/analyzer.hpp"

namespace teleop::scene::testing {

struct Case {
  SceneSetup setup{};
  TeleopParams analysed{};  // the loop as linearised at the equilibrium (engaged fixtures)
  double min_damping_ratio{0.0};
  double spectral_radius{0.0};
};

struct Outcome {
  Case c{};
  bool settled{false};    // the last window's amplitude is below 1 um
  bool sustained{false};  // the simulator's oscillation detector fired
  double amplitude_m{0.0};
};

// A campaign's tally (test_agreement.cpp, test_agreement_axes.cpp): a case outside the band
// |zeta| <= kBand must settle without a sustained oscillation when zeta > kBand and sustain one
// when zeta < -kBand.
struct CampaignTally {
  static constexpr double kBand = 0.02;
  int outside{0};
  int agree{0};
  int stable_cases{0};
  int unstable_cases{0};
  int inside_band{0};

  [[nodiscard]] static bool in_band(double zeta) { return std::abs(zeta) <= kBand; }
  // One case outside the band; true when the simulation did as predicted.
  bool add(double zeta, bool settled, bool sustained) {
    ++outside;
    const bool ok = zeta > kBand ? (settled && !sustained) : sustained;
    (zeta > kBand ? stable_cases : unstable_cases) += 1;
    agree += ok ? 1 : 0;
    return ok;
  }
  void print() const {
    std::printf("agreement: %d of %d outside |zeta| <= %.2f (%d stable, %d unstable), %d inside\n",
                agree, outside, kBand, stable_cases, unstable_cases, inside_band);
  }
};

inline Case random_case(std::mt19937& rng, bool ideal) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto log_uniform = [&](double lo, double hi) { return lo * std::pow(hi / lo, u(rng)); };
  TeleopParams p;
  p.sample_rate_hz = log_uniform(250.0, 2000.0);
  p.master_device = {log_uniform(0.02, 0.08), log_uniform(0.2, 1.0)};
  p.slave_device = {log_uniform(0.02, 0.08), log_uniform(0.2, 1.0)};
  const double kp = log_uniform(100.0, 1500.0);
  const double kd = log_uniform(0.5, 8.0);
  p.gains = {kp,
             kp * log_uniform(0.7, 1.4),
             kd,
             kd * log_uniform(0.7, 1.4),
             u(rng) < 0.3 ? log_uniform(0.05, 1.0) : 0.0,
             u(rng) < 0.3 ? log_uniform(0.05, 1.0) : 0.0,
             0.0};
  p.scaling = {u(rng) < 0.3 ? log_uniform(0.5, 2.0) : 1.0,
               u(rng) < 0.3 ? log_uniform(0.5, 2.0) : 1.0};
  p.slave_fixture = {log_uniform(200.0, 12000.0), u(rng) < 0.5 ? 0.0 : 0.002 * u(rng)};
  p.master_fixture = {u(rng) < 0.3 ? log_uniform(200.0, 12000.0) : 0.0,
                      u(rng) < 0.5 ? 0.0 : 0.002 * u(rng)};
  p.velocity_cutoff_hz = u(rng) < 0.5 ? 0.0 : log_uniform(50.0, 300.0);
  p.round_trip_delay_samples = static_cast<int>(u(rng) * 3.0);
  p.human.kind = HumanKind::kFixed;
  p.human.fixed = {log_uniform(0.003, 0.012), log_uniform(0.6, 6.0), log_uniform(50.0, 900.0)};

  Case c;
  SceneSetup& s = c.setup;
  s.ideal = ideal;
  s.seed = 1;
  s.teleop = p;
  s.law = control::from_teleop_params(p);
  const double push = 2.0;
  s.master.plant.device = p.master_device;
  s.slave.plant.device = p.slave_device;
  sim::HumanParams h;
  h.profile = sim::ForceProfile::constant(push);
  h.impedance = p.human.fixed;
  s.master.human = h;
  s.equilibrium_push_N = push;
  s.equilibrium_perturbation_m = 1e-4;
  for (device::SimDeviceConfig* d : {&s.master, &s.slave}) {
    d->quantize_position = !ideal;
    d->amplifier.max_force_N = ideal ? 1e12 : 16.5;
    d->load_cell.range_N = ideal ? 1e12 : 10.0;
    d->load_cell.noise_std_N = ideal ? 0.0 : 0.02;
    d->plant.coulomb_friction_N = ideal ? 0.0 : 0.02;
  }
  if (!ideal) {
    s.law.master_actuator.max_force_N = 16.5;
    s.law.slave_actuator.max_force_N = 16.5;
  }
  // The analyser's loop: fixtures lumped where the equilibrium lies inside them.
  const Equilibrium eq = static_equilibrium(p, push);
  c.analysed = p;
  if (!eq.master_fixture_engaged) c.analysed.master_fixture.stiffness_N_per_m = 0.0;
  if (!eq.slave_fixture_engaged) c.analysed.slave_fixture.stiffness_N_per_m = 0.0;
  const stability::AnalysisResult a = stability::analyze(c.analysed);
  c.min_damping_ratio = a.min_damping_ratio;
  c.spectral_radius = a.spectral_radius;
  // Long enough for the slowest mode to decay by 1e-4 twice over (or to grow as much).
  const double per_step = std::max(1e-6, std::abs(1.0 - a.spectral_radius));
  s.duration_s = std::clamp(2.0 * std::log(1e4) / per_step / p.sample_rate_hz, 2.0, 120.0);
  return c;
}

inline Outcome run_case(const Case& c) {
  Outcome o;
  o.c = c;
  const SimulationResult r = simulate(c.setup);
  o.amplitude_m = r.summary.oscillation.amplitude_m;
  o.sustained = r.summary.oscillation.detected || r.summary.master_oscillation.detected;
  o.settled =
      std::max(r.summary.oscillation.amplitude_m, r.summary.master_oscillation.amplitude_m) < 1e-6;
  return o;
}

}  // namespace teleop::scene::testing
