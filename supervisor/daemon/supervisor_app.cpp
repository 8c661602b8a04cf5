#include "supervisor/daemon/supervisor_app.hpp"

#include <fmt/core.h>
#include <signal.h>
#include <spdlog/sinks/rotating_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <zmq.hpp>

#include "common/config/node_loader.hpp"
#include "common/transport/socket_monitor.hpp"
#include "common/transport/zap_handler.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/core/configuration_check.hpp"
#include "supervisor/core/monitors.hpp"
#include "supervisor/core/parameter_audit.hpp"
#include "supervisor/core/report.hpp"
#include "supervisor/core/stability_guard.hpp"
#include "supervisor/core/status_builder.hpp"
#include "teleop/v1/config.pb.h"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::supervisor {
namespace {

using namespace std::chrono_literals;

// The model's round trip comes down only after the shorter one has held this long.
constexpr std::int64_t kRoundTripHoldNs = 5'000'000'000;
// A main-loop iteration later than this after the previous one: the supervisor itself stalled
// (its poll waits at most 20 ms, a status request takes at most a node command's 0.5 s).
constexpr std::int64_t kOwnStallNs = 250'000'000;

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

Gains from_proto(const v1::Gains& p) {
  return Gains{p.kpm(), p.kps(), p.kdm(), p.kds(), p.kvm(), p.kvs(), p.kfm()};
}

// One node as the supervisor sees it through its telemetry.
struct NodeView {
  std::string name;
  std::optional<v1::Telemetry> last{};
  std::int64_t last_received_ns{0};
  std::uint64_t session_id{0};
  std::uint64_t last_sequence{0};
  v1::NodeMode mode{v1::NODE_MODE_UNSPECIFIED};
  std::uint64_t overruns_at_check{0};
  std::int64_t overrun_check_ns{0};
  std::uint64_t lost_at_check{0};
  std::uint64_t accepted_at_check{0};
  // Cycle timestamps for the measured rate.
  std::deque<std::int64_t> cycle_times{};
  std::unique_ptr<OscillationMonitor> oscillation{};
  std::unique_ptr<PassivityObserver> passivity{};
  std::unique_ptr<NodeSummaryBuilder> summary{};
  double previous_position_m{0.0};
  bool have_position{false};
  std::int64_t oscillating_since_ns{0};
  std::int64_t active_since_ns{0};
  // Parameters in force that the supervisor did not approve (change number and fields), and
  // when it last e-stopped the nodes for them.
  std::string unapproved{};
  std::int64_t unapproved_estop_ns{0};
  std::uint64_t newest_change_seen{0};  // this session's
};

}  // namespace

struct SupervisorApp::Impl {
  Impl(const config::LoadedConfig& config, SupervisorOptions options)
      : loaded(config),
        params(config::to_teleop_params(config)),
        guard(params),
        audit(ApprovedParameters{params.gains, params.master_fixture.stiffness_N_per_m,
                                 params.slave_fixture.stiffness_N_per_m}),
        opts(std::move(options)),
        master_setup(config::to_node_setup(config, transport::Role::kMaster)),
        slave_setup(config::to_node_setup(config, transport::Role::kSlave)) {
    const v1::Supervisor& s = config.config.supervisor();
    report_endpoint = s.report_endpoint().empty() ? "tcp://127.0.0.1:5566" : s.report_endpoint();
    request_endpoint = s.request_endpoint().empty() ? "tcp://127.0.0.1:5567" : s.request_endpoint();
    const double count_m =
        2.0 * 3.141592653589793 * master_setup.sim.encoder.metres_per_radian /
        (master_setup.sim.encoder.counts_per_rev * master_setup.sim.encoder.transmission_ratio);
    oscillation_threshold_m =
        s.has_oscillation_threshold_m() ? s.oscillation_threshold_m() : 2.0 * count_m;
    passivity_threshold_J = s.has_passivity_threshold_j() ? s.passivity_threshold_j() : 0.005;
    passivity_power_threshold_W =
        s.has_passivity_power_threshold_w() ? s.passivity_power_threshold_w() : 0.002;
    escalation_ns =
        static_cast<std::int64_t>((s.has_escalation_ms() ? s.escalation_ms() : 500.0) * 1e6);
    change_ramp_ms = s.has_change_ramp_ms() ? s.change_ramp_ms() : 200.0;
    period_s = 1.0 / params.sample_rate_hz;
    live = guard.configured_inputs();
    // Two free-running loops always add at least one sample of round trip.
    live.round_trip_samples = std::max(1, live.round_trip_samples);
    master.name = "master";
    slave.name = "slave";
    for (NodeView* n : {&master, &slave}) {
      n->oscillation = std::make_unique<OscillationMonitor>(period_s, 0.5, oscillation_threshold_m);
      n->passivity = std::make_unique<PassivityObserver>(period_s);
    }
    master.summary = std::make_unique<NodeSummaryBuilder>(true, params.master_fixture.position_m,
                                                          params.master_fixture.stiffness_N_per_m);
    slave.summary = std::make_unique<NodeSummaryBuilder>(false, params.slave_fixture.position_m,
                                                         params.slave_fixture.stiffness_N_per_m);
    for (const std::string& k : config.config.security().read_only_client_public_keys()) {
      read_only_keys.push_back(k);
    }
    if (!s.secret_key_file().empty()) {
      own_key = transport::load_secret_key_file(s.secret_key_file());
    }
  }

  // --- sockets ---------------------------------------------------------------------------
  zmq::socket_t subscribe(const std::string& endpoint, const std::string& server_key) {
    transport::LinkSecurity sec;
    sec.insecure = loaded.config.security().insecure();
    sec.own = own_key;
    if (own_key && !server_key.empty()) sec.server_public_key = server_key;
    zmq::socket_t s(ctx, zmq::socket_type::sub);
    s.set(zmq::sockopt::linger, 0);
    s.set(zmq::sockopt::rcvhwm, 10000);
    // A node's telemetry with its flight record (10 s of cycles) is ~1-2 MB.
    s.set(zmq::sockopt::maxmsgsize, std::int64_t{16} << 20);
    (void)transport::apply_link_security(ctx, s, endpoint, transport::LinkRole::kClient, sec);
    s.set(zmq::sockopt::subscribe, "");
    s.connect(endpoint);
    return s;
  }

