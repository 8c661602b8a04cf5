// The one-axis teleoperator on each of n axes (scalars times the identity), written out rather
// than through to_axes: the reference the n-axis analysis and the n-axis guard reduce to.
#pragma once

#include <Eigen/Core>

#include "common/core/teleop_axes.hpp"
#include "common/core/teleop_params.hpp"

namespace teleop::test {

inline Eigen::MatrixXd identity_times(int n, double v) {
  return Eigen::MatrixXd::Identity(n, n) * v;
}

// The one-axis teleoperator on every one of n axes (scalars times the identity), written out
// here rather than through to_axes; one plane per side with the given normals.
inline TeleopAxesParams isotropic(const TeleopParams& p, int n,
                                  const Eigen::VectorXd& master_normal,
                                  const Eigen::VectorXd& slave_normal) {
  TeleopAxesParams a;
  a.axes = n;
  a.sample_rate_hz = p.sample_rate_hz;
  a.master_device = {identity_times(n, p.master_device.mass_kg),
                     Eigen::VectorXd::Constant(n, p.master_device.damping_Ns_per_m),
                     Eigen::VectorXd::Zero(n)};
  a.slave_device = {identity_times(n, p.slave_device.mass_kg),
                    Eigen::VectorXd::Constant(n, p.slave_device.damping_Ns_per_m),
                    Eigen::VectorXd::Zero(n)};
  a.master_planes = {{master_normal, 0.0, p.master_fixture.stiffness_N_per_m}};
  a.slave_planes = {{slave_normal, 0.0, p.slave_fixture.stiffness_N_per_m}};
  const Gains& g = p.gains;
  a.gains = {identity_times(n, g.kpm), identity_times(n, g.kps), identity_times(n, g.kdm),
             identity_times(n, g.kds), identity_times(n, g.kvm), identity_times(n, g.kvs),
             identity_times(n, g.kfm)};
  a.scaling = p.scaling;
  a.velocity_cutoff_hz = p.velocity_cutoff_hz;
  a.round_trip_delay_samples = p.round_trip_delay_samples;
  a.human.kind = p.human.kind;
  a.human.fixed = {identity_times(n, p.human.fixed.mass_kg),
                   identity_times(n, p.human.fixed.damping_Ns_per_m),
                   identity_times(n, p.human.fixed.stiffness_N_per_m)};
  if (p.human.kind == HumanKind::kBand)
    a.human.band_per_axis.assign(static_cast<std::size_t>(n), p.human.band);
  a.analysis = p.analysis;
  return a;
}

}  // namespace teleop::test
