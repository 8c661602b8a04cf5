#include "supervisor/core/axes_supervision.hpp"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <algorithm>
#include <array>
#include <utility>

#include "common/config/axes_config.hpp"

namespace teleop::supervisor {
namespace {

namespace pb = google::protobuf;

// A device's n-axis fields out; the scalars hold axis 0's value where only the list was given.
void device_view(v1::Device& d) {
  if (d.mass_matrix_kg_size() > 0 && !d.has_mass_kg()) d.set_mass_kg(d.mass_matrix_kg(0));
  if (d.damping_ns_per_m_per_axis_size() > 0) {
    d.set_damping_ns_per_m(d.damping_ns_per_m_per_axis(0));
  }
  if (d.coulomb_n_per_axis_size() > 0) d.set_coulomb_friction_n(d.coulomb_n_per_axis(0));
  d.clear_mass_matrix_kg();
  d.clear_damping_ns_per_m_per_axis();
  d.clear_coulomb_n_per_axis();
  d.clear_kinematics();
}

// Each gain g: its g_per_axis or g_matrix element 0 into g when the scalar was not given.
void gains_view(v1::Gains& g) {
  const pb::Descriptor* d = g.GetDescriptor();
  const pb::Reflection* r = g.GetReflection();
  for (const char* name : {"kpm", "kps", "kdm", "kds", "kvm", "kvs", "kfm"}) {
    const pb::FieldDescriptor* scalar = d->FindFieldByName(name);
    for (const char* suffix : {"_per_axis", "_matrix"}) {
      const pb::FieldDescriptor* list = d->FindFieldByName(std::string(name) + suffix);
      if (scalar == nullptr || list == nullptr) continue;
      if (r->FieldSize(g, list) > 0 && r->GetDouble(g, scalar) == 0.0) {
        r->SetDouble(&g, scalar, r->GetRepeatedDouble(g, list, 0));
      }
      r->ClearField(&g, list);
    }
  }
}

const char* side_name(stability::Side s) {
  return s == stability::Side::kMaster ? "master" : "slave";
}

}  // namespace

bool several_axes(const config::LoadedConfig& config) noexcept {
  return config::configured_axes(config.config) > 1;
}

config::LoadedConfig one_axis_view(const config::LoadedConfig& config) {
  config::LoadedConfig out = config;
  v1::SystemConfig& c = out.config;
  c.clear_axes();
  for (v1::Side* s : {c.mutable_master(), c.mutable_slave()}) {
    if (s->has_device()) device_view(*s->mutable_device());
    if (s->has_fixture()) s->mutable_fixture()->clear_plane();
  }
  if (c.has_gains()) gains_view(*c.mutable_gains());
  if (c.has_human() && c.human().band_per_axis_size() > 0) {
    const v1::HumanBand first = c.human().band_per_axis(0);
    c.mutable_human()->clear_band_per_axis();
    *c.mutable_human()->mutable_band() = first;
  }
  if (c.has_scene()) {
    c.mutable_scene()->clear_human_force_direction();
    c.mutable_scene()->clear_environment_plane();
  }
  return out;
}

config::CompiledSystem compile_supervised(const config::LoadedConfig& config) {
  if (!several_axes(config)) return config::compile_system(config);
  return config::compile_system(one_axis_view(config));
}

TeleopAxesParams supervised_axes_params(const config::LoadedConfig& config) {
  TeleopAxesParams p = config::to_axes_params(config);
  p.round_trip_delay_samples = std::max(1, p.round_trip_delay_samples);
  return p;
}

v1::StabilityReport to_report(const AxesAssessment& a, const TeleopAxesParams& params,
                              const ReportContext& context) {
  v1::StabilityReport r;
  r.set_time_ns(context.time_ns);
  r.set_master_sequence(context.master_sequence);
  r.set_verdict(std::string(stability::to_string(a.verdict)));
  r.set_min_damping_ratio(a.min_damping_ratio);
  r.set_required_damping_ratio(a.required_damping_ratio);
  r.set_round_trip_samples(params.round_trip_delay_samples);
  r.set_measured_round_trip_ns(context.measured_round_trip_ns);
  r.set_sample_rate_hz(params.sample_rate_hz);
  r.set_reason(context.reason);
  r.set_parameter_change_id(context.parameter_change_id);
  r.set_axes(params.axes);
  r.set_invalid_reason(a.invalid_reason);
  for (std::size_t i = 0; i < a.planes.size(); ++i) {
    const PlaneMargin& m = a.planes[i];
    const auto& planes =
        m.side == stability::Side::kMaster ? params.master_planes : params.slave_planes;
    v1::PlaneMargin* p = r.add_planes();
    p->set_side(side_name(m.side));
    p->set_index(static_cast<std::uint32_t>(m.plane));
    if (m.plane < planes.size()) {
      const PlaneFixtureParams& plane = planes[m.plane];
      for (Eigen::Index k = 0; k < plane.normal.size(); ++k) p->add_normal(plane.normal(k));
      p->set_offset_m(plane.offset_m);
    }
    p->set_stiffness_n_per_m(m.stiffness_N_per_m);
    if (m.max_stable_N_per_m) p->set_max_stable_stiffness_n_per_m(*m.max_stable_N_per_m);
    if (const auto f = m.fraction_of_limit()) p->set_fraction_of_limit(*f);
    if (const auto g = m.margin()) p->set_margin(*g);
    p->set_reason(m.reason);
    p->set_uncertain(m.uncertain);
    p->set_limiting(a.limiting_plane && *a.limiting_plane == i);
    p->set_description(m.describe());
  }
  // A fixed human is reported as configured (its matrices' diagonals): the analysis of a
  // coupled loop keeps the matrices and names no sample per axis.
  for (std::size_t i = 0; i < a.worst_human.size(); ++i) {
    v1::HumanImpedance* h = r.add_worst_human_per_axis();
    const auto j = static_cast<Eigen::Index>(i);
    if (params.human.kind == HumanKind::kFixed && j < params.human.fixed.mass_kg.rows() &&
        j < params.human.fixed.damping_Ns_per_m.rows() &&
        j < params.human.fixed.stiffness_N_per_m.rows()) {
      h->set_mass_kg(params.human.fixed.mass_kg(j, j));
      h->set_damping_ns_per_m(params.human.fixed.damping_Ns_per_m(j, j));
      h->set_stiffness_n_per_m(params.human.fixed.stiffness_N_per_m(j, j));
    } else {
      h->set_mass_kg(a.worst_human[i].impedance.mass_kg);
      h->set_damping_ns_per_m(a.worst_human[i].impedance.damping_Ns_per_m);
      h->set_stiffness_n_per_m(a.worst_human[i].impedance.stiffness_N_per_m);
    }
  }
  return r;
}

}  // namespace teleop::supervisor
