// The session file writer: an MCAP with one channel per topic (common/record/session.hpp), each
// carrying protobuf messages whose schema is embedded.
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include "common/record/session.hpp"

namespace teleop::record {

// A new file teleop-session-YYYYMMDD-HHMMSS.mcap in `dir` (UTC); throws naming it when it
// cannot be created. Recording never blocks the caller (drops are counted).
[[nodiscard]] std::unique_ptr<SessionSink> make_session_recorder(const std::filesystem::path& dir);

// The MCAP header's library string of a session: "teleop <version>" (common/core/version.hpp).
[[nodiscard]] std::string session_library();

// The same, at an exact path (teleopctl simulate --out, tests).
[[nodiscard]] std::unique_ptr<SessionSink> make_session_recorder_at(
    const std::filesystem::path& file);

}  // namespace teleop::record
