#include "supervisor/core/session_output.hpp"

#include <fmt/core.h>
#include <google/protobuf/text_format.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>

#include "common/config/axes_config.hpp"
#include "common/config/control_fingerprint.hpp"
#include "common/config/node_loader.hpp"
#include "common/core/version.hpp"
#include "supervisor/core/axes_supervision.hpp"

namespace teleop::supervisor {
namespace {

std::string number(double v) { return fmt::format("{:.9g}", v); }

std::string utc_iso8601(std::int64_t utc_ns) {
  const time_t seconds = static_cast<time_t>(utc_ns / 1'000'000'000);
  tm utc{};
  gmtime_r(&seconds, &utc);
  char text[32];
  strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%S", &utc);
  return fmt::format("{}.{:03d}Z", text, static_cast<int>((utc_ns / 1'000'000) % 1000));
}

std::string host_name() {
  char name[256] = {};
  if (gethostname(name, sizeof(name) - 1) != 0) return "unknown";
  return name;
}

}  // namespace

void record_cycles(record::SessionSink& sink, bool master, const v1::Telemetry& t,
                   std::int64_t log_time_ns) {
  if (t.cycles_size() == 0) return;
  const std::string& type = v1::CycleRecord::descriptor()->full_name();
  const std::int64_t newest = t.cycles(t.cycles_size() - 1).sample_time_ns();
  v1::CycleRecord c;
  std::string bytes;
  for (const v1::CycleRecord& in : t.cycles()) {
    c = in;
    c.set_session_id(t.session_id());
    bytes.clear();
    c.SerializeToString(&bytes);
    // A cycle newer than the newest (not sent by a sane node) is logged at the batch's time.
    const std::int64_t back = std::max<std::int64_t>(0, newest - in.sample_time_ns());
    sink.record_published(record::topic::cycle(master), type, log_time_ns - back,
                          in.sample_time_ns(), bytes);
  }
}

foxglove::Log to_foxglove_log(const v1::Alarm& a, std::int64_t log_time_ns) {
  foxglove::Log log;
  log.mutable_timestamp()->set_seconds(log_time_ns / 1'000'000'000);
  log.mutable_timestamp()->set_nanos(static_cast<std::int32_t>(log_time_ns % 1'000'000'000));
  switch (a.severity()) {
    case v1::Alarm::INFO:
      log.set_level(foxglove::Log::INFO);
      break;
    case v1::Alarm::WARNING:
    case v1::Alarm::ACTION:
      log.set_level(foxglove::Log::WARNING);
      break;
    case v1::Alarm::CRITICAL:
      log.set_level(foxglove::Log::ERROR);
      break;
    default:
      log.set_level(foxglove::Log::UNKNOWN);
      break;
  }
  std::string text = a.kind() + ": " + a.message();
  for (const v1::Evidence& e : a.evidence()) {
    text += fmt::format(" {}={:.6g}{}", e.name(), e.value(), e.unit());
  }
  if (!a.action().empty()) text += " (action: " + a.action() + ")";
  log.set_message(text);
  log.set_name("teleop-supervisor/" + (a.side().empty() ? std::string("system") : a.side()));
  return log;
}

std::map<std::string, std::string> teleop_metadata(const config::LoadedConfig& config,
                                                   std::string_view recorder,
                                                   std::int64_t start_utc_ns) {
  std::map<std::string, std::string> m;
  m["version"] = std::string(version());
  m["host"] = host_name();
  m["config_file"] = config.source_name;
  // Several axes: the fingerprint both nodes compute; the axes say which form the session's
  // cycles take.
  if (several_axes(config)) {
    m["config_fingerprint"] = config::fingerprint_hex(config::axes_control_fingerprint(config));
    m["axes"] = std::to_string(config::configured_axes(config.config));
  } else {
    m["config_fingerprint"] = config::fingerprint_hex(config::control_fingerprint(config));
  }
  std::string overrides;
  std::string previous;
  for (const auto& [path, assignment] : config.overridden) {
    if (assignment == previous) continue;  // one --set that created several sections
    overrides += (overrides.empty() ? "" : "; ") + assignment;
    previous = assignment;
  }
  m["config_overrides"] = overrides;
  m["recorder"] = std::string(recorder);
  m["started_utc"] = utc_iso8601(start_utc_ns);
  m["log_time"] =
      "UTC ns since the epoch: the wall clock on receipt (teleop-supervisor), or the run's start "
      "plus simulated time (teleopctl simulate)";
  m["publish_time"] =
      "per-cycle channels: the node's sample time (its CLOCK_MONOTONIC; simulated time in a "
      "simulation); other channels: = log_time";
  return m;
}

std::map<std::string, std::string> analysis_metadata(const v1::StabilityReport& r) {
  std::map<std::string, std::string> m;
  m["verdict"] = r.verdict();
  m["min_damping_ratio"] = number(r.min_damping_ratio());
  m["required_damping_ratio"] = number(r.required_damping_ratio());
  m["round_trip_samples"] = std::to_string(r.round_trip_samples());
  m["sample_rate_hz"] = number(r.sample_rate_hz());
  m["master_fixture_stiffness_N_per_m"] = number(r.master_fixture_stiffness_n_per_m());
  m["slave_fixture_stiffness_N_per_m"] = number(r.slave_fixture_stiffness_n_per_m());
  m["max_stable_master_stiffness_N_per_m"] = r.has_max_stable_master_stiffness_n_per_m()
                                                 ? number(r.max_stable_master_stiffness_n_per_m())
                                                 : "none";
  m["max_stable_slave_stiffness_N_per_m"] = r.has_max_stable_slave_stiffness_n_per_m()
                                                ? number(r.max_stable_slave_stiffness_n_per_m())
                                                : "none";
  // Several axes: each plane in use against its limit (StabilityReport.planes).
  if (r.axes() > 1) {
    m["axes"] = std::to_string(r.axes());
    for (const v1::PlaneMargin& p : r.planes()) {
      m[p.side() + "_plane_" + std::to_string(p.index())] = p.description();
    }
  }
  return m;
}

std::map<std::string, std::string> rt_metadata(const v1::RtStatus& rt) {
  std::map<std::string, std::string> m;
  m["fifo_priority"] = std::to_string(rt.fifo_priority());
  m["memory_locked"] = rt.memory_locked() ? "true" : "false";
  m["cpu"] = std::to_string(rt.cpu());
  m["cpu_dma_latency_us"] = std::to_string(rt.cpu_dma_latency_us());
  std::string refused;
  for (const std::string& r : rt.refused()) refused += (refused.empty() ? "" : "; ") + r;
  m["refused"] = refused;
  return m;
}

void record_session_start(record::SessionSink& sink, const config::LoadedConfig& config,
                          const std::string& config_text, const v1::StabilityReport& start,
                          std::string_view recorder, std::int64_t log_time_ns) {
  sink.metadata(record::metadata::kTeleop, teleop_metadata(config, recorder, log_time_ns));
  sink.metadata(record::metadata::kAnalysis, analysis_metadata(start));
  std::string text = config_text;
  if (text.empty()) google::protobuf::TextFormat::PrintToString(config.config, &text);
  sink.attachment(record::kConfigAttachment, "text/plain", log_time_ns, text);
}

std::int64_t wall_clock_ns() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace teleop::supervisor