  transport::LinkSecurity server_security() const {
    transport::LinkSecurity sec;
    sec.insecure = loaded.config.security().insecure();
    sec.own = own_key;
    for (const std::string& k : loaded.config.security().client_public_keys()) {
      sec.allowed_client_keys.push_back(k);
    }
    // Read-only consoles connect too; what they may ask is decided per request.
    for (const std::string& k : read_only_keys) sec.allowed_client_keys.push_back(k);
    return sec;
  }

  std::optional<v1::NodeCommandReply> command(const config::NodeSetup& node,
                                              const v1::NodeCommand& c) {
    transport::LinkSecurity sec;
    sec.insecure = loaded.config.security().insecure();
    sec.own = own_key;
    const std::string& key = node.settings.role == transport::Role::kMaster
                                 ? loaded.config.security().master_public_key()
                                 : loaded.config.security().slave_public_key();
    if (own_key && !key.empty()) sec.server_public_key = key;
    zmq::socket_t client = transport::make_command_client(ctx, node.endpoints.command, sec, 500ms);
    const auto bytes = transport::request_reply(client, c.SerializeAsString());
    if (!bytes) return std::nullopt;
    v1::NodeCommandReply r;
    if (!r.ParseFromString(*bytes)) return std::nullopt;
    return r;
  }

  // One topic-tagged message on the report endpoint; never throws (a refused send is dropped,
  // as a full queue drops it).
  void publish(std::string_view topic, const std::string& bytes) {
    if (transport::send_noexcept(*report_pub, topic,
                                 zmq::send_flags::sndmore | zmq::send_flags::dontwait)) {
      (void)transport::send_noexcept(*report_pub, bytes);
    }
  }

  // --- recording ---------------------------------------------------------------------------
  void record(std::string_view topic, const google::protobuf::Message& m) {
    if (!opts.sink) return;
    opts.sink->record(topic, m.GetDescriptor()->full_name(), monotonic_ns(), m.SerializeAsString());
  }

  // --- reports and alarms ------------------------------------------------------------------
  std::uint64_t master_sequence() const {
    if (!master.last || master.last->cycles_size() == 0) return 0;
    return master.last->cycles(master.last->cycles_size() - 1).sequence();
  }

  v1::StabilityReport make_report(const Assessment& a, const std::string& reason) const {
    return to_report(a, ReportContext{monotonic_ns(), master_sequence(), measured_round_trip_ns,
                                      reason, change_id});
  }

  void publish_report(const std::string& reason) {
    const Assessment& a = guard.assess(live);
    report = make_report(a, reason);
    const std::string bytes = report.SerializeAsString();
    publish("report", bytes);
    record(record::topic::kStability, report);
    spdlog::info("stability: {} (min damping ratio {:.4f}, round trip {} samples) [{}]",
                 report.verdict(), report.min_damping_ratio(), report.round_trip_samples(), reason);
  }

  void alarm(v1::Alarm::Severity severity, const std::string& kind, const std::string& side,
             const std::string& message,
             std::vector<std::tuple<std::string, double, std::string>> evidence,
             const std::string& action = "") {
    const std::string key = kind + "/" + side;
    const std::int64_t now = monotonic_ns();
    auto it = last_alarm_ns.find(key);
    // One of a kind per side per 2 s, unless the supervisor acted, or it is a command's, or a
    // change of the model (its own hold keeps those apart): the newest alarm of those kinds is
    // always what is in force.
    if (severity < v1::Alarm::ACTION && kind != "command" && kind != "round_trip" &&
        it != last_alarm_ns.end() && now - it->second < 2'000'000'000) {
      return;
    }
    last_alarm_ns[key] = now;
    v1::Alarm a;
    a.set_time_ns(now);
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
    recent_alarms.push_front(a);
    while (recent_alarms.size() > 50) recent_alarms.pop_back();
    const std::string bytes = a.SerializeAsString();
    publish("alarm", bytes);
    record(record::topic::kAlarms, a);
    std::string ev;
    for (const auto& [name, value, unit] : evidence)
      ev += fmt::format(" {}={:.6g}{}", name, value, unit);
    const std::string text =
        fmt::format("ALARM {} {} {}: {}{}{}", v1::Alarm::Severity_Name(severity), kind, side,
                    message, ev, action.empty() ? "" : " -> " + action);
    if (severity >= v1::Alarm::WARNING) {
      spdlog::warn("{}", text);
    } else {
      spdlog::info("{}", text);
    }
  }

