#include "supervisor/teleopctl/replay_supervision.hpp"

#include <fmt/format.h>
#include <google/protobuf/message.h>

#include <exception>
#include <ostream>
#include <string>

#include "common/telemetry/cycle_codec.hpp"
#include "supervisor/core/stability_guard.hpp"

namespace teleop::ctl {
namespace {

namespace pb = google::protobuf;
using nlohmann::json;

// The papers' paddles (Abbott-Okamura §4.1) at 1 kHz without fixtures: what a replay's summary
// stream stands on when the session holds no configuration that describes the teleoperator.
constexpr std::string_view kStandIn = R"(sample_rate_hz: 1000
master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }
slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } }
gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }
velocity_filter { cutoff_hz: 200 }
human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }
)";

[[nodiscard]] config::CompiledSystem replay_system(const std::optional<config::LoadedConfig>& cfg,
                                                   std::ostream& err) {
  if (cfg) {
    try {
      return config::compile_system(*cfg);
    } catch (const std::exception& e) {
      err << fmt::format(
          "teleopctl replay: the recorded /config does not describe the teleoperator ({}); the "
          "summary stream's monitors use defaults\n",
          e.what());
    }
  }
  return config::compile_system(config::parse_config_text(kStandIn, "(replay defaults)"));
}

}  // namespace

ReplaySummary::ReplaySummary(const std::optional<config::LoadedConfig>& config,
                             std::vector<Item> items, std::ostream& err)
    : system_(replay_system(config, err)), items_(std::move(items)) {
  reset();
}

void ReplaySummary::reset() {
  supervisor::SupervisorOptions o;
  o.replay = true;
  core_ = std::make_unique<supervisor::SupervisorCore>(system_, std::move(o), ports_);
  next_ = 0;
  applied_until_ns_ = 0;
}

v1::SupervisorStatus ReplaySummary::status() const {
  return core_->status();  // n > 1 axes: the per-axis figures of the newest cycles included
}

void ReplaySummary::advance_to(std::uint64_t log_time_ns) {
  if (log_time_ns < applied_until_ns_) reset();
  applied_until_ns_ = log_time_ns;
  while (next_ < items_.size() && items_[next_].log_time_ns <= log_time_ns) {
    apply(items_[next_]);
    ++next_;
  }
  core_->tick(static_cast<std::int64_t>(log_time_ns));
}

void ReplaySummary::apply(const Item& it) {
  const auto parse = [&](pb::Message& m) {
    return m.ParseFromArray(it.data.data(), static_cast<int>(it.data.size()));
  };
  const auto at = static_cast<std::int64_t>(it.log_time_ns);
  switch (it.kind) {
    case kMaster:
    case kSlave: {
      v1::Telemetry t;
      if (parse(t)) {
        core_->on_telemetry(
            it.kind == kMaster ? supervisor::Side::kMaster : supervisor::Side::kSlave, t, at);
      }
      break;
    }
    case kReport: {
      v1::StabilityReport r;
      if (parse(r)) core_->replay_report(r);
      break;
    }
    case kAlarm: {
      v1::Alarm a;
      if (parse(a)) core_->replay_alarm(a);
      break;
    }
    case kRecordedStatus: {
      v1::SupervisorStatus st;
      if (parse(st)) core_->replay_recording(st);
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
