#include "common/record/session_retention.hpp"

#include <algorithm>
#include <cctype>
#include <string_view>
#include <system_error>
#include <tuple>

namespace teleop::record {
namespace {

constexpr std::string_view kPrefix = "teleop-session-";
constexpr std::string_view kSuffix = ".mcap";
constexpr std::size_t kStampSize = 15;  // YYYYMMDD-HHMMSS

bool digits(std::string_view s) {
  return !s.empty() &&
         std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c) != 0; });
}

// The start time (YYYYMMDD-HHMMSS, sorts as text) and the same-second number (1 without one).
std::tuple<std::string, unsigned long> age_key(const std::filesystem::path& p) {
  const std::string name = p.filename().string();
  const std::string stem =
      name.substr(kPrefix.size(), name.size() - kPrefix.size() - kSuffix.size());
  const unsigned long n = stem.size() > kStampSize ? std::stoul(stem.substr(kStampSize + 1)) : 1;
  return {stem.substr(0, kStampSize), n};
}

}  // namespace

bool is_session_file_name(const std::string& name) {
  if (name.size() < kPrefix.size() + kStampSize + kSuffix.size()) return false;
  if (name.compare(0, kPrefix.size(), kPrefix) != 0) return false;
  if (name.compare(name.size() - kSuffix.size(), kSuffix.size(), kSuffix) != 0) return false;
  const std::string_view stem =
      std::string_view(name).substr(kPrefix.size(), name.size() - kPrefix.size() - kSuffix.size());
  const std::string_view stamp = stem.substr(0, kStampSize);
  if (stamp.size() != kStampSize || stamp[8] != '-' || !digits(stamp.substr(0, 8)) ||
      !digits(stamp.substr(9))) {
    return false;
  }
  if (stem.size() == kStampSize) return true;
  return stem[kStampSize] == '-' && digits(stem.substr(kStampSize + 1)) &&
         stem.size() - kStampSize - 1 <= 9;
}

std::vector<std::filesystem::path> sessions_to_remove(std::vector<SessionFileInfo> files,
                                                      const RetentionPolicy& policy,
                                                      const std::filesystem::path& current) {
  std::vector<std::filesystem::path> out;
  if (!policy.limited()) return out;
  std::sort(files.begin(), files.end(), [](const SessionFileInfo& a, const SessionFileInfo& b) {
    return age_key(a.path) < age_key(b.path);
  });
  std::size_t count = files.size();
  std::uint64_t bytes = 0;
  for (const SessionFileInfo& f : files) bytes += f.bytes;
  auto over = [&] {
    return (policy.max_sessions > 0 && count > policy.max_sessions) ||
           (policy.max_bytes > 0 && bytes > policy.max_bytes);
  };
  for (const SessionFileInfo& f : files) {
    if (!over()) break;
    if (f.path.filename() == current.filename()) continue;
    out.push_back(f.path);
    --count;
    bytes -= f.bytes;
  }
  return out;
}

std::vector<std::filesystem::path> apply_retention(const std::filesystem::path& dir,
                                                   const RetentionPolicy& policy,
                                                   const std::filesystem::path& current,
                                                   std::vector<std::string>* failures) {
  std::vector<std::filesystem::path> removed;
  if (!policy.limited()) return removed;
  std::vector<SessionFileInfo> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (!entry.is_regular_file(ec) || !is_session_file_name(entry.path().filename().string())) {
      continue;
    }
    const std::uintmax_t size = entry.file_size(ec);
    files.push_back({entry.path(), ec ? 0 : static_cast<std::uint64_t>(size)});
  }
  if (ec && failures) failures->push_back(dir.string() + ": " + ec.message());
  for (const std::filesystem::path& p : sessions_to_remove(std::move(files), policy, current)) {
    std::error_code rm;
    if (std::filesystem::remove(p, rm)) {
      removed.push_back(p);
    } else if (failures) {
      failures->push_back(p.string() + ": " + (rm ? rm.message() : "not removed"));
    }
  }
  return removed;
}

}  // namespace teleop::record
