#include "common/core/teleop_axes.hpp"

namespace teleop {
namespace {

Eigen::MatrixXd scalar(double v) { return Eigen::MatrixXd::Constant(1, 1, v); }

DeviceAxesParams device(const DeviceParams& d) {
  return {scalar(d.mass_kg), Eigen::VectorXd::Constant(1, d.damping_Ns_per_m),
          Eigen::VectorXd::Zero(1)};
}

PlaneFixtureParams plane(const FixtureParams& f) {
  return {Eigen::VectorXd::Constant(1, 1.0), f.position_m, f.stiffness_N_per_m};
}

}  // namespace

TeleopAxesParams to_axes(const TeleopParams& p) {
  TeleopAxesParams a;
  a.axes = 1;
  a.sample_rate_hz = p.sample_rate_hz;
  a.master_device = device(p.master_device);
  a.slave_device = device(p.slave_device);
  a.master_planes = {plane(p.master_fixture)};
  a.slave_planes = {plane(p.slave_fixture)};
  const Gains& g = p.gains;
  a.gains = {scalar(g.kpm), scalar(g.kps), scalar(g.kdm), scalar(g.kds),
             scalar(g.kvm), scalar(g.kvs), scalar(g.kfm)};
  a.scaling = p.scaling;
  a.velocity_cutoff_hz = p.velocity_cutoff_hz;
  a.round_trip_delay_samples = p.round_trip_delay_samples;
  a.human.kind = p.human.kind;
  a.human.fixed = {scalar(p.human.fixed.mass_kg), scalar(p.human.fixed.damping_Ns_per_m),
                   scalar(p.human.fixed.stiffness_N_per_m)};
  if (p.human.kind == HumanKind::kBand) a.human.band_per_axis = {p.human.band};
  a.analysis = p.analysis;
  return a;
}

}  // namespace teleop
