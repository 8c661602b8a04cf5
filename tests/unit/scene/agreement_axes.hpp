// Shared by the 3-axis agreement test and its bench: random 3-axis teleoperators (coupled mass
// matrices, rotated gain matrices, tilted planes) simulated from their equilibrium inside the
// planes by the n-axis lockstep simulator, next to the n-axis analyser's prediction.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>

#include "common/scene/lockstep_axes.hpp"
#include "common/stability/analysis_axes.hpp"

namespace teleop::scene::testing {

struct AxesCase {
  AxesSceneSetup setup{};
  TeleopAxesParams analysed{};  // the planes engaged at the equilibrium, the others at 0
  double min_damping_ratio{0.0};
  double spectral_radius{0.0};
};

struct AxesOutcome {
  bool settled{false};    // every axis's last window below 1 um
  bool sustained{false};  // the oscillation detector fired on some axis
  double amplitude_m{0.0};
};

// Three draws in this order. The order in which a function's arguments are evaluated is
// unspecified (GCC and clang differ), so no draw is ever an argument next to another draw: the
// cases must be the same whichever compiler built the test.
template <class Draw>
Eigen::Vector3d draw3(Draw draw) {
  const double a = draw();
  const double b = draw();
  const double c = draw();
  return {a, b, c};
}

inline Eigen::Matrix3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  const double w = g(rng);
  const Eigen::Vector3d xyz = draw3([&] { return g(rng); });
  const Eigen::Quaterniond q(w, xyz.x(), xyz.y(), xyz.z());
  return q.normalized().toRotationMatrix();
}

inline Eigen::Vector3d random_unit(std::mt19937& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  return draw3([&] { return g(rng); }).normalized();
}

// R diag(d) R^T: symmetric, its eigenvalues d.
template <class Draw>
Eigen::MatrixXd rotated_diagonal(std::mt19937& rng, bool rotate, Draw draw) {
  const Eigen::Vector3d d = draw3(draw);
  const Eigen::Matrix3d r = rotate ? random_rotation(rng) : Eigen::Matrix3d::Identity();
  return r * d.asDiagonal() * r.transpose();
}

inline AxesCase random_axes_case(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  auto log_uniform = [&](double lo, double hi) { return lo * std::pow(hi / lo, u(rng)); };
  TeleopAxesParams p;
  p.axes = 3;
  p.sample_rate_hz = log_uniform(250.0, 2000.0);
  for (DeviceAxesParams* d : {&p.master_device, &p.slave_device}) {
    d->mass_kg = rotated_diagonal(rng, u(rng) < 0.7, [&] { return log_uniform(0.02, 0.08); });
    d->damping_Ns_per_m = draw3([&] { return log_uniform(0.2, 1.0); });
    d->coulomb_N = Eigen::Vector3d::Zero();
  }
  // Gains: the one-axis campaign's ranges as eigenvalues, rotated half of the time.
  const bool rotate_gains = u(rng) < 0.5;
  const Eigen::Matrix3d rg = rotate_gains ? random_rotation(rng) : Eigen::Matrix3d::Identity();
  auto gain = [&](Eigen::Vector3d d) {
    return Eigen::MatrixXd(rg * d.asDiagonal() * rg.transpose());
  };
  const Eigen::Vector3d kp = draw3([&] { return log_uniform(100.0, 1500.0); });
  const Eigen::Vector3d kd = draw3([&] { return log_uniform(0.5, 8.0); });
  p.gains.kpm = gain(kp);
  p.gains.kps = gain(kp * log_uniform(0.7, 1.4));
  p.gains.kdm = gain(kd);
  p.gains.kds = gain(kd * log_uniform(0.7, 1.4));
  p.gains.kvm = gain(Eigen::Vector3d::Constant(u(rng) < 0.3 ? log_uniform(0.05, 1.0) : 0.0));
  p.gains.kvs = gain(Eigen::Vector3d::Constant(u(rng) < 0.3 ? log_uniform(0.05, 1.0) : 0.0));
  p.gains.kfm = Eigen::MatrixXd::Zero(3, 3);
  p.scaling = {u(rng) < 0.3 ? log_uniform(0.5, 2.0) : 1.0,
               u(rng) < 0.3 ? log_uniform(0.5, 2.0) : 1.0};
  p.velocity_cutoff_hz = u(rng) < 0.5 ? 0.0 : log_uniform(50.0, 300.0);
  p.round_trip_delay_samples = static_cast<int>(u(rng) * 3.0);
  p.human.kind = HumanKind::kFixed;
  p.human.fixed.mass_kg =
      rotated_diagonal(rng, u(rng) < 0.5, [&] { return log_uniform(0.003, 0.012); });
  p.human.fixed.damping_Ns_per_m =
      rotated_diagonal(rng, u(rng) < 0.5, [&] { return log_uniform(0.6, 6.0); });
  p.human.fixed.stiffness_N_per_m =
      rotated_diagonal(rng, u(rng) < 0.5, [&] { return log_uniform(50.0, 900.0); });
  // The slave's plane, tilted at random; a second one half of the time; a master plane 30 %.
  const Eigen::Vector3d n1 = random_unit(rng);
  p.slave_planes.push_back({n1, u(rng) < 0.5 ? 0.0 : 0.002 * u(rng), log_uniform(200.0, 12000.0)});
  if (u(rng) < 0.5) {
    p.slave_planes.push_back({random_unit(rng), 0.0, log_uniform(200.0, 12000.0)});
  }
  if (u(rng) < 0.3) {
    p.master_planes.push_back({random_unit(rng), 0.0, log_uniform(200.0, 12000.0)});
  }

  AxesCase c;
  AxesSceneSetup& s = c.setup;
  s.teleop = p;
  // Push into the first plane, as hard as the one-axis campaign pushes.
  s.push_direction = n1;
  s.push_profile = sim::ForceProfile::constant(2.0);
  s.equilibrium_perturbation_m = Eigen::VectorXd(1e-4 * random_unit(rng));
  const AxesEquilibrium eq = static_equilibrium_axes(p, 2.0 * n1);
  c.analysed = p;
  for (std::size_t j = 0; j < p.master_planes.size(); ++j) {
    if ((eq.master_planes & (1U << j)) == 0) c.analysed.master_planes[j].stiffness_N_per_m = 0.0;
  }
  for (std::size_t j = 0; j < p.slave_planes.size(); ++j) {
    if ((eq.slave_planes & (1U << j)) == 0) c.analysed.slave_planes[j].stiffness_N_per_m = 0.0;
  }
  const stability::AxesAnalysis a = stability::analyze_axes(c.analysed);
  c.min_damping_ratio = a.min_damping_ratio;
  c.spectral_radius = a.spectral_radius;
  // Long enough for the slowest mode to decay by 1e3 one and a half times over (or to grow).
  const double per_step = std::max(1e-6, std::abs(1.0 - a.spectral_radius));
  s.duration_s = std::clamp(1.5 * std::log(1e3) / per_step / p.sample_rate_hz, 2.0, 60.0);
  return c;
}

inline AxesOutcome run_axes_case(const AxesCase& c) {
  AxesOutcome o;
  const AxesSimulationResult r = simulate_axes(c.setup);
  o.amplitude_m =
      std::max(r.summary.oscillation.amplitude_m, r.summary.master_oscillation.amplitude_m);
  o.sustained = r.summary.oscillation.detected || r.summary.master_oscillation.detected;
  o.settled = o.amplitude_m < 1e-6;
  return o;
}

}  // namespace teleop::scene::testing
