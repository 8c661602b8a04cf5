// A recorded session: what the supervisor writes and `teleopctl replay` reads. One MCAP file
// (common/record) with one channel per topic, each carrying protobuf messages (teleop.v1) whose
// schema is embedded. The topics are named here and nowhere else.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

namespace teleop::record {

namespace topic {
inline constexpr std::string_view kConfig = "/config";                     // v1.SystemConfig
inline constexpr std::string_view kMasterTelemetry = "/master/telemetry";  // v1.Telemetry
inline constexpr std::string_view kSlaveTelemetry = "/slave/telemetry";    // v1.Telemetry
inline constexpr std::string_view kStability = "/supervisor/stability";    // v1.StabilityReport
inline constexpr std::string_view kAlarms = "/supervisor/alarms";          // v1.Alarm
inline constexpr std::string_view kParameterChanges =
    "/supervisor/parameter_changes";                               // v1.ParameterChangeRecord
inline constexpr std::string_view kStatus = "/supervisor/status";  // v1.SupervisorStatus
inline constexpr std::string_view kSupervisorPrefix = "/supervisor/";
// A node's telemetry topic.
[[nodiscard]] constexpr std::string_view telemetry(bool master) noexcept {
  return master ? kMasterTelemetry : kSlaveTelemetry;
}
}  // namespace topic

// Where a session's messages go (the MCAP session file; tests capture them).
class SessionSink {
 public:
  virtual ~SessionSink() = default;
  // `type` names the protobuf message type of `bytes` (its full name).
  virtual void record(std::string_view topic, const std::string& type, std::int64_t log_time_ns,
                      const std::string& bytes) = 0;
  [[nodiscard]] virtual std::string file() const { return {}; }
  [[nodiscard]] virtual std::uint64_t recorded() const { return 0; }
  [[nodiscard]] virtual std::uint64_t drops() const { return 0; }
  [[nodiscard]] virtual std::uint64_t bytes() const { return 0; }
  // "" while recording works; else why it stopped (disk full, I/O error), naming the file.
  [[nodiscard]] virtual std::string error() const { return {}; }
};

}  // namespace teleop::record
