#include "supervisor/core/report.hpp"

namespace teleop::supervisor {

v1::Gains to_proto(const Gains& g) {
  v1::Gains p;
  p.set_kpm(g.kpm);
  p.set_kps(g.kps);
  p.set_kdm(g.kdm);
  p.set_kds(g.kds);
  p.set_kvm(g.kvm);
  p.set_kvs(g.kvs);
  p.set_kfm(g.kfm);
  return p;
}

v1::StabilityReport to_report(const Assessment& a, const ReportContext& context) {
  v1::StabilityReport r;
  r.set_time_ns(context.time_ns);
  r.set_master_sequence(context.master_sequence);
  r.set_verdict(std::string(stability::to_string(a.verdict)));
  r.set_min_damping_ratio(a.min_damping_ratio);
  r.set_required_damping_ratio(a.required_damping_ratio);
  if (a.worst_human) {
    r.mutable_worst_human()->set_mass_kg(a.worst_human->impedance.mass_kg);
    r.mutable_worst_human()->set_damping_ns_per_m(a.worst_human->impedance.damping_Ns_per_m);
    r.mutable_worst_human()->set_stiffness_n_per_m(a.worst_human->impedance.stiffness_N_per_m);
    r.set_worst_human_force_n(a.worst_human->force_N);
  }
  r.set_master_fixture_stiffness_n_per_m(a.inputs.master_fixture_N_per_m);
  r.set_slave_fixture_stiffness_n_per_m(a.inputs.slave_fixture_N_per_m);
  if (a.max_master_N_per_m) r.set_max_stable_master_stiffness_n_per_m(*a.max_master_N_per_m);
  if (a.max_slave_N_per_m) r.set_max_stable_slave_stiffness_n_per_m(*a.max_slave_N_per_m);
  if (const auto c = a.slave_crossings.below_N_per_m) r.set_slave_crossing_below_n_per_m(*c);
  if (const auto c = a.slave_crossings.above_N_per_m) r.set_slave_crossing_above_n_per_m(*c);
  if (const auto c = a.master_crossings.below_N_per_m) r.set_master_crossing_below_n_per_m(*c);
  if (const auto c = a.master_crossings.above_N_per_m) r.set_master_crossing_above_n_per_m(*c);
  if (const auto m = a.master_margin()) r.set_master_margin(*m);
  if (const auto m = a.slave_margin()) r.set_slave_margin(*m);
  r.set_round_trip_samples(a.inputs.round_trip_samples);
  r.set_measured_round_trip_ns(context.measured_round_trip_ns);
  r.set_sample_rate_hz(a.inputs.sample_rate_hz);
  *r.mutable_gains() = to_proto(a.inputs.gains);
  r.set_reason(context.reason);
  r.set_parameter_change_id(context.parameter_change_id);
  return r;
}

}  // namespace teleop::supervisor
