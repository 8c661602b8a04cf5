#include "supervisor/teleopctl/replay_supervision.hpp"

#include <fmt/format.h>
#include <google/protobuf/message.h>

#include <exception>
#include <numbers>
#include <ostream>
#include <string>

#include "common/config/node_loader.hpp"
#include "common/core/defaults.hpp"
#include "common/sim/sensors.hpp"
#include "supervisor/core/stability_guard.hpp"

namespace teleop::ctl {
namespace {

namespace pb = google::protobuf;
using nlohmann::json;

[[nodiscard]] double encoder_count_m(const sim::EncoderParams& e) {
  return 2.0 * std::numbers::pi * e.metres_per_radian / (e.counts_per_rev * e.transmission_ratio);
}

}  // namespace

SummarySetup summary_setup(const std::optional<config::LoadedConfig>& cfg, std::ostream& err) {
  SummarySetup s;
  s.oscillation_threshold_m =
      defaults::kOscillationThreshold_counts * encoder_count_m(sim::EncoderParams{});
  if (!cfg) return s;
  const v1::Supervisor& sup = cfg->config.supervisor();
  try {
    const TeleopParams params = config::to_teleop_params(*cfg);
    s.period_s = 1.0 / params.sample_rate_hz;
    s.master_fixture = params.master_fixture;
    s.slave_fixture = params.slave_fixture;
    // The master's encoder count, as the supervisor takes it.
    s.oscillation_threshold_m =
        defaults::kOscillationThreshold_counts *
        encoder_count_m(config::to_node_setup(*cfg, transport::Role::kMaster).sim.encoder);
  } catch (const std::exception& e) {
    err << fmt::format(
        "teleopctl replay: the recorded /config does not describe the teleoperator ({}); the "
        "summary stream's monitors use defaults\n",
        e.what());
  }
  if (sup.has_oscillation_threshold_m()) s.oscillation_threshold_m = sup.oscillation_threshold_m();
  return s;
}

void ReplaySummary::advance_to(std::uint64_t log_time_ns) {
  if (log_time_ns < applied_until_ns_) reset();
  applied_until_ns_ = log_time_ns;
  while (next_ < items_.size() && items_[next_].log_time_ns <= log_time_ns) {
    apply(items_[next_]);
    ++next_;
  }
}

void ReplaySummary::fill(v1::SupervisorStatus& s) const {
  const auto now = static_cast<std::int64_t>(applied_until_ns_);
  s.set_time_ns(now);
  s.set_source("replay");
  if (report_) *s.mutable_report() = *report_;
  for (const v1::Alarm& a : alarms_) *s.add_recent_alarms() = a;
  if (recorded_) {
    s.set_recording_file(recorded_->recording_file());
    s.set_recorded_messages(recorded_->recorded_messages());
    s.set_recording_drops(recorded_->recording_drops());
    s.set_recording_bytes(recorded_->recording_bytes());
  }
  master_.fill(*s.mutable_master(), now);
  slave_.fill(*s.mutable_slave(), now);
  s.set_master_alive(s.master().alive());
  s.set_slave_alive(s.slave().alive());
  s.set_client_may_command(false);  // a replay cannot be commanded
}

void ReplaySummary::Side::reset() {
  builder.reset();
  oscillation.clear();
  passivity.reset();
  session_id = 0;
}

void ReplaySummary::Side::add(const v1::Telemetry& t, std::uint64_t log_time_ns) {
  // A restarted node (a new session) starts its summary again, as in the supervisor.
  if (session_id != 0 && t.session_id() != session_id) reset();
  session_id = t.session_id();
  for (const v1::CycleRecord& c : t.cycles()) {
    supervisor::feed_monitors(c, is_master_side, oscillation, passivity);
  }
  builder.add(t, static_cast<std::int64_t>(log_time_ns));
}

void ReplaySummary::Side::fill(v1::NodeSummary& out, std::int64_t now_ns) const {
  builder.fill(out, now_ns, supervisor::read_monitors(oscillation, passivity));
}

void ReplaySummary::reset() {
  master_.reset();
  slave_.reset();
  report_.reset();
  alarms_.clear();
  recorded_.reset();
  next_ = 0;
  applied_until_ns_ = 0;
}

void ReplaySummary::apply(const Item& it) {
  const auto parse = [&](pb::Message& m) {
    return m.ParseFromArray(it.data.data(), static_cast<int>(it.data.size()));
  };
  switch (it.kind) {
    case kMaster:
    case kSlave: {
      v1::Telemetry t;
      if (parse(t)) (it.kind == kMaster ? master_ : slave_).add(t, it.log_time_ns);
      break;
    }
    case kReport: {
      v1::StabilityReport r;
      if (parse(r)) report_ = std::move(r);
      break;
    }
    case kAlarm: {
      v1::Alarm a;
      if (parse(a)) {
        alarms_.push_front(std::move(a));
        while (alarms_.size() > kAlarmsShown) alarms_.pop_back();
      }
      break;
    }
    case kRecordedStatus: {
      v1::SupervisorStatus st;
      if (parse(st)) recorded_ = std::move(st);
      break;
    }
  }
}

std::vector<ReplaySummary::Item> summary_items(const record::SessionReader& session) {
  namespace topic = record::topic;
  std::vector<ReplaySummary::Item> items;
  session.mcap().for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    const std::string& t = m.channel->topic;
    const std::string schema = m.schema ? m.schema->name : std::string();
    auto is = [&](const pb::Descriptor* d) { return schema == d->full_name(); };
    std::optional<ReplaySummary::Kind> kind;
    if (t == topic::kMasterTelemetry && is(v1::Telemetry::descriptor())) {
      kind = ReplaySummary::kMaster;
    }
    if (t == topic::kSlaveTelemetry && is(v1::Telemetry::descriptor())) {
      kind = ReplaySummary::kSlave;
    }
    if (t == topic::kStability && is(v1::StabilityReport::descriptor())) {
      kind = ReplaySummary::kReport;
    }
    if (t == topic::kAlarms && is(v1::Alarm::descriptor())) kind = ReplaySummary::kAlarm;
    if (t == topic::kStatus && is(v1::SupervisorStatus::descriptor())) {
      kind = ReplaySummary::kRecordedStatus;
    }
    if (kind) items.push_back({*kind, m.log_time_ns, m.data});
  });
  return items;
}

json guard_analysis_json(const TeleopParams& params) {
  supervisor::StabilityGuard guard(params);
  const supervisor::Assessment a = guard.assess(guard.configured_inputs());
  return {{"verdict", std::string(stability::to_string(a.verdict))},
          {"min_damping_ratio", a.min_damping_ratio},
          {"round_trip_samples", a.inputs.round_trip_samples},
          {"slave_fixture_stiffness_N_per_m", a.inputs.slave_fixture_N_per_m},
          {"master_fixture_stiffness_N_per_m", a.inputs.master_fixture_N_per_m},
          {"max_stable_slave_stiffness_N_per_m",
           a.max_slave_N_per_m ? json(*a.max_slave_N_per_m) : json(nullptr)},
          {"max_stable_master_stiffness_N_per_m",
           a.max_master_N_per_m ? json(*a.max_master_N_per_m) : json(nullptr)},
          {"slave_margin", a.slave_margin() ? json(*a.slave_margin()) : json(nullptr)},
          {"master_margin", a.master_margin() ? json(*a.master_margin()) : json(nullptr)}};
}

}  // namespace teleop::ctl
