#include "common/runtime/node_retune.hpp"

#include <array>
#include <chrono>
#include <cmath>

#include "common/config/axes_config.hpp"
#include "common/config/parameter_space.hpp"

namespace teleop::runtime {

namespace v1 = teleop::v1;

// A parameter update as the RT core takes it; nullopt with the reason when a value is unusable
// (the one parameter space: the rules the configuration's own fields obey).
std::optional<node::Retune> retune_of(const node::NodeCore& /*core*/, const v1::ParameterUpdate& u,
                                      std::string& why) {
  why = config::check_parameter_update(u);
  if (!why.empty()) return std::nullopt;
  if (u.change_id() == 0) {
    why = "change_id must be > 0";
    return std::nullopt;
  }
  const v1::Gains& g = u.gains();
  node::Retune r;
  r.id = u.change_id();
  r.gains = Gains{g.kpm(), g.kps(), g.kdm(), g.kds(), g.kvm(), g.kvs(), g.kfm()};
  r.master_fixture = {u.master_fixture_stiffness_n_per_m(), u.master_fixture_position_m()};
  r.slave_fixture = {u.slave_fixture_stiffness_n_per_m(), u.slave_fixture_position_m()};
  r.apply_at_master_sequence = u.apply_at_master_sequence();
  r.ramp = std::chrono::nanoseconds(static_cast<long long>(std::llround(u.ramp_ms() * 1e6)));
  return r;
}

// The same for an n-axis node: its axes and planes a side decide what the update must hold
// (config::check_parameter_update_axes, the one parameter space).
std::optional<node::RetuneAxes> retune_of(const node::NodeCoreAxes& core,
                                          const v1::ParameterUpdate& u, std::string& why) {
  const control::LawAxesParams& law = core.settings().law;
  if (u.axes() == 0) {
    why =
        "guarded parameter changes are not supported for n > 1 axes in the one-axis form "
        "(this node has " +
        std::to_string(law.axes) +
        " axes: an update gives axes, the gain matrices and every plane's stiffness)";
    return std::nullopt;
  }
  why = config::check_parameter_update_axes(u, law.axes, law.master_planes.size(),
                                            law.slave_planes.size());
  if (!why.empty()) return std::nullopt;
  if (u.change_id() == 0) {
    why = "change_id must be > 0";
    return std::nullopt;
  }
  const GainsAxes g = config::gains_axes_of(u.gains(), law.axes, why);
  if (!why.empty()) return std::nullopt;
  control::LawGainsAxes gains;
  gains.kpm = g.kpm;
  gains.kps = g.kps;
  gains.kdm = g.kdm;
  gains.kds = g.kds;
  gains.kvm = g.kvm;
  gains.kvs = g.kvs;
  gains.kfm = g.kfm;
  node::RetuneAxes r;
  r.id = u.change_id();
  r.gains = node::gain_values(gains, law.axes);
  for (int i = 0; i < u.master_plane_stiffness_n_per_m_size(); ++i) {
    r.master_planes_N_per_m[static_cast<std::size_t>(i)] = u.master_plane_stiffness_n_per_m(i);
  }
  for (int i = 0; i < u.slave_plane_stiffness_n_per_m_size(); ++i) {
    r.slave_planes_N_per_m[static_cast<std::size_t>(i)] = u.slave_plane_stiffness_n_per_m(i);
  }
  r.apply_at_master_sequence = u.apply_at_master_sequence();
  r.ramp = std::chrono::nanoseconds(static_cast<long long>(std::llround(u.ramp_ms() * 1e6)));
  return r;
}

void fill_active(v1::ActiveParameters& a, const node::ActiveLaw& active) {
  a.set_change_id(active.change_id);
  a.set_applied_at_master_sequence(active.applied_at_master_sequence);
  a.mutable_gains()->set_kpm(active.gains.kpm);
  a.mutable_gains()->set_kps(active.gains.kps);
  a.mutable_gains()->set_kdm(active.gains.kdm);
  a.mutable_gains()->set_kds(active.gains.kds);
  a.mutable_gains()->set_kvm(active.gains.kvm);
  a.mutable_gains()->set_kvs(active.gains.kvs);
  a.mutable_gains()->set_kfm(active.gains.kfm);
  a.set_master_fixture_stiffness_n_per_m(active.master_fixture.stiffness_N_per_m);
  a.set_slave_fixture_stiffness_n_per_m(active.slave_fixture.stiffness_N_per_m);
  a.set_ramp_progress(active.ramp_progress);
}

// n axes: the gains as n x n matrices, every plane's stiffness.
void fill_active(v1::ActiveParameters& a, const node::ActiveLawAxes& active) {
  a.set_change_id(active.change_id);
  a.set_applied_at_master_sequence(active.applied_at_master_sequence);
  a.set_axes(static_cast<std::uint32_t>(active.axes));
  v1::Gains& g = *a.mutable_gains();
  const std::array<google::protobuf::RepeatedField<double>*, node::kGainMatrices> matrices{
      g.mutable_kpm_matrix(), g.mutable_kps_matrix(), g.mutable_kdm_matrix(),
      g.mutable_kds_matrix(), g.mutable_kvm_matrix(), g.mutable_kvs_matrix(),
      g.mutable_kfm_matrix()};
  const auto used = static_cast<std::size_t>(active.axes * active.axes);
  for (std::size_t m = 0; m < node::kGainMatrices; ++m) {
    for (std::size_t i = 0; i < used; ++i) matrices[m]->Add(active.gains[m][i]);
  }
  for (int i = 0; i < active.master_planes; ++i) {
    a.add_master_plane_stiffness_n_per_m(active.master_planes_N_per_m[static_cast<std::size_t>(i)]);
  }
  for (int i = 0; i < active.slave_planes; ++i) {
    a.add_slave_plane_stiffness_n_per_m(active.slave_planes_N_per_m[static_cast<std::size_t>(i)]);
  }
  a.set_ramp_progress(active.ramp_progress);
}

}  // namespace teleop::runtime
