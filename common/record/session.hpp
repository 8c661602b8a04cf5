// A recorded session: what the supervisor writes and `teleopctl replay` reads. One MCAP file
// (common/record) with one channel per topic, each carrying protobuf messages (teleop.v1) whose
// schema is embedded. The topics are named here and nowhere else.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>

namespace teleop::record {

namespace topic {
// Each topic's message type (teleop.v1 unless named), one channel per topic, protobuf encoded
// with the schema (a FileDescriptorSet) embedded. log_time: the recorder's wall clock, UTC ns
// since the epoch, when the supervisor received the message (a simulated session: the wall
// clock at the start of the run plus simulated time); publish_time: the sender's own time (a
// node's CLOCK_MONOTONIC sample time on the per-cycle channels, else = log_time). Sessions
// recorded before per-cycle channels and wall-clock log times have only the batched telemetry
// and monotonic log times; replay reads both.
inline constexpr std::string_view kConfig = "/config";                     // v1.SystemConfig
inline constexpr std::string_view kMasterTelemetry = "/master/telemetry";  // v1.Telemetry
inline constexpr std::string_view kSlaveTelemetry = "/slave/telemetry";    // v1.Telemetry
// One message per control cycle, taken from the batched telemetry (cycles only, no flight
// records); publish_time = the cycle's sample_time_ns, session_id set.
inline constexpr std::string_view kMasterCycle = "/master/cycle";        // v1.CycleRecord
inline constexpr std::string_view kSlaveCycle = "/slave/cycle";          // v1.CycleRecord
inline constexpr std::string_view kStability = "/supervisor/stability";  // v1.StabilityReport
inline constexpr std::string_view kAlarms = "/supervisor/alarms";        // v1.Alarm
// Every alarm again, for Foxglove's Log panel. Alarm severity -> foxglove.Log level: INFO ->
// INFO, WARNING -> WARNING, ACTION (the supervisor acted) -> WARNING, CRITICAL (it disengaged
// the nodes) -> ERROR, unspecified -> UNKNOWN; timestamp = the log time; name
// "teleop-supervisor/<side>"; message "<kind>: <message>" and " (action: <action>)" if any.
inline constexpr std::string_view kLog = "/supervisor/log";  // foxglove.Log
inline constexpr std::string_view kParameterChanges =
    "/supervisor/parameter_changes";                               // v1.ParameterChangeRecord
inline constexpr std::string_view kStatus = "/supervisor/status";  // v1.SupervisorStatus
inline constexpr std::string_view kSupervisorPrefix = "/supervisor/";
// A node's telemetry topic.
[[nodiscard]] constexpr std::string_view telemetry(bool master) noexcept {
  return master ? kMasterTelemetry : kSlaveTelemetry;
}
// A node's per-cycle topic.
[[nodiscard]] constexpr std::string_view cycle(bool master) noexcept {
  return master ? kMasterCycle : kSlaveCycle;
}
}  // namespace topic

// MCAP Metadata records of a session (name -> key/value strings), written at start; the rt
// records when the node's first telemetry arrives (its RtStatus: the settings in force).
namespace metadata {
// version ("0.1.0"), host, config_file, config_fingerprint (16 hex digits), recorder
// ("teleop-supervisor" or "teleopctl simulate"), started_utc (ISO 8601), clock ("wall").
inline constexpr std::string_view kTeleop = "teleop";
// The stability analysis at start: verdict, min_damping_ratio, required_damping_ratio,
// round_trip_samples, sample_rate_hz, fixture stiffnesses and their largest stable values.
inline constexpr std::string_view kAnalysis = "teleop.analysis";
// fifo_priority, memory_locked, cpu, cpu_dma_latency_us, refused ("; "-joined).
inline constexpr std::string_view kRtMaster = "teleop.rt.master";
inline constexpr std::string_view kRtSlave = "teleop.rt.slave";
}  // namespace metadata

// The configuration file as it was read, an MCAP Attachment (media type text/plain).
inline constexpr std::string_view kConfigAttachment = "config.textproto";

// Where a session's messages go (the MCAP session file; tests capture them).
class SessionSink {
 public:
  virtual ~SessionSink() = default;
  // `type` names the protobuf message type of `bytes` (its full name).
  virtual void record(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
                      const std::string& bytes) = 0;
  // The same with the sender's own time as the MCAP publish_time (record(): = log time).
  virtual void record_published(std::string_view topic, const std::string& type,
                                std::int64_t log_time_ns, std::int64_t publish_time_ns,
                                const std::string& bytes) {
    (void)publish_time_ns;
    record(topic, type, log_time_ns, bytes);
  }
  // An MCAP Metadata record (names in `metadata` above) and an Attachment (e.g.
  // kConfigAttachment); a sink that keeps no file ignores them.
  virtual void metadata(std::string_view name, const std::map<std::string, std::string>& values) {
    (void)name;
    (void)values;
  }
  virtual void attachment(std::string_view name, std::string_view media_type,
                          std::int64_t log_time_ns, const std::string& data) {
    (void)name;
    (void)media_type;
    (void)log_time_ns;
    (void)data;
  }
  [[nodiscard]] virtual std::string file() const { return {}; }
  [[nodiscard]] virtual std::uint64_t recorded() const { return 0; }
  [[nodiscard]] virtual std::uint64_t drops() const { return 0; }
  [[nodiscard]] virtual std::uint64_t bytes() const { return 0; }
  // "" while recording works; else why it stopped (disk full, I/O error), naming the file.
  [[nodiscard]] virtual std::string error() const { return {}; }
};

}  // namespace teleop::record