  // --- parameter changes ---------------------------------------------------------------------
  v1::ParameterChangeReply apply_change(const ChangeRequest& change, bool dry_run,
                                        const std::string& why) {
    v1::ParameterChangeReply reply;
    const Decision d = guard.check(live, change);
    *reply.mutable_prediction() = make_report(d.prediction, "prediction: " + why);
    reply.set_reason(d.reason);
    if (!d.accepted || dry_run) {
      reply.set_accepted(d.accepted && dry_run ? true : false);
      if (d.accepted && dry_run) reply.set_reason(d.reason + " (dry run: not applied)");
      return reply;
    }
    if (!master.last || !slave.last) {
      reply.set_accepted(false);
      reply.set_reason("refused: both nodes must be running to apply a change");
      return reply;
    }
    // Never a number sent before, even one whose change a node refused: a reused number
    // could not be told apart in the nodes' telemetry.
    const std::uint64_t id = std::max(change_id, last_sent_change_id) + 1;
    const std::uint64_t at =
        master_sequence() + static_cast<std::uint64_t>(std::lround(0.2 * params.sample_rate_hz));
    v1::NodeCommand c;
    c.set_kind(v1::NodeCommand::RETUNE);
    v1::ParameterUpdate* u = c.mutable_update();
    u->set_change_id(id);
    *u->mutable_gains() = to_proto(d.proposed.gains);
    u->set_master_fixture_stiffness_n_per_m(d.proposed.master_fixture_N_per_m);
    u->set_master_fixture_position_m(params.master_fixture.position_m);
    u->set_slave_fixture_stiffness_n_per_m(d.proposed.slave_fixture_N_per_m);
    u->set_slave_fixture_position_m(params.slave_fixture.position_m);
    u->set_apply_at_master_sequence(at);
    u->set_ramp_ms(change_ramp_ms);
    // Approved before it is sent: the nodes may apply it before this thread hears back.
    audit.approve(id, ApprovedParameters{d.proposed.gains, d.proposed.master_fixture_N_per_m,
                                         d.proposed.slave_fixture_N_per_m});
    last_sent_change_id = id;
    for (const config::NodeSetup* n : {&master_setup, &slave_setup}) {
      const auto r = command(*n, c);
      if (!r || !r->ok()) {
        reply.set_accepted(false);
        reply.set_reason(fmt::format("refused: {} did not take the change ({})",
                                     n == &master_setup ? "master" : "slave",
                                     r ? r->message() : std::string("no reply")));
        return reply;
      }
    }
    change_id = id;
    live = d.proposed;
    reply.set_accepted(true);
    reply.set_change_id(id);
    reply.set_apply_at_master_sequence(at);
    publish_report("parameter change " + std::to_string(id) + ": " + why);
    return reply;
  }

  // --- telemetry -----------------------------------------------------------------------------
  void on_telemetry(NodeView& n, const v1::Telemetry& t, bool is_master) {
    const std::int64_t now = monotonic_ns();
    if (n.session_id != 0 && t.session_id() != n.session_id) {
      alarm(v1::Alarm::WARNING, "node_state", n.name, "restarted (new session)",
            {{"session_id", static_cast<double>(t.session_id() % 1000000), ""}});
      n.oscillation->clear();
      n.passivity->reset();
      n.summary->reset();
      n.newest_change_seen = 0;
      n.unapproved.clear();
    }
    n.session_id = t.session_id();
    if (n.mode != t.mode() && (t.mode() == v1::SAFE || t.mode() == v1::FAULT)) {
      alarm(v1::Alarm::WARNING, "node_state", n.name,
            fmt::format("went {} ({})", v1::NodeMode_Name(t.mode()), t.mode_reason()), {});
    }
    n.mode = t.mode();
    if (is_master && !heard_master) {
      heard_master = true;
      adopt_parameters_in_force(t);
    }
    n.last = t;
    n.last_received_ns = now;
    // After the master's first message: a change in force on running nodes is adopted then.
    if (heard_master) audit_parameters(n, t, now);
    for (const v1::CycleRecord& c : t.cycles()) {
      n.cycle_times.push_back(c.sample_time_ns());
      while (n.cycle_times.size() > 2000) n.cycle_times.pop_front();
      feed_monitors(c, is_master, *n.oscillation, *n.passivity);
    }
    n.summary->add(t, now);
    record(record::topic::telemetry(is_master), t);
  }

