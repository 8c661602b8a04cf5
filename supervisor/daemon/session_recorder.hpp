// The supervisor's session file: an MCAP (common/record) with one channel per topic, each
// carrying protobuf messages whose schema is embedded. Topics: /config, /master/telemetry,
// /slave/telemetry, /supervisor/stability, /supervisor/alarms, /supervisor/parameter_changes.
#pragma once

#include <filesystem>
#include <memory>

#include "supervisor/daemon/supervisor_app.hpp"

namespace teleop::supervisor {

// A new file teleop-session-YYYYMMDD-HHMMSS.mcap in `dir` (UTC); throws naming it when it
// cannot be created. Recording never blocks the caller (drops are counted).
[[nodiscard]] std::unique_ptr<RecordSink> make_session_recorder(const std::filesystem::path& dir);

// The same, at an exact path (teleopctl simulate --out, tests).
[[nodiscard]] std::unique_ptr<RecordSink> make_session_recorder_at(
    const std::filesystem::path& file);

}  // namespace teleop::supervisor
