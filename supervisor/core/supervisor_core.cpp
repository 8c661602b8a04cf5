#include "supervisor/core/supervisor_core.hpp"

#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/config/node_loader.hpp"
#include "common/config/parameter_space.hpp"
#include "common/core/defaults.hpp"
#include "supervisor/core/configuration_check.hpp"
#include "supervisor/core/report.hpp"
#include "supervisor/core/session_output.hpp"

namespace teleop::supervisor {
namespace {

Gains from_proto(const v1::Gains& p) {
  return Gains{p.kpm(), p.kps(), p.kdm(), p.kds(), p.kvm(), p.kvs(), p.kfm()};
}

bool coupling(v1::NodeMode m) { return m == v1::ALIGNING || m == v1::ENGAGED || m == v1::CLUTCHED; }

}  // namespace

SupervisorCore::SupervisorCore(const config::LoadedConfig& config, SupervisorOptions options,
                               SupervisorPorts& ports)
    : SupervisorCore(compile_supervised(config), axes_state(config), std::move(options), ports) {}

SupervisorCore::SupervisorCore(config::CompiledSystem system, SupervisorOptions options,
                               SupervisorPorts& ports)
    : SupervisorCore(std::move(system), std::nullopt, std::move(options), ports) {}

std::optional<SupervisorCore::AxesState> SupervisorCore::axes_state(
    const config::LoadedConfig& config) {
  if (!several_axes(config)) return std::nullopt;
  return AxesState{
      config, supervised_axes_params(config), {}, {}, config::axes_control_fingerprint(config)};
}

SupervisorCore::SupervisorCore(config::CompiledSystem system, std::optional<AxesState> axes,
                               SupervisorOptions options, SupervisorPorts& ports)
    : ports_(ports),
      system_(std::move(system)),
      params_(system_.teleop()),
      guard_(params_),
      audit_(ApprovedParameters{params_.gains, params_.master_fixture.stiffness_N_per_m,
                                params_.slave_fixture.stiffness_N_per_m}),
      opts_(std::move(options)) {
  const config::SupervisorSettings& s = system_.supervisor();
  oscillation_threshold_m_ = s.oscillation_threshold_m;
  passivity_threshold_J_ = s.passivity_threshold_J;
  passivity_power_threshold_W_ = s.passivity_power_threshold_W;
  escalation_ns_ = static_cast<std::int64_t>(s.escalation_ms * 1e6);
  change_ramp_ms_ = s.change_ramp_ms;
  // The lowered stiffness is in force once the change applied (0.2 s) and ramped: only
  // evidence from then on may escalate further.
  ladder_ = EscalationLadder(escalation_ns_,
                             200'000'000 + static_cast<std::int64_t>(change_ramp_ms_ * 1e6));
  period_s_ = 1.0 / params_.sample_rate_hz;
  live_ = guard_.configured_inputs();
  // Two free-running loops always add at least one sample of round trip.
  live_.round_trip_samples = std::max(1, live_.round_trip_samples);
  master_.name = "master";
  master_.side = Side::kMaster;
  slave_.name = "slave";
  slave_.side = Side::kSlave;
  for (NodeView* n : {&master_, &slave_}) {
    n->oscillation = std::make_unique<OscillationMonitor>(period_s_, 0.5, oscillation_threshold_m_);
    n->passivity = std::make_unique<PassivityObserver>(period_s_);
  }
  master_.summary = std::make_unique<NodeSummaryBuilder>(true, params_.master_fixture.position_m,
                                                         params_.master_fixture.stiffness_N_per_m,
                                                         5.0, 0.05, params_.scaling.position);
  slave_.summary = std::make_unique<NodeSummaryBuilder>(false, params_.slave_fixture.position_m,
                                                        params_.slave_fixture.stiffness_N_per_m,
                                                        5.0, 0.05, params_.scaling.position);
  axes_ = std::move(axes);
  if (!axes_) return;
  // Change 0: the file's n-axis values (gain matrices, plane stiffnesses), as the nodes report.
  const v1::ParameterUpdate file = axes_update(axes_->params, 0, 0);
  audit_ = ParameterAudit(approved_axes(axes_->params.axes, file.gains(),
                                        file.master_plane_stiffness_n_per_m(),
                                        file.slave_plane_stiffness_n_per_m()));
  for (NodeView* n : {&master_, &slave_}) {
    n->oscillation_axes = std::make_unique<OscillationMonitorAxes>(axes_->params.axes, period_s_,
                                                                   0.5, oscillation_threshold_m_);
    n->passivity_axes = std::make_unique<PassivityObserverAxes>(axes_->params.axes, period_s_);
  }
}

// --- messages out ----------------------------------------------------------------------------
void SupervisorCore::record(std::string_view topic, const google::protobuf::Message& m) {
  if (!opts_.sink) return;
  opts_.sink->record(topic, m.GetDescriptor()->full_name(), log_time_ns(), m.SerializeAsString());
}

void SupervisorCore::record_start() {
  if (!opts_.sink) return;
  record_session_start(*opts_.sink, source(), opts_.config_text, report_, "teleop-supervisor",
                       log_time_ns());
  master_.rt_recorded = false;
  slave_.rt_recorded = false;
}

std::optional<v1::NodeCommandReply> SupervisorCore::command(Side side, v1::NodeCommand::Kind kind) {
  if (opts_.replay) return std::nullopt;
  v1::NodeCommand c;
  c.set_kind(kind);
  return ports_.command(side, c);
}

std::uint64_t SupervisorCore::master_sequence() const {
  if (!master_.last || master_.last->cycles_size() == 0) return 0;
  return master_.last->cycles(master_.last->cycles_size() - 1).sequence();
}

v1::StabilityReport SupervisorCore::make_report(const Assessment& a,
                                                const std::string& reason) const {
  return to_report(
      a, ReportContext{now_ns_, master_sequence(), measured_round_trip_ns_, reason, change_id_});
}

void SupervisorCore::publish_report(const std::string& reason) {
  if (opts_.replay) return;  // the recorded reports are shown (replay_report())
  if (axes_) {
    publish_axes_report(reason);
    return;
  }
  const Assessment& a = guard_.assess(live_);
  report_ = make_report(a, reason);
  ports_.report(report_);
  record(record::topic::kStability, report_);
  spdlog::info("stability: {} (min damping ratio {:.4f}, round trip {} samples) [{}]",
               report_.verdict(), report_.min_damping_ratio(), report_.round_trip_samples(),
               reason);
}

v1::SystemConfig SupervisorCore::config_in_force() const {
  if (axes_) return axes_config_in_force();
  v1::SystemConfig c = system_.source().config;
  *c.mutable_gains() = to_proto(live_.gains);
  // A side without a fixture keeps none while its stiffness in force is 0.
  if (c.master().has_fixture() || live_.master_fixture_N_per_m != 0.0) {
    c.mutable_master()->mutable_fixture()->set_stiffness_n_per_m(live_.master_fixture_N_per_m);
  }
  if (c.slave().has_fixture() || live_.slave_fixture_N_per_m != 0.0) {
    c.mutable_slave()->mutable_fixture()->set_stiffness_n_per_m(live_.slave_fixture_N_per_m);
  }
  return c;
}

void SupervisorCore::publish_config() {
  if (opts_.replay) return;
  const v1::SystemConfig c = config_in_force();
  std::string bytes = c.SerializeAsString();
  if (bytes == published_config_ && now_ns_ - config_published_ns_ < kConfigRepeatNs) return;
  ports_.config(c);
  published_config_ = std::move(bytes);
  config_published_ns_ = now_ns_;
}

void SupervisorCore::change_decided(const v1::ParameterChangeRecord& rec) {
  record(record::topic::kParameterChanges, rec);
  if (!opts_.replay) ports_.parameter_change(rec);
  publish_config();  // at once when it changed the parameters in force
}

void SupervisorCore::alarm(v1::Alarm::Severity severity, const std::string& kind,
                           const std::string& side, const std::string& message,
                           const Evidence& evidence, const std::string& action) {
  if (opts_.replay) return;  // the recorded alarms are shown (replay_alarm())
  const std::string key = kind + "/" + side;
  auto it = last_alarm_ns_.find(key);
  // One of a kind per side per 2 s, unless the supervisor acted, or it is a command's, or a
  // change of the model (its own hold keeps those apart): the newest alarm of those kinds is
  // always what is in force.
  if (severity < v1::Alarm::ACTION && kind != "command" && kind != "round_trip" &&
      it != last_alarm_ns_.end() && now_ns_ - it->second < 2'000'000'000) {
    return;
  }
  last_alarm_ns_[key] = now_ns_;
  v1::Alarm a;
  a.set_time_ns(now_ns_);
  a.set_master_sequence(master_sequence());
  a.set_severity(severity);
  a.set_kind(kind);
  a.set_side(side);
  a.set_message(message);
  a.set_action(action);
  for (const auto& [name, value, unit] : evidence) {
    v1::Evidence* e = a.add_evidence();
    e->set_name(name);
    e->set_value(value);
    e->set_unit(unit);
  }
  replay_alarm(a);
  ports_.alarm(a);
  record(record::topic::kAlarms, a);
  record(record::topic::kLog, to_foxglove_log(a, log_time_ns()));
  std::string ev;
  for (const auto& [name, value, unit] : evidence) {
    ev += fmt::format(" {}={:.6g}{}", name, value, unit);
  }
  const std::string text =
      fmt::format("ALARM {} {} {}: {}{}{}", v1::Alarm::Severity_Name(severity), kind, side, message,
                  ev, action.empty() ? "" : " -> " + action);
  if (severity >= v1::Alarm::WARNING) {
    spdlog::warn("{}", text);
  } else {
    spdlog::info("{}", text);
  }
}

void SupervisorCore::start(std::int64_t now_ns) {
  now_ns_ = now_ns;
  record(record::topic::kConfig, source().config);
  publish_config();
  publish_report("start");
  record_start();
  // Recording was asked for and could not start: said once, loudly, at start.
  if (!opts_.sink && !opts_.record_failure.empty()) {
    alarm(v1::Alarm::CRITICAL, "recorder", "system",
          "not recording: " + opts_.record_failure + " (supervising without recording)", {});
  }
  next_check_ns_ = now_ns;
}

// --- parameter changes -----------------------------------------------------------------------
v1::ParameterUpdate SupervisorCore::make_update(const LiveInputs& proposed, std::uint64_t id,
                                                std::uint64_t at) const {
  v1::ParameterUpdate u;
  u.set_change_id(id);
  *u.mutable_gains() = to_proto(proposed.gains);
  u.set_master_fixture_stiffness_n_per_m(proposed.master_fixture_N_per_m);
  u.set_master_fixture_position_m(params_.master_fixture.position_m);
  u.set_slave_fixture_stiffness_n_per_m(proposed.slave_fixture_N_per_m);
  u.set_slave_fixture_position_m(params_.slave_fixture.position_m);
  u.set_apply_at_master_sequence(at);
  u.set_ramp_ms(change_ramp_ms_);
  return u;
}

v1::ParameterChangeReply SupervisorCore::apply_change(const ChangeRequest& change, bool dry_run,
                                                      const std::string& why) {
  v1::ParameterChangeReply reply;
  const Decision d = guard_.check(live_, change);
  *reply.mutable_prediction() = make_report(d.prediction, "prediction: " + why);
  reply.set_reason(d.reason);
  if (!d.accepted || dry_run) {
    reply.set_accepted(d.accepted && dry_run ? true : false);
    if (d.accepted && dry_run) reply.set_reason(d.reason + " (dry run: not applied)");
    return reply;
  }
  if (!master_.last || !slave_.last) {
    reply.set_accepted(false);
    reply.set_reason("refused: both nodes must be running to apply a change");
    return reply;
  }
  // Never a number sent before, even one whose change a node refused: a reused number
  // could not be told apart in the nodes' telemetry.
  const std::uint64_t id = std::max(change_id_, last_sent_change_id_) + 1;
  const std::uint64_t at =
      master_sequence() + static_cast<std::uint64_t>(std::lround(0.2 * params_.sample_rate_hz));
  v1::NodeCommand c;
  c.set_kind(v1::NodeCommand::RETUNE);
  *c.mutable_update() = make_update(d.proposed, id, at);
  // Approved before it is sent: the nodes may apply it before this thread hears back.
  audit_.approve(id, ApprovedParameters{d.proposed.gains, d.proposed.master_fixture_N_per_m,
                                        d.proposed.slave_fixture_N_per_m});
  last_sent_change_id_ = id;
  if (const Delivery sent = send_to_both(c); !sent.refusal.empty()) {
    reply.set_accepted(false);
    // Nobody took it: nothing changed. The master took it and the slave did not: roll back.
    reply.set_reason("refused: " + sent.refusal +
                     (sent.master_took ? roll_back(id, sent.refusal) : ""));
    return reply;
  }
  change_id_ = id;
  live_ = d.proposed;
  reply.set_accepted(true);
  reply.set_change_id(id);
  reply.set_apply_at_master_sequence(at);
  publish_report("parameter change " + std::to_string(id) + ": " + why);
  return reply;
}

// A RETUNE to the master, then (when the master took it) the slave.
SupervisorCore::Delivery SupervisorCore::send_to_both(const v1::NodeCommand& c) {
  Delivery d;
  for (const NodeView* n : {&master_, &slave_}) {
    const auto r = ports_.command(n->side, c);
    // No reply is no proof the node did not take it: counted as taken, to be rolled back.
    if (n == &master_) d.master_took = !r || r->ok();
    if (!r || !r->ok()) {
      d.refusal = fmt::format("{} did not take the change ({})", n->name,
                              r ? r->message() : std::string("no reply"));
      return d;
    }
  }
  return d;
}

// Change `refused_id` reached one node and not the other: the pair must not run two sets of
// values nobody analysed together. The values in force before go to both under a new change
// number (the refused change, still waiting for its sequence or ramping, is replaced); if that
// fails too, both nodes are e-stopped. Returns what was done, for the refusal's reason.
std::string SupervisorCore::roll_back(std::uint64_t refused_id, const std::string& refusal) {
  const std::uint64_t id = last_sent_change_id_ + 1;
  const std::uint64_t at =
      master_sequence() + static_cast<std::uint64_t>(std::lround(0.2 * params_.sample_rate_hz));
  v1::NodeCommand c;
  c.set_kind(v1::NodeCommand::RETUNE);
  if (axes_) {
    // Several axes: the values in force, gain matrices and planes.
    *c.mutable_update() = axes_update(axes_->params, id, at);
    const v1::ParameterUpdate& u = c.update();
    audit_.approve(id,
                   approved_axes(axes_->params.axes, u.gains(), u.master_plane_stiffness_n_per_m(),
                                 u.slave_plane_stiffness_n_per_m()));
  } else {
    *c.mutable_update() = make_update(live_, id, at);
    audit_.approve(id, ApprovedParameters{live_.gains, live_.master_fixture_N_per_m,
                                          live_.slave_fixture_N_per_m});
  }
  last_sent_change_id_ = id;
  const std::string again = send_to_both(c).refusal;
  if (again.empty()) {
    change_id_ = id;
    alarm(v1::Alarm::WARNING, "parameter_change", "system",
          fmt::format("change {} refused: {}", refused_id, refusal),
          {{"change_id", static_cast<double>(refused_id), ""}},
          fmt::format("rolled back on both nodes (change {})", id));
    return fmt::format("; rolled back on both nodes as change {}", id);
  }
  const auto rm = command(Side::kMaster, v1::NodeCommand::ESTOP);
  const auto rs = command(Side::kSlave, v1::NodeCommand::ESTOP);
  const std::string action =
      fmt::format("e-stopped both nodes (master {}, slave {})",
                  rm ? v1::NodeMode_Name(rm->mode()) : std::string("NO REPLY"),
                  rs ? v1::NodeMode_Name(rs->mode()) : std::string("NO REPLY"));
  alarm(v1::Alarm::CRITICAL, "parameter_change", "system",
        fmt::format("change {} refused ({}) and its roll-back too ({}): the nodes may run "
                    "different parameters",
                    refused_id, refusal, again),
        {{"change_id", static_cast<double>(refused_id), ""}}, action);
  return "; the roll-back failed too (" + again + "): " + action;
}

void SupervisorCore::on_change_request(const v1::ParameterChangeRequest& c,
                                       v1::SupervisorReply& reply) {
  if (axes_) {
    if (c.plane_stiffness_size() > 0 || c.gain_element_size() > 0) {
      request_axes_change(c, reply);
    } else {
      refuse_axes_change(c, reply);
    }
    return;
  }
  if (c.plane_stiffness_size() > 0 || c.gain_element_size() > 0) {
    v1::ParameterChangeReply& refused = *reply.mutable_change();
    refused.set_accepted(false);
    refused.set_reason(
        "refused: plane stiffnesses and gain elements are n-axis fields; this teleoperator is one "
        "axis (master.fixture.stiffness_N_per_m, gains.kps, ...)");
    v1::ParameterChangeRecord rec;
    *rec.mutable_request() = c;
    *rec.mutable_reply() = refused;
    rec.set_time_ns(now_ns_);
    change_decided(rec);
    return;
  }
  // A per-axis list or a matrix would not survive from_proto (the scalars only): refused by
  // name rather than dropped.
  if (const std::string why = config::check_one_axis_gains(c.gains()); !why.empty()) {
    v1::ParameterChangeReply& refused = *reply.mutable_change();
    refused.set_accepted(false);
    refused.set_reason("refused: " + why);
    v1::ParameterChangeRecord rec;
    *rec.mutable_request() = c;
    *rec.mutable_reply() = refused;
    rec.set_time_ns(now_ns_);
    change_decided(rec);
    spdlog::info("change request ({}): {}", c.requested_by(), refused.reason());
    return;
  }
  ChangeRequest change;
  if (c.has_gains()) change.gains = from_proto(c.gains());
  if (c.has_master_fixture_stiffness_n_per_m()) {
    change.master_fixture_N_per_m = c.master_fixture_stiffness_n_per_m();
  }
  if (c.has_slave_fixture_stiffness_n_per_m()) {
    change.slave_fixture_N_per_m = c.slave_fixture_stiffness_n_per_m();
  }
  *reply.mutable_change() = apply_change(
      change, c.dry_run(),
      "requested by " + (c.requested_by().empty() ? std::string("operator") : c.requested_by()));
  v1::ParameterChangeRecord rec;
  *rec.mutable_request() = c;
  *rec.mutable_reply() = reply.change();
  rec.set_time_ns(now_ns_);
  change_decided(rec);
  spdlog::info("change request ({}): {}", c.requested_by(), reply.change().reason());
}

// --- telemetry -------------------------------------------------------------------------------
void SupervisorCore::on_telemetry(Side side, const v1::Telemetry& t, std::int64_t now_ns) {
  now_ns_ = now_ns;
  const bool is_master = side == Side::kMaster;
  NodeView& n = is_master ? master_ : slave_;
  if (n.session_id != 0 && t.session_id() != n.session_id) {
    alarm(v1::Alarm::WARNING, "node_state", n.name, "restarted (new session)",
          {{"session_id", static_cast<double>(t.session_id() % 1000000), ""}});
    n.oscillation->clear();
    n.passivity->reset();
    n.summary->reset();
    if (n.oscillation_axes) n.oscillation_axes->clear();
    if (n.passivity_axes) n.passivity_axes->reset();
    n.newest_change_seen = 0;
    n.unapproved.clear();
  }
  n.session_id = t.session_id();
  if (n.mode != t.mode() && (t.mode() == v1::SAFE || t.mode() == v1::FAULT)) {
    alarm(v1::Alarm::WARNING, "node_state", n.name,
          fmt::format("went {} ({})", v1::NodeMode_Name(t.mode()), t.mode_reason()), {});
  }
  n.mode = t.mode();
  // Several axes: every gain-matrix element and plane stiffness (ActiveParameters.axes) is
  // adopted and audited.
  if (is_master && !heard_master_) {
    heard_master_ = true;
    if (axes_) {
      adopt_axes_parameters_in_force(t);
    } else {
      adopt_parameters_in_force(t);
    }
  }
  n.last = t;
  n.last_received_ns = now_ns;
  // After the master's first message: a change in force on running nodes is adopted then.
  if (heard_master_) audit_parameters(n, t);
  for (const v1::CycleRecord& c : t.cycles()) {
    n.cycle_times.push_back(c.sample_time_ns());
    while (n.cycle_times.size() > 2000) n.cycle_times.pop_front();
    if (!axes_) feed_monitors(c, is_master, *n.oscillation, *n.passivity);
  }
  if (axes_) feed_axes_monitors(n, t);
  n.summary->add(t, now_ns);
  record(record::topic::telemetry(is_master), t);
  if (opts_.sink) {
    record_cycles(*opts_.sink, is_master, t, log_time_ns());
    if (!n.rt_recorded && t.has_rt()) {
      opts_.sink->metadata(is_master ? record::metadata::kRtMaster : record::metadata::kRtSlave,
                           rt_metadata(t.rt()));
      n.rt_recorded = true;
    }
  }
}

// Any parameter in force that this supervisor did not approve (a RETUNE that reached a node
// some other way): CRITICAL, and both nodes e-stopped. Not only disengaged: whoever retuned
// the node can arm and engage it again, and nothing known-good is in force; the e-stop holds
// until an operator clears it, and is repeated while the values stay (a guarded change,
// `teleopctl set`, puts approved values in force).
void SupervisorCore::audit_parameters(NodeView& n, const v1::Telemetry& t) {
  if (!t.has_active()) return;
  const std::vector<ParameterMismatch> mismatches = audit_.check(t.active(), n.newest_change_seen);
  n.newest_change_seen = std::max(n.newest_change_seen, t.active().change_id());
  if (mismatches.empty()) {
    n.unapproved.clear();
    return;
  }
  const std::string what = describe(mismatches);
  // Announced once per change number and set of fields (a ramp's values move every cycle).
  std::string key = std::to_string(t.active().change_id());
  for (const ParameterMismatch& m : mismatches) key += " " + m.field;
  const bool found_now = key != n.unapproved;
  const bool may_move = t.mode() != v1::SAFE && t.mode() != v1::FAULT;
  const bool stop = may_move && now_ns_ - n.unapproved_estop_ns >= 100'000'000;
  if (!found_now && !stop) return;
  n.unapproved = key;
  std::string action;
  if (stop) {
    n.unapproved_estop_ns = now_ns_;
    const auto rm = command(Side::kMaster, v1::NodeCommand::ESTOP);
    const auto rs = command(Side::kSlave, v1::NodeCommand::ESTOP);
    action = fmt::format("e-stopped both nodes (master {}, slave {})",
                         rm ? v1::NodeMode_Name(rm->mode()) : std::string("NO REPLY"),
                         rs ? v1::NodeMode_Name(rs->mode()) : std::string("NO REPLY"));
  }
  Evidence evidence;
  for (const ParameterMismatch& m : mismatches) {
    evidence.emplace_back(m.field + " in force", m.in_force, "");
    evidence.emplace_back(m.field + " approved", m.approved, "");
  }
  alarm(v1::Alarm::CRITICAL, "unapproved_parameters", n.name,
        "parameters in force that the supervisor did not approve: " + what, evidence, action);
}

// A supervisor started (or restarted) while the nodes run: what they run is what counts.
// A guarded change made by an earlier supervisor is adopted (gains, fixtures and the change
// number, so the next change follows it), and the alarm says so.
void SupervisorCore::adopt_parameters_in_force(const v1::Telemetry& t) {
  const v1::ActiveParameters& a = t.active();
  if (t.has_active() && a.change_id() > change_id_) {
    change_id_ = a.change_id();
    last_sent_change_id_ = std::max(last_sent_change_id_, change_id_);
    audit_.adopt(change_id_,
                 ApprovedParameters{from_proto(a.gains()), a.master_fixture_stiffness_n_per_m(),
                                    a.slave_fixture_stiffness_n_per_m()});
    live_.gains = from_proto(a.gains());
    live_.master_fixture_N_per_m = a.master_fixture_stiffness_n_per_m();
    live_.slave_fixture_N_per_m = a.slave_fixture_stiffness_n_per_m();
    alarm(v1::Alarm::WARNING, "supervisor", "system",
          fmt::format("started with the nodes already {}: change {} in force, adopted "
                      "(master fixture {:.0f} N/m, slave fixture {:.0f} N/m)",
                      v1::NodeMode_Name(t.mode()), a.change_id(), live_.master_fixture_N_per_m,
                      live_.slave_fixture_N_per_m),
          {{"change_id", static_cast<double>(a.change_id()), ""}});
    publish_report(fmt::format("adopted the parameters in force (change {})", a.change_id()));
    publish_config();
    // Adopted, not trusted: a change that misses the requirement with this supervisor's model
    // (its round trip, its human) lowers the fixtures, as a model that stops meeting it does,
    // retried until applied (the slave may not have been heard yet).
    if (guard_.assess(live_).acceptable()) return;
    last_lowering_try_ns_ = now_ns_;
    lowering_why_ = fmt::format("the adopted change {} misses the requirement", a.change_id());
    const Lowering l = lower_fixtures(lowering_why_);
    alarm(v1::Alarm::ACTION, "supervisor", "system",
          lowering_why_ + " with this supervisor's model",
          {{"min_damping_ratio", guard_.assess(live_).min_damping_ratio, ""}}, l.action);
    lowering_pending_ = !l.applied;
  } else if (coupling(t.mode())) {
    alarm(v1::Alarm::WARNING, "supervisor", "system",
          fmt::format("started with the nodes already {} (configured parameters in force)",
                      v1::NodeMode_Name(t.mode())),
          {});
  }
}

// --- requests --------------------------------------------------------------------------------
v1::SupervisorReply SupervisorCore::on_request(const v1::SupervisorRequest& req,
                                               const std::string& client_key, std::int64_t now_ns) {
  now_ns_ = now_ns;
  v1::SupervisorReply reply;
  if (const std::string why = read_only_refusal(req, client_key); !why.empty()) {
    reply.set_error(why);
    reply.set_refused_read_only(true);
    spdlog::warn("{}", why);
    return reply;
  }
  try {
    handle_request(req, reply);
    if (reply.has_status()) {
      reply.mutable_status()->set_client_may_command(
          client_key.empty() || std::find(read_only_keys().begin(), read_only_keys().end(),
                                          client_key) == read_only_keys().end());
    }
  } catch (const std::exception& e) {
    reply.set_error(e.what());
  }
  return reply;
}

void SupervisorCore::handle_request(const v1::SupervisorRequest& req, v1::SupervisorReply& reply) {
  if (req.has_change()) {
    on_change_request(req.change(), reply);
  } else if (req.has_node_command()) {
    *reply.mutable_node_command() = forward_node_command(req.node_command());
  } else if (req.has_recording()) {
    set_recording(req.recording().record(), reply);
    fill_status(*reply.mutable_status(), true);
  } else {
    fill_status(*reply.mutable_status(), true);
  }
}

// Whether `request` may come from a client with this key (Z85; empty: no CURVE).
std::string SupervisorCore::read_only_refusal(const v1::SupervisorRequest& req,
                                              const std::string& key) const {
  if (key.empty() ||
      std::find(read_only_keys().begin(), read_only_keys().end(), key) == read_only_keys().end()) {
    return {};
  }
  if (req.has_status()) return {};
  if (req.has_node_command() && (req.node_command().kind() == v1::NodeCommand::ESTOP ||
                                 req.node_command().kind() == v1::NodeCommand::STATUS)) {
    return {};
  }
  if (req.has_change() && req.change().dry_run()) return {};
  return "refused: this client's key " + key +
         " is read-only (security.read_only_client_public_keys): status, predictions and "
         "e-stop only";
}

// A state command from a console, forwarded to the node(s) it names; both nodes' replies
// come back and the outcome is announced (an INFO alarm of kind "command") and recorded.
v1::NodeCommandResult SupervisorCore::forward_node_command(const v1::NodeCommandRequest& r) {
  v1::NodeCommandResult result;
  const v1::NodeCommand::Kind k = r.kind();
  if (k != v1::NodeCommand::ARM && k != v1::NodeCommand::ENGAGE &&
      k != v1::NodeCommand::DISENGAGE && k != v1::NodeCommand::CLUTCH &&
      k != v1::NodeCommand::UNCLUTCH && k != v1::NodeCommand::CLEAR &&
      k != v1::NodeCommand::ESTOP && k != v1::NodeCommand::STATUS) {
    throw std::invalid_argument("node command " + v1::NodeCommand::Kind_Name(k) +
                                " is not forwarded (arm, engage, disengage, clutch, unclutch, "
                                "clear, estop, status; gains through a parameter change)");
  }
  const std::string target = r.target().empty() ? "both" : r.target();
  if (target != "both" && target != "master" && target != "slave") {
    throw std::invalid_argument("node command target '" + target +
                                "' is not master, slave or both");
  }
  // The supervisor analysed its own file: nodes that run another (their fingerprints differ
  // from its own) are not armed or engaged through it, whatever they say to each other.
  if ((k == v1::NodeCommand::ARM || k == v1::NodeCommand::ENGAGE) &&
      !configuration_mismatch_.empty()) {
    throw std::invalid_argument("arm and engage refused by the supervisor: " +
                                configuration_mismatch_);
  }
  std::string summary;
  // An e-stop always goes to both, whatever the first answers.
  for (const NodeView* n : {&master_, &slave_}) {
    if (k != v1::NodeCommand::ESTOP && target != "both" && target != n->name) continue;
    v1::NodeCommandOutcome* o = result.add_outcomes();
    o->set_node(n->name);
    const auto reply = command(n->side, k);
    o->set_replied(reply.has_value());
    if (reply) *o->mutable_reply() = *reply;
    summary +=
        fmt::format("{}{} {}", summary.empty() ? "" : ", ", n->name,
                    reply ? fmt::format("{}{}", v1::NodeMode_Name(reply->mode()),
                                        reply->ok() ? "" : " (refused: " + reply->message() + ")")
                          : std::string("NO REPLY"));
  }
  if (k != v1::NodeCommand::STATUS) {
    alarm(
        k == v1::NodeCommand::ESTOP ? v1::Alarm::WARNING : v1::Alarm::INFO, "command", target,
        fmt::format("{} by {}: {}", v1::NodeCommand::Kind_Name(k),
                    r.requested_by().empty() ? std::string("operator") : r.requested_by(), summary),
        {});
  }
  return result;
}

void SupervisorCore::set_recording(bool on, v1::SupervisorReply& reply) {
  if (!on) {
    if (!opts_.sink) {
      reply.set_error("not recording");
      return;
    }
    const std::string file = opts_.sink->file();
    opts_.sink.reset();  // closes the file: summary and footer written
    alarm(v1::Alarm::INFO, "command", "system", "recording stopped: " + file, {});
    return;
  }
  if (opts_.sink) {
    reply.set_error("already recording to " + opts_.sink->file());
    return;
  }
  if (!opts_.new_sink) {
    reply.set_error("this supervisor cannot start a recording (no record directory)");
    return;
  }
  opts_.sink = opts_.new_sink();
  recorder_failure_announced_ = false;
  record(record::topic::kConfig, source().config);
  record(record::topic::kStability, report_);
  record_start();
  alarm(v1::Alarm::INFO, "command", "system", "recording started: " + opts_.sink->file(), {});
}

// --- status ----------------------------------------------------------------------------------
void SupervisorCore::replay_alarm(const v1::Alarm& a) {
  recent_alarms_.push_front(a);
  while (recent_alarms_.size() > 50) recent_alarms_.pop_back();
}

v1::SupervisorStatus SupervisorCore::status() const {
  v1::SupervisorStatus s;
  fill_status(s, !opts_.replay);
  return s;
}

void SupervisorCore::fill_status(v1::SupervisorStatus& s, bool may_command) const {
  s.set_time_ns(now_ns_);
  s.set_source(opts_.replay ? "replay" : "live");
  if (!opts_.replay || report_replayed_) *s.mutable_report() = report_;
  // The round trip as measured now: the report is re-published only when the model changes
  // (a whole sample, or the rate), so its own figure is the one of that moment (0 in the one
  // published at the start). The model's samples are this figure's, rounded up.
  if (measured_round_trip_ns_ > 0) {
    s.mutable_report()->set_measured_round_trip_ns(measured_round_trip_ns_);
  }
  int shown = 0;
  for (const v1::Alarm& a : recent_alarms_) {
    if (++shown > 20) break;
    *s.add_recent_alarms() = a;
  }
  s.set_record_dir(opts_.record_dir);
  if (opts_.sink) {
    s.set_recording_file(opts_.sink->file());
    s.set_recorded_messages(opts_.sink->recorded());
    s.set_recording_drops(opts_.sink->drops());
    s.set_recording_bytes(opts_.sink->bytes());
    s.set_recording_error(opts_.sink->error());
  } else if (!opts_.record_failure.empty()) {
    s.set_recording_error(opts_.record_failure);
  } else if (replayed_recording_) {
    s.set_recording_file(replayed_recording_->recording_file());
    s.set_recorded_messages(replayed_recording_->recorded_messages());
    s.set_recording_drops(replayed_recording_->recording_drops());
    s.set_recording_bytes(replayed_recording_->recording_bytes());
  }
  s.set_pid(opts_.pid);
  s.set_master_alive(master_.last && now_ns_ - master_.last_received_ns < kHeartbeatNs);
  s.set_slave_alive(slave_.last && now_ns_ - slave_.last_received_ns < kHeartbeatNs);
  master_.summary->fill(
      *s.mutable_master(), now_ns_,
      axes_ ? axes_readings(master_) : read_monitors(*master_.oscillation, *master_.passivity));
  slave_.summary->fill(
      *s.mutable_slave(), now_ns_,
      axes_ ? axes_readings(slave_) : read_monitors(*slave_.oscillation, *slave_.passivity));
  s.set_client_may_command(may_command);
  fill_configuration_status(s);
  if (last_axes_change_.request_id() != 0) *s.mutable_last_change() = last_axes_change_;
}

// docs/nodes.md "Before engage": the fingerprints, each node's own check, the experiment banner.
void SupervisorCore::fill_configuration_status(v1::SupervisorStatus& s) const {
  // Several axes: none of its own yet (its one-axis view's would mislead; the nodes' are
  // compared with each other).
  s.set_config_fingerprint(
      axes_ ? axes_->fingerprint
            : system_.node(transport::Role::kMaster).settings.config_fingerprint);
  s.set_configuration_mismatch(configuration_mismatch_);
  s.set_experiment_banner(experiment_banner(source().config.experiment().allow_unstable(),
                                            master_.last ? &*master_.last : nullptr,
                                            slave_.last ? &*slave_.last : nullptr));
  for (const auto& [view, summary] :
       {std::pair{&master_, s.mutable_master()}, std::pair{&slave_, s.mutable_slave()}}) {
    if (!view->last) continue;
    summary->set_config_fingerprint(view->last->config_fingerprint());
    summary->set_peer_config_fingerprint(view->last->peer_config_fingerprint());
    *summary->mutable_configuration_check() = view->last->configuration_check();
  }
}

}  // namespace teleop::supervisor
