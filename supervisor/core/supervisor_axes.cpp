// SupervisorCore with several task-space axes (supervisor_core.hpp; docs/architecture.md "The
// supervisor with several axes"): the n-axis report, the monitors per axis and on the vector
// port, guarded changes of plane stiffnesses and gain elements, and the nodes' fingerprints
// against each other.
#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include <array>
#include <chrono>
#include <cmath>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/control_fingerprint.hpp"
#include "common/config/parameter_space.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "supervisor/core/supervisor_core.hpp"

namespace teleop::supervisor {
namespace {

// Why the codec refused a cycle, or why it is not this system's.
std::string refusal(const v1::CycleRecord& c, const std::optional<node::CycleRecordAxes>& r,
                    int axes) {
  if (!r) {
    return fmt::format(
        "cycle {} is malformed (axes {}, {} positions, {} velocities, {} forces: the codec "
        "refuses it)",
        c.sequence(), c.axes(), c.positions_m_size(), c.velocities_m_per_s_size(),
        c.forces_n_size());
  }
  return fmt::format("cycle {} has {} axes, the configuration {}", c.sequence(), r->axes, axes);
}

}  // namespace

void SupervisorCore::publish_axes_report(const std::string& reason) {
  // The file's model with the measured rate and round trip (update_model keeps them in live_).
  TeleopAxesParams p = axes_->params;
  p.sample_rate_hz = live_.sample_rate_hz;
  p.round_trip_delay_samples = live_.round_trip_samples;
  const std::pair<double, int> key{p.sample_rate_hz, p.round_trip_delay_samples};
  auto known = axes_->assessed.find(key);
  if (known == axes_->assessed.end()) {
    known = axes_->assessed.emplace(key, assess_axes(p, p.analysis.required_damping_ratio)).first;
  }
  axes_->assessment = known->second;
  const AxesAssessment& a = axes_->assessment;
  report_ = to_report(
      a, p, ReportContext{now_ns_, master_sequence(), measured_round_trip_ns_, reason, change_id_});
  ports_.report(report_);
  record(record::topic::kStability, report_);
  std::string planes;
  for (const PlaneMargin& m : a.planes) planes += "; " + m.describe();
  spdlog::info("stability ({} axes): {} (min damping ratio {:.4f}, round trip {} samples{}){} [{}]",
               p.axes, report_.verdict(), report_.min_damping_ratio(), report_.round_trip_samples(),
               a.invalid_reason.empty() ? "" : ", " + a.invalid_reason, planes, reason);
}

// Each cycle as n axes (axes_from_proto): positions into the per-axis oscillation monitors,
// f . v into the passivity observer while coupled (the master's port with the measured force,
// the slave's with its opposite, as for one axis). A cycle the codec refuses, or one of another
// number of axes, is skipped and alarmed, never trusted.
void SupervisorCore::feed_axes_monitors(NodeView& n, const v1::Telemetry& t) {
  const int axes = axes_->params.axes;
  const auto count = static_cast<std::size_t>(axes);
  const bool is_master = n.side == Side::kMaster;
  std::uint64_t refused = 0;
  std::string first;
  for (const v1::CycleRecord& c : t.cycles()) {
    const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(c);
    if (!r || r->axes != axes) {
      if (refused++ == 0) first = refusal(c, r, axes);
      continue;
    }
    if (c.mode() != v1::ENGAGED && c.mode() != v1::CLUTCHED) {
      n.oscillation_axes->clear();
      n.passivity_axes->reset();
      continue;
    }
    std::array<double, kMaxAxes> force{};
    for (std::size_t i = 0; i < count; ++i) force[i] = is_master ? r->force_N[i] : -r->force_N[i];
    n.oscillation_axes->add(std::span<const double>(r->position_m.data(), count));
    (void)n.passivity_axes->add(std::span<const double>(force.data(), count),
                                std::span<const double>(r->velocity_m_per_s.data(), count));
  }
  if (refused == 0) return;
  n.refused_cycles += refused;
  alarm(
      v1::Alarm::WARNING, "telemetry", n.name,
      fmt::format("{} of {} cycles refused and not monitored: {}", refused, t.cycles_size(), first),
      {{"refused_cycles", static_cast<double>(refused), ""},
       {"refused_cycles_total", static_cast<double>(n.refused_cycles), ""}});
}

// A sustained oscillation on some axis (the worst named), or else an active vector port.
SupervisorCore::Finding SupervisorCore::axes_finding(NodeView& n) const {
  Finding f;
  if (n.oscillation_axes->full()) {
    const OscillationAxes o = n.oscillation_axes->check();
    if (o.detected()) {
      f.what = fmt::format("{} axis {}: oscillation {:.0f} Hz, {:.2g} mm", n.name, o.worst_axis,
                           o.worst.frequency_hz, o.worst.amplitude_m * 1e3);
      f.kind = "oscillation";
      f.evidence = {{"axis", static_cast<double>(o.worst_axis), ""},
                    {"amplitude", o.worst.amplitude_m * 1e3, "mm"},
                    {"frequency", o.worst.frequency_hz, "Hz"},
                    {"previous_amplitude", o.worst.previous_amplitude_m * 1e3, "mm"}};
      return f;
    }
  }
  const PassivityObserverAxes& p = *n.passivity_axes;
  if (p.energy_J() < -passivity_threshold_J_ &&
      p.recent_power_W() < -passivity_power_threshold_W_) {
    f.what = fmt::format("{}: active port over its {} axes (passivity observer on f . v)", n.name,
                         p.axes());
    f.kind = "passivity";
    f.evidence = {{"energy", p.energy_J(), "J"},
                  {"min_energy", p.min_energy_J(), "J"},
                  {"power_last_second", p.recent_power_W(), "W"}};
  }
  return f;
}

// What a console shows of one node's monitors: the worst axis's oscillation, the port's energy.
MonitorReadings SupervisorCore::axes_readings(const NodeView& n) const {
  MonitorReadings r;
  if (n.oscillation_axes->full()) {
    const OscillationAxes o = n.oscillation_axes->check();
    r.oscillation_amplitude_m = o.worst.amplitude_m;
    r.oscillation_frequency_hz = o.worst.frequency_hz;
    r.oscillating = o.detected();
  }
  r.passivity_energy_J = n.passivity_axes->energy_J();
  return r;
}

// A change request with several axes: refused, nothing sent to a node (a RETUNE carries the
// one-axis gains and fixtures, and n > 1 nodes refuse every RETUNE). Recorded and published as
// every decided change is.
void SupervisorCore::refuse_axes_change(const v1::ParameterChangeRequest& c,
                                        v1::SupervisorReply& reply) {
  v1::ParameterChangeReply& refused = *reply.mutable_change();
  refused.set_accepted(false);
  std::string reason = fmt::format(
      "refused: guarded parameter changes are not supported with {} axes yet in their one-axis "
      "form (a fixture stiffness a side, scalar gains): name the plane or the gain element "
      "(slave.planes[0].stiffness_N_per_m=..., gains.kps[0,0]=...); nothing was sent to the "
      "nodes",
      axes_->params.axes);
  *refused.mutable_prediction() = report_;
  // A fixture stiffness asked for: what the n-axis guard would say, every plane of that side at
  // it (the one-axis request names one stiffness a side). Gains are not assessed here. Not with
  // a human band: the guard's ramp checks over a band take seconds (11 s for cartesian3), which
  // the supervisor's loop cannot spare while it watches the nodes.
  const bool stiffness =
      c.has_master_fixture_stiffness_n_per_m() || c.has_slave_fixture_stiffness_n_per_m();
  if (stiffness && axes_->params.human.kind == HumanKind::kBand) {
    reason +=
        "; the n-axis guard's opinion is not computed in the supervisor's loop with a human band "
        "(`teleopctl analyze FILE --set ...` gives every plane's limit)";
  } else if (stiffness) {
    TeleopAxesParams current = axes_->params;
    current.sample_rate_hz = live_.sample_rate_hz;
    current.round_trip_delay_samples = live_.round_trip_samples;
    TeleopAxesParams proposed = current;
    if (c.has_master_fixture_stiffness_n_per_m()) {
      for (PlaneFixtureParams& p : proposed.master_planes) {
        p.stiffness_N_per_m = c.master_fixture_stiffness_n_per_m();
      }
    }
    if (c.has_slave_fixture_stiffness_n_per_m()) {
      for (PlaneFixtureParams& p : proposed.slave_planes) {
        p.stiffness_N_per_m = c.slave_fixture_stiffness_n_per_m();
      }
    }
    const AxesDecision d = assess_axes_change(current, proposed);
    reason += "; were it applied to every plane of the side, the n-axis guard says: " + d.reason;
    *refused.mutable_prediction() =
        to_report(d.prediction, proposed,
                  ReportContext{now_ns_, master_sequence(), measured_round_trip_ns_,
                                "prediction: requested by " + c.requested_by(), change_id_});
  }
  refused.set_reason(reason);
  v1::ParameterChangeRecord rec;
  *rec.mutable_request() = c;
  *rec.mutable_reply() = refused;
  rec.set_time_ns(now_ns_);
  change_decided(rec);
  spdlog::info("change request ({}): {}", c.requested_by(), refused.reason());
}

namespace {

// The gain matrix `name` names (kpm ... kfm), or nullptr.
Eigen::MatrixXd* gain_matrix(GainsAxes& g, const std::string& name) {
  const std::array<std::pair<const char*, Eigen::MatrixXd*>, 7> all{{{"kpm", &g.kpm},
                                                                     {"kps", &g.kps},
                                                                     {"kdm", &g.kdm},
                                                                     {"kds", &g.kds},
                                                                     {"kvm", &g.kvm},
                                                                     {"kvs", &g.kvs},
                                                                     {"kfm", &g.kfm}}};
  for (const auto& [n, m] : all) {
    if (name == n) return m;
  }
  return nullptr;
}

}  // namespace

TeleopAxesParams SupervisorCore::axes_in_force() const {
  TeleopAxesParams p = axes_->params;
  p.sample_rate_hz = live_.sample_rate_hz;
  p.round_trip_delay_samples = live_.round_trip_samples;
  return p;
}

std::string SupervisorCore::propose_axes(const v1::ParameterChangeRequest& c,
                                         TeleopAxesParams& p) const {
  if (c.has_gains() || c.has_master_fixture_stiffness_n_per_m() ||
      c.has_slave_fixture_stiffness_n_per_m()) {
    return "the one-axis fields (gains' scalars, a fixture stiffness a side) given with plane "
           "stiffnesses or gain elements: give every value in the n-axis form";
  }
  for (const v1::PlaneStiffnessChange& s : c.plane_stiffness()) {
    std::vector<PlaneFixtureParams>& planes = s.slave() ? p.slave_planes : p.master_planes;
    const char* side = s.slave() ? "slave" : "master";
    if (s.plane() >= planes.size()) {
      return fmt::format("{}.planes[{}]: the {} has {} plane(s) (numbered from 0)", side, s.plane(),
                         side, planes.size());
    }
    planes[s.plane()].stiffness_N_per_m = s.stiffness_n_per_m();
  }
  const auto n = static_cast<std::uint32_t>(p.axes);
  for (const v1::GainElementChange& g : c.gain_element()) {
    Eigen::MatrixXd* m = gain_matrix(p.gains, g.gain());
    if (m == nullptr) {
      return fmt::format("gains.{}: not a gain (kpm, kps, kdm, kds, kvm, kvs or kfm)", g.gain());
    }
    if (g.every_axis()) {
      *m = g.value() * Eigen::MatrixXd::Identity(p.axes, p.axes);
    } else if (g.row() >= n || g.column() >= n) {
      return fmt::format("gains.{}[{},{}]: rows and columns are 0 to {} ({} axes)", g.gain(),
                         g.row(), g.column(), n - 1, n);
    } else {
      // Both (row, column) and (column, row): a gain matrix stays symmetric.
      (*m)(g.row(), g.column()) = g.value();
      (*m)(g.column(), g.row()) = g.value();
    }
  }
  return {};
}

v1::ParameterUpdate SupervisorCore::axes_update(const TeleopAxesParams& p, std::uint64_t id,
                                                std::uint64_t at) const {
  v1::ParameterUpdate u;
  u.set_change_id(id);
  u.set_axes(static_cast<std::uint32_t>(p.axes));
  v1::Gains& g = *u.mutable_gains();
  const std::array<std::pair<const Eigen::MatrixXd*, google::protobuf::RepeatedField<double>*>, 7>
      matrices{{{&p.gains.kpm, g.mutable_kpm_matrix()},
                {&p.gains.kps, g.mutable_kps_matrix()},
                {&p.gains.kdm, g.mutable_kdm_matrix()},
                {&p.gains.kds, g.mutable_kds_matrix()},
                {&p.gains.kvm, g.mutable_kvm_matrix()},
                {&p.gains.kvs, g.mutable_kvs_matrix()},
                {&p.gains.kfm, g.mutable_kfm_matrix()}}};
  for (const auto& [m, out] : matrices) {
    for (int r = 0; r < p.axes; ++r) {
      for (int c = 0; c < p.axes; ++c) out->Add((*m)(r, c));
    }
  }
  for (const PlaneFixtureParams& plane : p.master_planes) {
    u.add_master_plane_stiffness_n_per_m(plane.stiffness_N_per_m);
  }
  for (const PlaneFixtureParams& plane : p.slave_planes) {
    u.add_slave_plane_stiffness_n_per_m(plane.stiffness_N_per_m);
  }
  u.set_apply_at_master_sequence(at);
  u.set_ramp_ms(change_ramp_ms_);
  return u;
}

v1::SystemConfig SupervisorCore::axes_config_in_force() const {
  v1::SystemConfig c = axes_->source.config;
  if (change_id_ == 0) return c;
  const v1::ParameterUpdate u = axes_update(axes_->params, 0, 0);
  *c.mutable_gains() = u.gains();  // the seven matrices
  for (const auto& [side, values] :
       {std::pair{c.mutable_master(), &u.master_plane_stiffness_n_per_m()},
        std::pair{c.mutable_slave(), &u.slave_plane_stiffness_n_per_m()}}) {
    v1::Fixture& f = *side->mutable_fixture();
    for (int i = 0; i < f.plane_size() && i < values->size(); ++i) {
      f.mutable_plane(i)->set_stiffness_n_per_m(values->Get(i));
    }
  }
  return c;
}

void SupervisorCore::axes_change_decided(const v1::ParameterChangeRequest& c,
                                         const v1::ParameterChangeReply& reply) {
  if (!reply.pending()) last_axes_change_ = reply;
  v1::ParameterChangeRecord rec;
  *rec.mutable_request() = c;
  *rec.mutable_reply() = reply;
  rec.set_time_ns(now_ns_);
  change_decided(rec);
  spdlog::info("change request {} ({}): {}", reply.request_id(), c.requested_by(), reply.reason());
}

// Checked here (the field named), analysed beside the loop: the reply says pending.
void SupervisorCore::request_axes_change(const v1::ParameterChangeRequest& c,
                                         v1::SupervisorReply& reply) {
  v1::ParameterChangeReply& r = *reply.mutable_change();
  r.set_request_id(++axes_requests_);
  const TeleopAxesParams current = axes_in_force();
  TeleopAxesParams proposed = current;
  std::string why;
  if (axes_change_) {
    why = fmt::format("change request {} is still being assessed; ask again once it is decided",
                      axes_change_->request_id);
  } else {
    why = propose_axes(c, proposed);
  }
  if (why.empty()) {
    // The one parameter space: what the nodes will check, checked before anything is analysed.
    why = config::check_parameter_update_axes(axes_update(proposed, 1, 0), proposed.axes,
                                              static_cast<int>(proposed.master_planes.size()),
                                              static_cast<int>(proposed.slave_planes.size()));
  }
  if (!why.empty()) {
    r.set_accepted(false);
    r.set_reason("refused: " + why);
    *r.mutable_prediction() = report_;
    axes_change_decided(c, r);
    return;
  }
  axes_change_ =
      AxesChange{c, r.request_id(), proposed, std::async(std::launch::async, [current, proposed] {
                   return assess_axes_change(current, proposed);
                 })};
  r.set_pending(true);
  r.set_reason(fmt::format(
      "pending: change request {} is being analysed by the n-axis guard beside the supervisor's "
      "loop; the decision follows in the supervisor's status (last_change)",
      r.request_id()));
  *r.mutable_prediction() = report_;
  spdlog::info("change request {} ({}): analysing", r.request_id(), c.requested_by());
}

// From tick(): the analysis done, the change decided (and, accepted, sent to both nodes).
void SupervisorCore::finish_axes_change() {
  if (!axes_change_ ||
      axes_change_->decision.wait_for(std::chrono::seconds(0)) != std::future_status::ready) {
    return;
  }
  AxesChange change = std::move(*axes_change_);
  axes_change_.reset();
  AxesDecision d;
  try {
    d = change.decision.get();
  } catch (const std::exception& e) {
    d.accepted = false;
    d.reason = std::string("refused: the guard's analysis failed: ") + e.what();
  }
  v1::ParameterChangeReply reply;
  reply.set_request_id(change.request_id);
  apply_axes_change(change, d, reply);
  axes_change_decided(change.request, reply);
}

void SupervisorCore::apply_axes_change(const AxesChange& change, const AxesDecision& d,
                                       v1::ParameterChangeReply& reply) {
  const v1::ParameterChangeRequest& c = change.request;
  const std::string who =
      "requested by " + (c.requested_by().empty() ? std::string("operator") : c.requested_by());
  *reply.mutable_prediction() =
      to_report(d.prediction, change.proposed,
                ReportContext{now_ns_, master_sequence(), measured_round_trip_ns_,
                              "prediction: " + who, change_id_});
  reply.set_reason(d.reason);
  if (!d.accepted || c.dry_run()) {
    reply.set_accepted(d.accepted && c.dry_run());
    if (d.accepted) reply.set_reason(d.reason + " (dry run: not applied)");
    return;
  }
  if (!master_.last || !slave_.last) {
    reply.set_accepted(false);
    reply.set_reason("refused: both nodes must be running to apply a change");
    return;
  }
  const std::uint64_t id = std::max(change_id_, last_sent_change_id_) + 1;
  const std::uint64_t at =
      master_sequence() + static_cast<std::uint64_t>(std::lround(0.2 * params_.sample_rate_hz));
  v1::NodeCommand cmd;
  cmd.set_kind(v1::NodeCommand::RETUNE);
  *cmd.mutable_update() = axes_update(change.proposed, id, at);
  const v1::ParameterUpdate& u = cmd.update();
  // Approved before it is sent, as for one axis.
  audit_.approve(id,
                 approved_axes(change.proposed.axes, u.gains(), u.master_plane_stiffness_n_per_m(),
                               u.slave_plane_stiffness_n_per_m()));
  last_sent_change_id_ = id;
  if (const Delivery sent = send_to_both(cmd); !sent.refusal.empty()) {
    reply.set_accepted(false);
    reply.set_reason("refused: " + sent.refusal +
                     (sent.master_took ? roll_back(id, sent.refusal) : ""));
    return;
  }
  change_id_ = id;
  axes_->params.gains = change.proposed.gains;
  axes_->params.master_planes = change.proposed.master_planes;
  axes_->params.slave_planes = change.proposed.slave_planes;
  // The guard's prediction is the model in force now (no analysis again in the loop).
  axes_->assessed.clear();
  const std::pair<double, int> key{change.proposed.sample_rate_hz,
                                   static_cast<int>(change.proposed.round_trip_delay_samples)};
  axes_->assessed[key] = d.prediction;
  reply.set_accepted(true);
  reply.set_change_id(id);
  reply.set_apply_at_master_sequence(at);
  publish_axes_report("parameter change " + std::to_string(id) + ": " + who);
}

// The n-axis ladder's lowering (escalation.hpp), as lower_fixtures for one axis: every plane in
// use to half its stiffness, never above half its limit in the assessment in force, as one
// guarded change (requested by "supervisor"), analysed beside the loop like an operator's and
// sent to both nodes once accepted. A lowering that cannot be asked for now (another change
// being assessed) or is refused leaves the ladder's next step, disengaging, to act.
SupervisorCore::Lowering SupervisorCore::lower_planes(const std::string& why) {
  v1::ParameterChangeRequest c;
  c.set_requested_by("supervisor");
  std::string planes;
  for (const auto& [slave, list] : {std::pair{false, &axes_->params.master_planes},
                                    std::pair{true, &axes_->params.slave_planes}}) {
    for (std::size_t i = 0; i < list->size(); ++i) {
      const double now = (*list)[i].stiffness_N_per_m;
      if (!(now > 0.0)) continue;
      double target = 0.5 * now;
      for (const PlaneMargin& m : axes_->assessment.planes) {
        if ((m.side == stability::Side::kSlave) == slave && m.plane == i && m.max_stable_N_per_m) {
          target = std::min(target, 0.5 * *m.max_stable_N_per_m);
        }
      }
      v1::PlaneStiffnessChange& p = *c.add_plane_stiffness();
      p.set_slave(slave);
      p.set_plane(static_cast<std::uint32_t>(i));
      p.set_stiffness_n_per_m(target);
      planes += fmt::format("{}{} plane {} {:.0f} -> {:.0f} N/m", planes.empty() ? "" : ", ",
                            slave ? "slave" : "master", i, now, target);
    }
  }
  if (c.plane_stiffness_size() == 0) return {false, "no plane to lower"};
  spdlog::warn("lowering the planes: {}", why);
  v1::SupervisorReply reply;
  request_axes_change(c, reply);
  if (!reply.change().pending()) {
    return {false, "could not lower the planes: " + reply.change().reason()};
  }
  return {true, fmt::format("lowering the planes (change request {}, analysed by the guard, then "
                            "sent to both nodes): {}",
                            reply.change().request_id(), planes)};
}

// A supervisor (re)started on running n-axis nodes, as for one axis (adopt_parameters_in_force):
// a guarded change an earlier supervisor made (a change number above this one's) is adopted, its
// gain matrices and plane stiffnesses validated first by the rules a RETUNE meets
// (config::check_parameter_update_axes). Values of another shape, or that a RETUNE could not
// carry, are not adopted: the audit then finds them unapproved (CRITICAL, both nodes e-stopped).
void SupervisorCore::adopt_axes_parameters_in_force(const v1::Telemetry& t) {
  const v1::ActiveParameters& a = t.active();
  if (!t.has_active() || a.change_id() <= change_id_) {
    const v1::NodeMode m = t.mode();
    if (m == v1::ALIGNING || m == v1::ENGAGED || m == v1::CLUTCHED) {
      alarm(v1::Alarm::WARNING, "supervisor", "system",
            fmt::format("started with the nodes already {} (configured parameters in force)",
                        v1::NodeMode_Name(t.mode())),
            {});
    }
    return;
  }
  TeleopAxesParams p = axes_->params;
  v1::ParameterUpdate in_force;
  in_force.set_change_id(a.change_id());
  in_force.set_axes(a.axes());
  *in_force.mutable_gains() = a.gains();
  *in_force.mutable_master_plane_stiffness_n_per_m() = a.master_plane_stiffness_n_per_m();
  *in_force.mutable_slave_plane_stiffness_n_per_m() = a.slave_plane_stiffness_n_per_m();
  std::string why = config::check_parameter_update_axes(in_force, p.axes,
                                                        static_cast<int>(p.master_planes.size()),
                                                        static_cast<int>(p.slave_planes.size()));
  if (why.empty()) p.gains = config::gains_axes_of(a.gains(), p.axes, why);
  if (!why.empty()) {
    spdlog::error("change {} in force on the nodes not adopted: {}", a.change_id(), why);
    return;
  }
  for (int i = 0; i < a.master_plane_stiffness_n_per_m_size(); ++i) {
    p.master_planes[static_cast<std::size_t>(i)].stiffness_N_per_m =
        a.master_plane_stiffness_n_per_m(i);
  }
  for (int i = 0; i < a.slave_plane_stiffness_n_per_m_size(); ++i) {
    p.slave_planes[static_cast<std::size_t>(i)].stiffness_N_per_m =
        a.slave_plane_stiffness_n_per_m(i);
  }
  change_id_ = a.change_id();
  last_sent_change_id_ = std::max(last_sent_change_id_, change_id_);
  audit_.adopt(change_id_, approved_axes(p.axes, a.gains(), a.master_plane_stiffness_n_per_m(),
                                         a.slave_plane_stiffness_n_per_m()));
  axes_->params.gains = p.gains;
  axes_->params.master_planes = p.master_planes;
  axes_->params.slave_planes = p.slave_planes;
  axes_->assessed.clear();
  std::string planes;
  for (const auto& [side, list] :
       {std::pair{"master", &p.master_planes}, std::pair{"slave", &p.slave_planes}}) {
    for (std::size_t i = 0; i < list->size(); ++i) {
      planes += fmt::format(", {} plane {} {:.0f} N/m", side, i, (*list)[i].stiffness_N_per_m);
    }
  }
  alarm(v1::Alarm::WARNING, "supervisor", "system",
        fmt::format("started with the nodes already {}: change {} in force, adopted ({} axes{})",
                    v1::NodeMode_Name(t.mode()), a.change_id(), p.axes, planes),
        {{"change_id", static_cast<double>(a.change_id()), ""}});
  publish_axes_report(fmt::format("adopted the parameters in force (change {})", a.change_id()));
  publish_config();
  // Adopted, but not taken on trust: a change that misses the requirement with this
  // supervisor's model (its round trip, its human) disengages both nodes at once, as a model
  // that stops meeting it does; the operator may then lower it with `teleopctl set`.
  if (axes_->assessment.acceptable()) return;
  const auto coupled = [](const NodeView& v) {
    return v.mode == v1::ALIGNING || v.mode == v1::ENGAGED || v.mode == v1::CLUTCHED;
  };
  // Heard from the master first: a coupled master means a coupled slave, not yet heard.
  const bool move = coupled(master_) || coupled(slave_);
  const auto rm = move ? command(Side::kMaster, v1::NodeCommand::DISENGAGE) : std::nullopt;
  const auto rs = move ? command(Side::kSlave, v1::NodeCommand::DISENGAGE) : std::nullopt;
  alarm(v1::Alarm::CRITICAL, "supervisor", "system",
        fmt::format("the adopted change {} does not meet the requirement: {} (least damping "
                    "ratio {:.4f}, required {:.4f})",
                    a.change_id(), report_.verdict(), report_.min_damping_ratio(),
                    report_.required_damping_ratio()),
        {{"min_damping_ratio", axes_->assessment.min_damping_ratio, ""}},
        fmt::format("disengaged both nodes (master {}, slave {})",
                    rm ? v1::NodeMode_Name(rm->mode()) : v1::NodeMode_Name(master_.mode),
                    rs ? v1::NodeMode_Name(rs->mode()) : v1::NodeMode_Name(slave_.mode)));
}

// Several axes: each node's fingerprint against the one both nodes of this file compute
// (config::axes_control_fingerprint), as for one axis; the gains and plane stiffnesses in force
// are the audit's (unapproved values e-stop), so a difference is named by the fingerprints.
std::string SupervisorCore::axes_configuration_mismatch() const {
  const std::uint64_t own = axes_->fingerprint;
  const bool master_differs = master_.last && master_.last->config_fingerprint() != own;
  const bool slave_differs = slave_.last && slave_.last->config_fingerprint() != own;
  if (!master_differs && !slave_differs) return {};
  std::string m = "configuration fingerprints differ: supervisor " + config::fingerprint_hex(own);
  for (const NodeView* n : {&master_, &slave_}) {
    if (!n->last) continue;
    const std::uint64_t f = n->last->config_fingerprint();
    m += ", " + n->name + " " + (f == 0 ? std::string("none") : config::fingerprint_hex(f));
  }
  return m + fmt::format(
                 " ({} axes: the masses, damping, kinematics, planes, gains, scaling, filter, "
                 "round trip, human, analysis, link timing or the experiment flag differ)",
                 axes_->params.axes);
}

}  // namespace teleop::supervisor