  // Any parameter in force that this supervisor did not approve (a RETUNE that reached a node
  // some other way): CRITICAL, and both nodes e-stopped. Not only disengaged: whoever retuned
  // the node can arm and engage it again, and nothing known-good is in force; the e-stop holds
  // until an operator clears it, and is repeated while the values stay (a guarded change,
  // `teleopctl set`, puts approved values in force).
  void audit_parameters(NodeView& n, const v1::Telemetry& t, std::int64_t now) {
    if (!t.has_active()) return;
    const std::vector<ParameterMismatch> mismatches = audit.check(t.active(), n.newest_change_seen);
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
    const bool stop = may_move && now - n.unapproved_estop_ns >= 100'000'000;
    if (!found_now && !stop) return;
    n.unapproved = key;
    std::string action;
    if (stop) {
      n.unapproved_estop_ns = now;
      v1::NodeCommand c;
      c.set_kind(v1::NodeCommand::ESTOP);
      const auto rm = command(master_setup, c);
      const auto rs = command(slave_setup, c);
      action = fmt::format("e-stopped both nodes (master {}, slave {})",
                           rm ? v1::NodeMode_Name(rm->mode()) : std::string("NO REPLY"),
                           rs ? v1::NodeMode_Name(rs->mode()) : std::string("NO REPLY"));
    }
    std::vector<std::tuple<std::string, double, std::string>> evidence;
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
  void adopt_parameters_in_force(const v1::Telemetry& t) {
    const bool running =
        t.mode() == v1::ALIGNING || t.mode() == v1::ENGAGED || t.mode() == v1::CLUTCHED;
    const v1::ActiveParameters& a = t.active();
    if (t.has_active() && a.change_id() > change_id) {
      change_id = a.change_id();
      last_sent_change_id = std::max(last_sent_change_id, change_id);
      audit.adopt(change_id,
                  ApprovedParameters{from_proto(a.gains()), a.master_fixture_stiffness_n_per_m(),
                                     a.slave_fixture_stiffness_n_per_m()});
      live.gains = from_proto(a.gains());
      live.master_fixture_N_per_m = a.master_fixture_stiffness_n_per_m();
      live.slave_fixture_N_per_m = a.slave_fixture_stiffness_n_per_m();
      alarm(v1::Alarm::WARNING, "supervisor", "system",
            fmt::format("started with the nodes already {}: change {} in force, adopted "
                        "(master fixture {:.0f} N/m, slave fixture {:.0f} N/m)",
                        v1::NodeMode_Name(t.mode()), a.change_id(), live.master_fixture_N_per_m,
                        live.slave_fixture_N_per_m),
            {{"change_id", static_cast<double>(a.change_id()), ""}});
      publish_report(fmt::format("adopted the parameters in force (change {})", a.change_id()));
    } else if (running) {
      alarm(v1::Alarm::WARNING, "supervisor", "system",
            fmt::format("started with the nodes already {} (configured parameters in force)",
                        v1::NodeMode_Name(t.mode())),
            {});
    }
  }

  // README "Before engage": both nodes' fingerprints against the supervisor's own; a
  // difference (new or changed) is an alarm naming the fingerprints and, where telemetry shows
  // them, the fields.
  void check_configurations() {
    ApprovedConfiguration approved;
    approved.change_id = change_id;
    approved.gains = live.gains;
    approved.master_fixture_N_per_m = live.master_fixture_N_per_m;
    approved.slave_fixture_N_per_m = live.slave_fixture_N_per_m;
    const ConfigurationMismatch m = compare_configurations(
        master_setup.settings.config_fingerprint, approved, master.last ? &*master.last : nullptr,
        slave.last ? &*slave.last : nullptr);
    if (!m.message.empty() && m.message != configuration_mismatch) {
      alarm(v1::Alarm::WARNING, "configuration", m.side, m.message + " (arm and engage refused)",
            {});
    }
    configuration_mismatch = m.message;
  }

  void check_live() {
    const std::int64_t now = monotonic_ns();
    check_configurations();
    // Heartbeats.
    for (NodeView* n : {&master, &slave}) {
      if (n->last && now - n->last_received_ns > 500'000'000) {
        alarm(v1::Alarm::WARNING, "heartbeat", n->name, "no telemetry for over 0.5 s",
              {{"silent", static_cast<double>(now - n->last_received_ns) * 1e-9, "s"}});
      }
      if (!n->last) continue;
      // Overruns and loss over the last second.
      if (now - n->overrun_check_ns >= 1'000'000'000) {
        const std::uint64_t overruns = n->last->loop().overruns();
        const std::uint64_t lost = n->last->link().lost();
        const std::uint64_t accepted = n->last->link().accepted();
        if (n->overrun_check_ns != 0) {
          const std::uint64_t d_over = overruns - std::min(overruns, n->overruns_at_check);
          if (d_over > 10) {
            alarm(v1::Alarm::WARNING, "overruns", n->name, "loop overran in the last second",
                  {{"overruns", static_cast<double>(d_over), ""},
                   {"wakeup_p99", static_cast<double>(n->last->loop().wakeup_p99_ns()) * 1e-3,
                    "us"}});
          }
          const double d_lost = static_cast<double>(lost - std::min(lost, n->lost_at_check));
          const double d_acc =
              static_cast<double>(accepted - std::min(accepted, n->accepted_at_check));
          if (d_lost + d_acc > 0 && d_lost / (d_lost + d_acc) > 0.01) {
            alarm(v1::Alarm::WARNING, "loss", n->name, "more than 1 % of peer states lost",
                  {{"loss", d_lost / (d_lost + d_acc), ""}});
          }
        }
        n->overruns_at_check = overruns;
        n->lost_at_check = lost;
        n->accepted_at_check = accepted;
        n->overrun_check_ns = now;
      }
    }
    // Measured rate and round trip -> the model.
    LiveInputs next = live;
    if (master.cycle_times.size() > 500) {
      // The median cycle interval: skipped (overrun) cycles do not read as a slower loop.
      std::vector<std::int64_t> d;
      d.reserve(master.cycle_times.size());
      for (std::size_t i = 1; i < master.cycle_times.size(); ++i) {
        d.push_back(master.cycle_times[i] - master.cycle_times[i - 1]);
      }
      std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
      const double rate = 1e9 / static_cast<double>(d[d.size() / 2]);
      // The loops run on a grid: a rate within 0.5 % of the file's is the file's.
      if (std::abs(rate - params.sample_rate_hz) > 0.005 * params.sample_rate_hz) {
        next.sample_rate_hz = rate;
      }
    }
    std::int64_t rtt = 0;
    for (NodeView* n : {&master, &slave}) {
      if (n->last) rtt = std::max(rtt, n->last->link().round_trip_p99_ns());
    }
    // The model's round trip: the largest measured over the last 5 s (down only after that).
    if (rtt > 0) rtt = round_trip_model.add(now, rtt);
    measured_round_trip_ns = rtt;
    if (rtt > 0) {
      const double period_ns = 1e9 / next.sample_rate_hz;
      const int samples =
          std::max(1, static_cast<int>(std::ceil(static_cast<double>(rtt) / period_ns - 1e-9)));
      next.round_trip_samples = std::max(samples, params.round_trip_delay_samples);
    }
    if (!(next == live)) {
      const bool rtt_grew = next.round_trip_samples > live.round_trip_samples;
      live = next;
      alarm(v1::Alarm::INFO, "round_trip", "system",
            fmt::format("model updated: round trip {} samples at {:.1f} Hz",
                        live.round_trip_samples, live.sample_rate_hz),
            {{"round_trip_p99", static_cast<double>(rtt) * 1e-6, "ms"}});
      publish_report(rtt_grew ? "round trip grew" : "measured inputs changed");
      if (rtt_grew && !guard.assess(live).acceptable()) {
        // Announced like every change the supervisor makes: an ACTION alarm naming it.
        const std::string action = lower_fixtures("the measured round trip grew");
        alarm(v1::Alarm::ACTION, "round_trip", "system",
              fmt::format("the model with a {}-sample round trip no longer meets the requirement",
                          live.round_trip_samples),
              {{"round_trip_p99", static_cast<double>(rtt) * 1e-6, "ms"},
               {"min_damping_ratio", guard.assess(live).min_damping_ratio, ""}},
              action);
        lowering_pending = action.rfind("lowered fixtures", 0) != 0;
      }
    }
    // A lowering the guard could not apply (a node's telemetry not in yet, say) is tried again
    // at every check while the model still misses the requirement, until it is applied.
    if (lowering_pending && now - last_lowering_try_ns >= 200'000'000) {
      last_lowering_try_ns = now;
      if (guard.assess(live).acceptable()) {
        lowering_pending = false;
      } else {
        const std::string action = lower_fixtures("the measured round trip grew (retried)");
        if (action.rfind("lowered fixtures", 0) == 0) {
          lowering_pending = false;
          alarm(v1::Alarm::ACTION, "round_trip", "system",
                fmt::format("the model with a {}-sample round trip no longer meets the "
                            "requirement (retried)",
                            live.round_trip_samples),
                {{"round_trip_p99", static_cast<double>(rtt) * 1e-6, "ms"},
                 {"min_damping_ratio", guard.assess(live).min_damping_ratio, ""}},
                action);
        }
      }
    }
    // Oscillation and passivity, with escalation.
    if (escalation_stage == 1 && !settled && now >= escalated_ns) {
      settled = true;
      for (NodeView* n : {&master, &slave}) {
        n->oscillation->clear();
        n->passivity->reset();
        n->oscillating_since_ns = 0;
      }
    }
    bool misbehaving = false;
    for (NodeView* n : {&master, &slave}) {
      std::string what;
      std::vector<std::tuple<std::string, double, std::string>> evidence;
      if (n->oscillation->full()) {
        const scene::Oscillation o = n->oscillation->check();
        if (o.detected) {
          what = "sustained oscillation";
          evidence = {{"amplitude", o.amplitude_m * 1e3, "mm"},
                      {"frequency", o.frequency_hz, "Hz"},
                      {"previous_amplitude", o.previous_amplitude_m * 1e3, "mm"}};
        }
      }
      if (what.empty() && n->passivity->energy_J() < -passivity_threshold_J &&
          n->passivity->recent_power_W() < -passivity_power_threshold_W) {
        what = "active port (passivity observer)";
        evidence = {{"energy", n->passivity->energy_J(), "J"},
                    {"min_energy", n->passivity->min_energy_J(), "J"},
                    {"power_last_second", n->passivity->recent_power_W(), "W"}};
      }
      if (what.empty()) {
        n->oscillating_since_ns = 0;
        continue;
      }
      misbehaving = true;
      if (n->oscillating_since_ns == 0) {
        n->oscillating_since_ns = now;
        // Both nodes hand over their last seconds at full rate (recorded with their telemetry).
        v1::NodeCommand fr;
        fr.set_kind(v1::NodeCommand::FLIGHT_RECORD);
        (void)command(master_setup, fr);
        (void)command(slave_setup, fr);
      }
      const std::int64_t lasting = now - n->oscillating_since_ns;
      const std::string kind = what == "sustained oscillation" ? "oscillation" : "passivity";
      if (lasting < escalation_ns) {
        alarm(v1::Alarm::WARNING, kind, n->name, what, evidence);
      } else if (escalation_stage == 0) {
        escalation_stage = 1;
        // The lowered stiffness is in force once the change applied (0.2 s) and ramped: only
        // evidence from then on may escalate further.
        escalated_ns = now + 200'000'000 + static_cast<std::int64_t>(change_ramp_ms * 1e6);
        settled = false;
        const std::string action = lower_fixtures(what + " on the " + n->name);
        alarm(v1::Alarm::ACTION, kind, n->name, what, evidence, action);
      } else if (escalation_stage == 1 && settled && lasting >= escalation_ns) {
        escalation_stage = 2;
        v1::NodeCommand c;
        c.set_kind(v1::NodeCommand::DISENGAGE);
        auto coupling = [](const NodeView& v) {
          return v.mode == v1::ALIGNING || v.mode == v1::ENGAGED || v.mode == v1::CLUTCHED;
        };
        // A node that already left coupling (the peer's disengage reached it) stays armed.
        const auto rm = coupling(master) ? command(master_setup, c) : std::nullopt;
        const auto rs = coupling(slave) ? command(slave_setup, c) : std::nullopt;
        alarm(v1::Alarm::CRITICAL, kind, n->name, what + " persisted after lowering the fixtures",
              evidence,
              fmt::format("disengaged both nodes (master {}, slave {})",
                          rm ? v1::NodeMode_Name(rm->mode()) : v1::NodeMode_Name(master.mode),
                          rs ? v1::NodeMode_Name(rs->mode()) : v1::NodeMode_Name(slave.mode)));
      }
    }
    if (!misbehaving && escalation_stage != 0 && settled &&
        now - escalated_ns > 2 * escalation_ns) {
      escalation_stage = 0;
    }
  }

  // Lowers the fixtures in use to half their stiffness (never above half the predicted
  // maximum) through the guard; returns what was done.
  std::string lower_fixtures(const std::string& why) {
    ChangeRequest change;
    if (live.master_fixture_N_per_m > 0.0) {
      change.master_fixture_N_per_m = guard.lowered_stiffness(live, false, 0.5);
    }
    if (live.slave_fixture_N_per_m > 0.0) {
      change.slave_fixture_N_per_m = guard.lowered_stiffness(live, true, 0.5);
    }
    if (!change.master_fixture_N_per_m && !change.slave_fixture_N_per_m) {
      return "no fixture to lower";
    }
    const v1::ParameterChangeReply r = apply_change(change, false, "lowered: " + why);
    v1::ParameterChangeRecord rec;
    rec.mutable_request()->set_requested_by("supervisor");
    if (change.master_fixture_N_per_m) {
      rec.mutable_request()->set_master_fixture_stiffness_n_per_m(*change.master_fixture_N_per_m);
    }
    if (change.slave_fixture_N_per_m) {
      rec.mutable_request()->set_slave_fixture_stiffness_n_per_m(*change.slave_fixture_N_per_m);
    }
    *rec.mutable_reply() = r;
    rec.set_time_ns(monotonic_ns());
    record(record::topic::kParameterChanges, rec);
    return r.accepted()
               ? fmt::format("lowered fixtures (change {}): master {:.0f} N/m, slave {:.0f} N/m",
                             r.change_id(), live.master_fixture_N_per_m, live.slave_fixture_N_per_m)
               : "could not lower the fixtures: " + r.reason();
  }

  void on_request(const v1::SupervisorRequest& req, v1::SupervisorReply& reply) {
    if (req.has_change()) {
      const v1::ParameterChangeRequest& c = req.change();
      ChangeRequest change;
      if (c.has_gains()) change.gains = from_proto(c.gains());
      if (c.has_master_fixture_stiffness_n_per_m()) {
        change.master_fixture_N_per_m = c.master_fixture_stiffness_n_per_m();
      }
      if (c.has_slave_fixture_stiffness_n_per_m()) {
        change.slave_fixture_N_per_m = c.slave_fixture_stiffness_n_per_m();
      }
      *reply.mutable_change() =
          apply_change(change, c.dry_run(),
                       "requested by " +
                           (c.requested_by().empty() ? std::string("operator") : c.requested_by()));
      v1::ParameterChangeRecord rec;
      *rec.mutable_request() = c;
      *rec.mutable_reply() = reply.change();
      rec.set_time_ns(monotonic_ns());
      record(record::topic::kParameterChanges, rec);
      spdlog::info("change request ({}): {}", c.requested_by(), reply.change().reason());
    } else if (req.has_node_command()) {
      *reply.mutable_node_command() = forward_node_command(req.node_command());
    } else if (req.has_recording()) {
      set_recording(req.recording().record(), reply);
      fill_status(*reply.mutable_status(), true);
    } else {
      fill_status(*reply.mutable_status(), true);
    }
  }

  void fill_status(v1::SupervisorStatus& s, bool may_command) const {
    const std::int64_t now = monotonic_ns();
    s.set_time_ns(now);
    s.set_source("live");
    *s.mutable_report() = report;
    // The round trip as measured now: the report is re-published only when the model changes
    // (a whole sample, or the rate), so its own figure is the one of that moment (0 in the one
    // published at the start). The model's samples are this figure's, rounded up.
    if (measured_round_trip_ns > 0) {
      s.mutable_report()->set_measured_round_trip_ns(measured_round_trip_ns);
    }
    int shown = 0;
    for (const v1::Alarm& a : recent_alarms) {
      if (++shown > 20) break;
      *s.add_recent_alarms() = a;
    }
    s.set_record_dir(opts.record_dir);
    if (opts.sink) {
      s.set_recording_file(opts.sink->file());
      s.set_recorded_messages(opts.sink->recorded());
      s.set_recording_drops(opts.sink->drops());
      s.set_recording_bytes(opts.sink->bytes());
      s.set_recording_error(opts.sink->error());
    } else if (!opts.record_failure.empty()) {
      s.set_recording_error(opts.record_failure);
    }
    s.set_pid(static_cast<std::uint32_t>(::getpid()));
    s.set_master_alive(master.last && now - master.last_received_ns < 500'000'000);
    s.set_slave_alive(slave.last && now - slave.last_received_ns < 500'000'000);
    master.summary->fill(*s.mutable_master(), now,
                         read_monitors(*master.oscillation, *master.passivity));
    slave.summary->fill(*s.mutable_slave(), now,
                        read_monitors(*slave.oscillation, *slave.passivity));
    s.set_client_may_command(may_command);
    fill_configuration_status(s);
  }

  // README "Before engage": the fingerprints, each node's own check, the experiment banner.
  void fill_configuration_status(v1::SupervisorStatus& s) const {
    s.set_config_fingerprint(master_setup.settings.config_fingerprint);
    s.set_configuration_mismatch(configuration_mismatch);
    s.set_experiment_banner(experiment_banner(loaded.config.experiment().allow_unstable(),
                                              master.last ? &*master.last : nullptr,
                                              slave.last ? &*slave.last : nullptr));
    for (const auto& [view, summary] :
         {std::pair{&master, s.mutable_master()}, std::pair{&slave, s.mutable_slave()}}) {
      if (!view->last) continue;
      summary->set_config_fingerprint(view->last->config_fingerprint());
      summary->set_peer_config_fingerprint(view->last->peer_config_fingerprint());
      *summary->mutable_configuration_check() = view->last->configuration_check();
    }
  }

  // A state command from a console, forwarded to the node(s) it names; both nodes' replies
  // come back and the outcome is announced (an INFO alarm of kind "command") and recorded.
  v1::NodeCommandResult forward_node_command(const v1::NodeCommandRequest& r) {
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
    v1::NodeCommand c;
    c.set_kind(k);
    std::string summary;
    // An e-stop always goes to both, whatever the first answers.
    for (const auto& [name, setup] :
         {std::pair<std::string, const config::NodeSetup*>{"master", &master_setup},
          std::pair<std::string, const config::NodeSetup*>{"slave", &slave_setup}}) {
      if (k != v1::NodeCommand::ESTOP && target != "both" && target != name) continue;
      v1::NodeCommandOutcome* o = result.add_outcomes();
      o->set_node(name);
      const auto reply = command(*setup, c);
      o->set_replied(reply.has_value());
      if (reply) *o->mutable_reply() = *reply;
      summary +=
          fmt::format("{}{} {}", summary.empty() ? "" : ", ", name,
                      reply ? fmt::format("{}{}", v1::NodeMode_Name(reply->mode()),
                                          reply->ok() ? "" : " (refused: " + reply->message() + ")")
                            : std::string("NO REPLY"));
    }
    if (k != v1::NodeCommand::STATUS) {
      alarm(k == v1::NodeCommand::ESTOP ? v1::Alarm::WARNING : v1::Alarm::INFO, "command", target,
            fmt::format("{} by {}: {}", v1::NodeCommand::Kind_Name(k),
                        r.requested_by().empty() ? std::string("operator") : r.requested_by(),
                        summary),
            {});
    }
    return result;
  }

  void set_recording(bool on, v1::SupervisorReply& reply) {
    if (!on) {
      if (!opts.sink) {
        reply.set_error("not recording");
        return;
      }
      const std::string file = opts.sink->file();
      opts.sink.reset();  // closes the file: summary and footer written
      alarm(v1::Alarm::INFO, "command", "system", "recording stopped: " + file, {});
      return;
    }
    if (opts.sink) {
      reply.set_error("already recording to " + opts.sink->file());
      return;
    }
    if (!opts.new_sink) {
      reply.set_error("this supervisor cannot start a recording (no record directory)");
      return;
    }
    opts.sink = opts.new_sink();
    recorder_failure_announced = false;
    record(record::topic::kConfig, loaded.config);
    record(record::topic::kStability, report);
    alarm(v1::Alarm::INFO, "command", "system", "recording started: " + opts.sink->file(), {});
  }

  // Whether `request` may come from a client with this key (Z85; empty: no CURVE).
  std::string read_only_refusal(const v1::SupervisorRequest& req, const std::string& key) const {
    if (key.empty() ||
        std::find(read_only_keys.begin(), read_only_keys.end(), key) == read_only_keys.end()) {
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

  // --- isolation and own faults (issue 14, findings 8 and 9) ---------------------------------
  // Recording was asked for and could not start: said once, loudly, at start.
  void announce_record_failure() {
    if (opts.sink || opts.record_failure.empty()) return;
    alarm(v1::Alarm::CRITICAL, "recorder", "system",
          "not recording: " + opts.record_failure + " (supervising without recording)", {});
  }

  // The session file vanished under a running recorder (its directory removed): the writes
  // go to an unlinked file and the session is lost. Said once, loudly.
  void check_recording_file() {
    if (!opts.sink || recording_file_lost_announced) return;
    const std::string file = opts.sink->file();
    std::error_code ec;
    if (file.empty() || std::filesystem::exists(file, ec) || ec) return;
    recording_file_lost_announced = true;
    alarm(v1::Alarm::CRITICAL, "recorder", "system",
          "recording file " + file +
              " no longer exists (record directory removed?): this session is not being kept",
          {{"recorded_messages", static_cast<double>(opts.sink->recorded()), ""}});
  }

  // The supervisor's own loop stood still (SIGSTOP, a debugger, swapped out): the nodes'
  // telemetry of that time is still queued, so silence is not judged from before the stall.
  // Each node gets the full heartbeat window from now; a node that really stopped is
  // still found 0.5 s later. The stall itself is reported.
  void excuse_own_stall() {
    const std::int64_t now = monotonic_ns();
    const std::int64_t gap = last_iteration_ns == 0 ? 0 : now - last_iteration_ns;
    last_iteration_ns = now;
    if (gap < kOwnStallNs) return;
    for (NodeView* n : {&master, &slave}) {
      if (n->last) n->last_received_ns = std::max(n->last_received_ns, now);
    }
    alarm(v1::Alarm::INFO, "supervisor", "system",
          fmt::format("the supervisor's own loop stalled for {:.3f} s; node heartbeats judged "
                      "from now",
                      static_cast<double>(gap) * 1e-9),
          {{"stall", static_cast<double>(gap) * 1e-9, "s"}});
  }

  // Binds, connects and announces; then loop() until `stop`. Nothing a client or a node sends
  // ends the supervisor: an iteration that throws is logged and the loop goes on (issue 14
  // finding 4); a failure to start is the caller's.
  void run(const std::atomic<bool>& stop) {
    start();
    while (!stop.load()) {
      try {
        loop(stop);
      } catch (const std::exception& e) {
        spdlog::error("main loop: {} (carrying on)", e.what());
      }
    }
    spdlog::info("stopping");
  }

  void start() {
    zap.emplace(ctx);
    report_pub.emplace(
        transport::make_telemetry_publisher(ctx, report_endpoint, server_security()));
    request_rep.emplace(transport::make_command_server(ctx, request_endpoint, server_security()));
    // Each client within its budget (issue 14 finding 5).
    monitor.emplace(ctx, std::vector<zmq::socket_t*>{&*report_pub, &*request_rep}, "supervisor",
                    std::vector<transport::InboundBudget>{transport::kSubscriberBudget,
                                                          transport::kCommandClientBudget});
    master_sub.emplace(
        subscribe(master_setup.endpoints.telemetry, loaded.config.security().master_public_key()));
    slave_sub.emplace(
        subscribe(slave_setup.endpoints.telemetry, loaded.config.security().slave_public_key()));
    record(record::topic::kConfig, loaded.config);
    publish_report("start");
    announce_record_failure();
    spdlog::info("supervising master {} and slave {}; reports on {}, requests on {}",
                 master_setup.endpoints.telemetry, slave_setup.endpoints.telemetry, report_endpoint,
                 request_endpoint);
    next_check = monotonic_ns();
  }

  void loop(const std::atomic<bool>& stop) {
    while (!stop.load()) {
      iterations.fetch_add(1, std::memory_order_relaxed);
      excuse_own_stall();
      zmq::pollitem_t items[] = {{master_sub->handle(), 0, ZMQ_POLLIN, 0},
                                 {slave_sub->handle(), 0, ZMQ_POLLIN, 0},
                                 {request_rep->handle(), 0, ZMQ_POLLIN, 0}};
      try {
        (void)zmq::poll(items, 3, 20ms);
      } catch (const zmq::error_t&) {
        continue;
      }
      zmq::message_t msg;
      for (int i = 0; i < 2; ++i) {
        zmq::socket_t& sock = i == 0 ? *master_sub : *slave_sub;
        for (transport::Received got; (got = transport::receive_whole(sock, msg)).parts > 0;) {
          v1::Telemetry t;
          if (got.parts != 1 || !t.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
            continue;
          }
          on_telemetry(i == 0 ? master : slave, t, i == 0);
        }
      }
      // The whole request, every part of it, so the socket can always answer (issue 14
      // finding 4: a 2-part request made the reply throw EFSM, which ended the supervisor).
      if (const transport::Received got = transport::receive_whole(*request_rep, msg);
          got.parts > 0) {
        v1::SupervisorRequest req;
        v1::SupervisorReply reply;
        std::string key;
        try {
          const char* uid = msg.gets("User-Id");
          if (uid != nullptr) key = uid;
        } catch (const zmq::error_t&) {
          // No ZAP user id (plaintext on loopback): a local client, not read-only.
        }
        if (got.parts != 1) {
          reply.set_error("malformed request: " + std::to_string(got.parts) +
                          " parts (a request is one frame)");
        } else if (!req.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
          reply.set_error("malformed request");
        } else if (const std::string why = read_only_refusal(req, key); !why.empty()) {
          reply.set_error(why);
          reply.set_refused_read_only(true);
          spdlog::warn("{}", why);
        } else {
          try {
            on_request(req, reply);
            if (reply.has_status()) {
              reply.mutable_status()->set_client_may_command(
                  key.empty() || std::find(read_only_keys.begin(), read_only_keys.end(), key) ==
                                     read_only_keys.end());
            }
          } catch (const std::exception& e) {
            reply.set_error(e.what());
          }
        }
        const std::string out = reply.SerializeAsString();
        std::string why;
        if (!transport::send_noexcept(*request_rep, out, zmq::send_flags::dontwait, &why)) {
          spdlog::warn("request endpoint: reply not sent: {}", why);
        }
      }
      if (monotonic_ns() >= next_check) {
        next_check += 100'000'000;
        excuse_own_stall();  // a stall inside this iteration (e.g. in the poll) counts too
        check_live();
        // A recorder that stopped on an error (disk full) is said once, loudly; the nodes are
        // not affected and the file keeps every chunk written before it.
        check_recording_file();
        if (opts.sink && !recorder_failure_announced) {
          const std::string why = opts.sink->error();
          if (!why.empty()) {
            recorder_failure_announced = true;
            alarm(v1::Alarm::CRITICAL, "recorder", "system", "recording stopped: " + why,
                  {{"recorded_messages", static_cast<double>(opts.sink->recorded()), ""},
                   {"dropped", static_cast<double>(opts.sink->drops()), ""}});
          }
        }
        // The summary stream consoles draw from: ten times a second.
        v1::SupervisorStatus st;
        fill_status(st, false);
        const std::string bytes = st.SerializeAsString();
        publish("status", bytes);
        // Once a second the supervisor's own status goes into the session: the recorder's
        // drops and counts, the nodes' liveness, the report in force.
        if (++checks % 10 == 0 && opts.sink) {
          v1::SupervisorReply status;
          on_request(v1::SupervisorRequest{}, status);
          record(record::topic::kStatus, status.status());
        }
      }
    }
  }

  config::LoadedConfig loaded;
  TeleopParams params;
  StabilityGuard guard;
  ParameterAudit audit;
  SupervisorOptions opts;
  config::NodeSetup master_setup;
  config::NodeSetup slave_setup;
  std::string report_endpoint;
  std::string request_endpoint;
  double oscillation_threshold_m{0.0};
  double passivity_threshold_J{0.0};
  double passivity_power_threshold_W{0.0};
  std::int64_t escalation_ns{0};
  double change_ramp_ms{200.0};
  double period_s{0.001};
  std::optional<transport::CurveKeyPair> own_key{};
  zmq::context_t ctx{1};
  std::optional<transport::ZapHandler> zap{};
  std::optional<zmq::socket_t> report_pub{};
  std::optional<zmq::socket_t> request_rep{};
  std::optional<zmq::socket_t> master_sub{};
  std::optional<zmq::socket_t> slave_sub{};
  std::int64_t next_check{0};
  // After the sockets: stopped (destroyed) before they close.
  std::optional<transport::SocketMonitor> monitor{};
  NodeView master{};
  NodeView slave{};
  LiveInputs live{};
  std::int64_t measured_round_trip_ns{0};
  // The round-trip guard's lowering was refused (retried at every check).
  // Up at once, down after 5 s of the shorter round trip.
  RoundTripModel round_trip_model{kRoundTripHoldNs};
  bool lowering_pending{false};
  std::int64_t last_lowering_try_ns{0};
  std::uint64_t change_id{0};
  std::uint64_t last_sent_change_id{0};  // the newest change number sent, taken or not
  v1::StabilityReport report{};
  std::deque<v1::Alarm> recent_alarms{};
  std::map<std::string, std::int64_t> last_alarm_ns{};
  std::uint64_t checks{0};
  std::vector<std::string> read_only_keys{};
  bool heard_master{false};
  std::string configuration_mismatch{};  // "" while the supervisor and both nodes agree
  bool recorder_failure_announced{false};
  bool recording_file_lost_announced{false};
  std::int64_t last_iteration_ns{0};
  int escalation_stage{0};
  std::int64_t escalated_ns{0};  // stage 1: when the lowered stiffness is fully in force
  bool settled{true};
  std::atomic<std::uint64_t> iterations{0};  // the watchdog's heartbeat
};

SupervisorApp::SupervisorApp(const config::LoadedConfig& config, SupervisorOptions options)
    : impl_(std::make_unique<Impl>(config, std::move(options))) {}

SupervisorApp::~SupervisorApp() = default;

void SupervisorApp::run(const std::atomic<bool>& stop) { impl_->run(stop); }

std::uint64_t SupervisorApp::loop_iterations() const noexcept {
  return impl_->iterations.load(std::memory_order_relaxed);
}

}  // namespace teleop::supervisor
