// Session retention (docs/supervisor.md "Session retention"): the record directory keeps at
// most a configured number of session files and bytes; when a new session starts, the oldest
// are removed until both limits hold again, never the session being recorded.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace teleop::record {

struct RetentionPolicy {
  std::uint32_t max_sessions{0};  // 0: no limit
  std::uint64_t max_bytes{0};     // 0: no limit
  [[nodiscard]] bool limited() const noexcept { return max_sessions > 0 || max_bytes > 0; }
};

struct SessionFileInfo {
  std::filesystem::path path{};
  std::uint64_t bytes{0};
};

// Whether `name` is a session file's name as make_session_recorder gives it:
// teleop-session-YYYYMMDD-HHMMSS.mcap or teleop-session-YYYYMMDD-HHMMSS-N.mcap (N >= 2, a
// second file in the same second). Nothing else in the directory is ever removed.
[[nodiscard]] bool is_session_file_name(const std::string& name);

// Which of `files` (any order) to remove, oldest first: the oldest by the start time in the
// name (then N), until at most max_sessions files and max_bytes bytes remain, counting the
// current one, which is never removed (so the limits may stay exceeded by it alone).
[[nodiscard]] std::vector<std::filesystem::path> sessions_to_remove(
    std::vector<SessionFileInfo> files, const RetentionPolicy& policy,
    const std::filesystem::path& current);

// The session files in `dir`, then removes what sessions_to_remove says. Returns the removed
// paths; a file that cannot be removed is skipped (named in `failures`).
std::vector<std::filesystem::path> apply_retention(const std::filesystem::path& dir,
                                                   const RetentionPolicy& policy,
                                                   const std::filesystem::path& current,
                                                   std::vector<std::string>* failures = nullptr);

}  // namespace teleop::record
