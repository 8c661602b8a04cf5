// SupervisorCore's periodic checks (supervisor_core.hpp): its own stalls, the configurations,
// heartbeats, overruns and loss, the measured model and the round-trip lowering, oscillation
// and passivity through the escalation ladder, and the recorder.
#include <fmt/core.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "supervisor/core/configuration_check.hpp"
#include "supervisor/core/supervisor_core.hpp"

namespace teleop::supervisor {

void SupervisorCore::tick(std::int64_t now_ns) {
  now_ns_ = now_ns;
  if (opts_.replay) return;  // a replay's checks were the live supervisor's, recorded
  excuse_own_stall();
  if (axes_) finish_axes_change();  // an n-axis change analysed beside the loop
  if (now_ns < next_check_ns_) return;
  next_check_ns_ += kCheckPeriodNs;
  check_live();
  check_recorder();
  // The summary stream consoles draw from: ten times a second.
  v1::SupervisorStatus st;
  fill_status(st, false);
  ports_.status(st);
  publish_config();  // sent again once a second, for live viewers that joined later
  // Once a second the supervisor's own status goes into the session: the recorder's drops and
  // counts, the nodes' liveness, the report in force.
  if (++checks_ % 10 == 0 && opts_.sink) {
    v1::SupervisorReply status;
    handle_request(v1::SupervisorRequest{}, status);
    record(record::topic::kStatus, status.status());
  }
}

// The supervisor's own loop stood still (SIGSTOP, a debugger, swapped out): the nodes'
// telemetry of that time is still queued, so silence is not judged from before the stall.
// Each node gets the full heartbeat window from now; a node that really stopped is still found
// 0.5 s later. The stall itself is reported.
void SupervisorCore::excuse_own_stall() {
  const std::int64_t gap = last_iteration_ns_ == 0 ? 0 : now_ns_ - last_iteration_ns_;
  last_iteration_ns_ = now_ns_;
  if (gap < kOwnStallNs) return;
  for (NodeView* n : {&master_, &slave_}) {
    if (n->last) n->last_received_ns = std::max(n->last_received_ns, now_ns_);
  }
  alarm(v1::Alarm::INFO, "supervisor", "system",
        fmt::format("the supervisor's own loop stalled for {:.3f} s; node heartbeats judged "
                    "from now",
                    static_cast<double>(gap) * 1e-9),
        {{"stall", static_cast<double>(gap) * 1e-9, "s"}});
}

void SupervisorCore::check_live() {
  check_configurations();
  check_heartbeats(master_);
  check_heartbeats(slave_);
  update_model();
  retry_lowering();
  check_findings();
}

// docs/nodes.md "Before engage": both nodes' fingerprints against the supervisor's own; a
// difference (new or changed) is an alarm naming the fingerprints and, where telemetry shows them,
// the fields.
void SupervisorCore::check_configurations() {
  if (axes_) {
    const std::string m = axes_configuration_mismatch();
    if (!m.empty() && m != configuration_mismatch_) {
      alarm(v1::Alarm::WARNING, "configuration", "system", m + " (arm and engage refused)", {});
    }
    configuration_mismatch_ = m;
    return;
  }
  ApprovedConfiguration approved;
  approved.change_id = change_id_;
  approved.gains = live_.gains;
  approved.master_fixture_N_per_m = live_.master_fixture_N_per_m;
  approved.slave_fixture_N_per_m = live_.slave_fixture_N_per_m;
  const ConfigurationMismatch m = compare_configurations(
      system_.node(transport::Role::kMaster).settings.config_fingerprint, approved,
      master_.last ? &*master_.last : nullptr, slave_.last ? &*slave_.last : nullptr);
  if (!m.message.empty() && m.message != configuration_mismatch_) {
    alarm(v1::Alarm::WARNING, "configuration", m.side, m.message + " (arm and engage refused)", {});
  }
  configuration_mismatch_ = m.message;
}

// Silence, and overruns and loss over the last second.
void SupervisorCore::check_heartbeats(NodeView& n) {
  if (n.last && now_ns_ - n.last_received_ns > kHeartbeatNs) {
    alarm(v1::Alarm::WARNING, "heartbeat", n.name, "no telemetry for over 0.5 s",
          {{"silent", static_cast<double>(now_ns_ - n.last_received_ns) * 1e-9, "s"}});
  }
  if (!n.last || now_ns_ - n.overrun_check_ns < 1'000'000'000) return;
  const std::uint64_t overruns = n.last->loop().overruns();
  const std::uint64_t lost = n.last->link().lost();
  const std::uint64_t accepted = n.last->link().accepted();
  if (n.overrun_check_ns != 0) {
    const std::uint64_t d_over = overruns - std::min(overruns, n.overruns_at_check);
    if (d_over > 10) {
      alarm(v1::Alarm::WARNING, "overruns", n.name, "loop overran in the last second",
            {{"overruns", static_cast<double>(d_over), ""},
             {"wakeup_p99", static_cast<double>(n.last->loop().wakeup_p99_ns()) * 1e-3, "us"}});
    }
    const double d_lost = static_cast<double>(lost - std::min(lost, n.lost_at_check));
    const double d_acc = static_cast<double>(accepted - std::min(accepted, n.accepted_at_check));
    if (d_lost + d_acc > 0 && d_lost / (d_lost + d_acc) > 0.01) {
      alarm(v1::Alarm::WARNING, "loss", n.name, "more than 1 % of peer states lost",
            {{"loss", d_lost / (d_lost + d_acc), ""}});
    }
  }
  n.overruns_at_check = overruns;
  n.lost_at_check = lost;
  n.accepted_at_check = accepted;
  n.overrun_check_ns = now_ns_;
}

// The measured rate and round trip into the model; a longer round trip that makes the model
// miss its requirement lowers the fixtures.
void SupervisorCore::update_model() {
  LiveInputs next = live_;
  if (master_.cycle_times.size() > 500) {
    // The median cycle interval: skipped (overrun) cycles do not read as a slower loop.
    std::vector<std::int64_t> d;
    d.reserve(master_.cycle_times.size());
    for (std::size_t i = 1; i < master_.cycle_times.size(); ++i) {
      d.push_back(master_.cycle_times[i] - master_.cycle_times[i - 1]);
    }
    std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
    const double rate = 1e9 / static_cast<double>(d[d.size() / 2]);
    // The loops run on a grid: a rate within 0.5 % of the file's is the file's.
    if (std::abs(rate - params_.sample_rate_hz) > 0.005 * params_.sample_rate_hz) {
      next.sample_rate_hz = rate;
    }
  }
  std::int64_t rtt = 0;
  for (const NodeView* n : {&master_, &slave_}) {
    if (n->last) rtt = std::max(rtt, n->last->link().round_trip_p99_ns());
  }
  // The model's round trip: the largest measured over the last 5 s (down only after that).
  if (rtt > 0) rtt = round_trip_model_.add(now_ns_, rtt);
  measured_round_trip_ns_ = rtt;
  if (rtt > 0) {
    const double period_ns = 1e9 / next.sample_rate_hz;
    const int samples =
        std::max(1, static_cast<int>(std::ceil(static_cast<double>(rtt) / period_ns - 1e-9)));
    next.round_trip_samples = std::max(samples, params_.round_trip_delay_samples);
  }
  if (next == live_) return;
  const bool rtt_grew = next.round_trip_samples > live_.round_trip_samples;
  live_ = next;
  alarm(v1::Alarm::INFO, "round_trip", "system",
        fmt::format("model updated: round trip {} samples at {:.1f} Hz", live_.round_trip_samples,
                    live_.sample_rate_hz),
        {{"round_trip_p99", static_cast<double>(rtt) * 1e-6, "ms"}});
  publish_report(rtt_grew ? "round trip grew" : "measured inputs changed");
  if (axes_) {
    // A lowering of the planes is a guarded n-axis change, analysed beside the loop (seconds
    // with a band) while this model is unstable now: both nodes are disengaged at once.
    if (axes_->assessment.acceptable()) return;
    const auto coupled = [](const NodeView& v) {
      return v.mode == v1::ALIGNING || v.mode == v1::ENGAGED || v.mode == v1::CLUTCHED;
    };
    const auto rm =
        coupled(master_) ? command(Side::kMaster, v1::NodeCommand::DISENGAGE) : std::nullopt;
    const auto rs =
        coupled(slave_) ? command(Side::kSlave, v1::NodeCommand::DISENGAGE) : std::nullopt;
    alarm(v1::Alarm::CRITICAL, "round_trip", "system",
          fmt::format("the {}-axis model with a {}-sample round trip at {:.1f} Hz no longer meets "
                      "the requirement; lowering the planes would wait for the guard's "
                      "analysis, so both nodes are disengaged now",
                      axes_->params.axes, live_.round_trip_samples, live_.sample_rate_hz),
          {{"round_trip_p99", static_cast<double>(measured_round_trip_ns_) * 1e-6, "ms"},
           {"min_damping_ratio", axes_->assessment.min_damping_ratio, ""}},
          fmt::format("disengaged both nodes (master {}, slave {})",
                      rm ? v1::NodeMode_Name(rm->mode()) : v1::NodeMode_Name(master_.mode),
                      rs ? v1::NodeMode_Name(rs->mode()) : v1::NodeMode_Name(slave_.mode)));
    return;
  }
  // Stability is not monotonic in the round trip (nor in the rate): a shorter one can make the
  // model miss its requirement as well as a longer one. Whatever changed, a model that misses
  // it lowers the fixtures.
  if (guard_.assess(live_).acceptable()) return;
  // Announced like every change the supervisor makes: an ACTION alarm naming it. A refused
  // lowering is tried again kLoweringRetryNs after this attempt.
  last_lowering_try_ns_ = now_ns_;
  lowering_why_ = "the measured round trip or rate changed";
  const Lowering l = lower_fixtures(rtt_grew ? "the measured round trip grew" : lowering_why_);
  announce_lowering(l, "");
  lowering_pending_ = !l.applied;
}

// The ACTION alarm of a lowering because the measured model misses its requirement.
void SupervisorCore::announce_lowering(const Lowering& l, const char* suffix) {
  alarm(v1::Alarm::ACTION, "round_trip", "system",
        fmt::format("the model with a {}-sample round trip at {:.1f} Hz no longer meets the "
                    "requirement{}",
                    live_.round_trip_samples, live_.sample_rate_hz, suffix),
        {{"round_trip_p99", static_cast<double>(measured_round_trip_ns_) * 1e-6, "ms"},
         {"min_damping_ratio", guard_.assess(live_).min_damping_ratio, ""}},
        l.action);
}

// A lowering the guard could not apply (a node's telemetry not in yet, say) is tried again
// every kLoweringRetryNs while the model still misses the requirement, until it is applied.
void SupervisorCore::retry_lowering() {
  if (!lowering_pending_ || now_ns_ - last_lowering_try_ns_ < kLoweringRetryNs) return;
  last_lowering_try_ns_ = now_ns_;
  if (guard_.assess(live_).acceptable()) {
    lowering_pending_ = false;
    return;
  }
  const Lowering l = lower_fixtures(lowering_why_ + " (retried)");
  if (!l.applied) return;
  lowering_pending_ = false;
  announce_lowering(l, " (retried)");
}

// A sustained oscillation, or else an active port, on one node.
SupervisorCore::Finding SupervisorCore::finding(NodeView& n) const {
  Finding f;
  if (n.oscillation->full()) {
    const scene::Oscillation o = n.oscillation->check();
    if (o.detected) {
      f.what = "sustained oscillation";
      f.kind = "oscillation";
      f.evidence = {{"amplitude", o.amplitude_m * 1e3, "mm"},
                    {"frequency", o.frequency_hz, "Hz"},
                    {"previous_amplitude", o.previous_amplitude_m * 1e3, "mm"}};
      return f;
    }
  }
  if (n.passivity->energy_J() < -passivity_threshold_J_ &&
      n.passivity->recent_power_W() < -passivity_power_threshold_W_) {
    f.what = "active port (passivity observer)";
    f.kind = "passivity";
    f.evidence = {{"energy", n.passivity->energy_J(), "J"},
                  {"min_energy", n.passivity->min_energy_J(), "J"},
                  {"power_last_second", n.passivity->recent_power_W(), "W"}};
  }
  return f;
}

// Oscillation and passivity through the ladder (escalation.hpp).
void SupervisorCore::check_findings() {
  if (ladder_.settle(now_ns_)) {
    // The lowered stiffness is in force: only evidence from now on counts.
    for (NodeView* n : {&master_, &slave_}) {
      n->oscillation->clear();
      n->passivity->reset();
      if (n->oscillation_axes) n->oscillation_axes->clear();
      if (n->passivity_axes) n->passivity_axes->reset();
      n->finding_since_ns = 0;
    }
  }
  bool any = false;
  for (NodeView* n : {&master_, &slave_}) {
    const Finding f = axes_ ? axes_finding(*n) : finding(*n);
    if (f.what.empty()) {
      n->finding_since_ns = 0;
      continue;
    }
    any = true;
    if (n->finding_since_ns == 0) {
      n->finding_since_ns = now_ns_;
      // Both nodes hand over their last seconds at full rate (recorded with their telemetry).
      (void)command(Side::kMaster, v1::NodeCommand::FLIGHT_RECORD);
      (void)command(Side::kSlave, v1::NodeCommand::FLIGHT_RECORD);
    }
    switch (ladder_.on_finding(now_ns_, now_ns_ - n->finding_since_ns)) {
      case EscalationAction::kWarn:
        alarm(v1::Alarm::WARNING, f.kind, n->name, f.what, f.evidence);
        break;
      case EscalationAction::kLowerFixtures: {
        const std::string why = f.what + " on the " + n->name;
        alarm(v1::Alarm::ACTION, f.kind, n->name, f.what, f.evidence,
              (axes_ ? lower_planes(why) : lower_fixtures(why)).action);
        break;
      }
      case EscalationAction::kDisengage:
        if (axes_) {
          disengage_both(*n, f, "persisted after lowering the planes");
          break;
        }
        disengage_both(*n, f);
        break;
      case EscalationAction::kNone:
        break;
    }
  }
  ladder_.end_check(now_ns_, any);
}

void SupervisorCore::disengage_both(const NodeView& n, const Finding& f, const std::string& why) {
  const auto coupled = [](const NodeView& v) {
    return v.mode == v1::ALIGNING || v.mode == v1::ENGAGED || v.mode == v1::CLUTCHED;
  };
  // A node that already left coupling (the peer's disengage reached it) stays armed.
  const auto rm =
      coupled(master_) ? command(Side::kMaster, v1::NodeCommand::DISENGAGE) : std::nullopt;
  const auto rs =
      coupled(slave_) ? command(Side::kSlave, v1::NodeCommand::DISENGAGE) : std::nullopt;
  alarm(v1::Alarm::CRITICAL, f.kind, n.name, f.what + " " + why, f.evidence,
        fmt::format("disengaged both nodes (master {}, slave {})",
                    rm ? v1::NodeMode_Name(rm->mode()) : v1::NodeMode_Name(master_.mode),
                    rs ? v1::NodeMode_Name(rs->mode()) : v1::NodeMode_Name(slave_.mode)));
}

// Lowers the fixtures in use to half their stiffness (never above half the predicted maximum)
// through the guard.
SupervisorCore::Lowering SupervisorCore::lower_fixtures(const std::string& why) {
  ChangeRequest change;
  if (live_.master_fixture_N_per_m > 0.0) {
    change.master_fixture_N_per_m = guard_.lowered_stiffness(live_, false, 0.5);
  }
  if (live_.slave_fixture_N_per_m > 0.0) {
    change.slave_fixture_N_per_m = guard_.lowered_stiffness(live_, true, 0.5);
  }
  if (!change.master_fixture_N_per_m && !change.slave_fixture_N_per_m) {
    return {false, "no fixture to lower"};
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
  rec.set_time_ns(now_ns_);
  change_decided(rec);
  if (!r.accepted()) return {false, "could not lower the fixtures: " + r.reason()};
  return {true,
          fmt::format("lowered fixtures (change {}): master {:.0f} N/m, slave {:.0f} N/m",
                      r.change_id(), live_.master_fixture_N_per_m, live_.slave_fixture_N_per_m)};
}

// A recorder that stopped on an error (disk full), or whose file vanished under it (its
// directory removed: the writes go to an unlinked file), is said once, loudly; the nodes are
// not affected and the file keeps every chunk written before it.
void SupervisorCore::check_recorder() {
  if (!opts_.sink) return;
  const std::string file = opts_.sink->file();
  std::error_code ec;
  if (!recording_file_lost_announced_ && !file.empty() && !std::filesystem::exists(file, ec) &&
      !ec) {
    recording_file_lost_announced_ = true;
    alarm(v1::Alarm::CRITICAL, "recorder", "system",
          "recording file " + file +
              " no longer exists (record directory removed?): this session is not being kept",
          {{"recorded_messages", static_cast<double>(opts_.sink->recorded()), ""}});
  }
  if (recorder_failure_announced_) return;
  const std::string why = opts_.sink->error();
  if (why.empty()) return;
  recorder_failure_announced_ = true;
  alarm(v1::Alarm::CRITICAL, "recorder", "system", "recording stopped: " + why,
        {{"recorded_messages", static_cast<double>(opts_.sink->recorded()), ""},
         {"dropped", static_cast<double>(opts_.sink->drops()), ""}});
}

}  // namespace teleop::supervisor
