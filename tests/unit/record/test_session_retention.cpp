// Session retention (docs/supervisor.md "Session retention"): files of made-up sizes in a temp
// directory; which remain is worked out by hand from the policy (oldest by the start time in
// the name, the current one never removed, other files never touched).
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <set>
#include <string>

#include "common/record/session_recorder.hpp"
#include "common/record/session_retention.hpp"
#include "tests/unit/record/record_test_util.hpp"

namespace teleop::record {
namespace {

void write_file(const std::filesystem::path& p, std::size_t bytes) {
  std::ofstream out(p, std::ios::binary);
  out << std::string(bytes, 'x');
}

std::set<std::string> names_in(const std::filesystem::path& dir) {
  std::set<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    out.insert(e.path().filename().string());
  }
  return out;
}

TEST(SessionRetention, OnlyTheRecordersNamesAreSessionFiles) {
  EXPECT_TRUE(is_session_file_name("teleop-session-20261122-101500.mcap"));
  EXPECT_TRUE(is_session_file_name("teleop-session-20261122-101500-2.mcap"));
  EXPECT_FALSE(is_session_file_name("teleop-session-20261122-101500.mcap.bak"));
  EXPECT_FALSE(is_session_file_name("teleop-session-2026112-101500.mcap"));
  EXPECT_FALSE(is_session_file_name("teleop-session-20261122_101500.mcap"));
  EXPECT_FALSE(is_session_file_name("teleop-session-20261122-101500-.mcap"));
  EXPECT_FALSE(is_session_file_name("my-session.mcap"));
  EXPECT_FALSE(is_session_file_name("teleop-supervisor.log"));
}

TEST(SessionRetention, KeepsTheNewestNByStartTimeWithASameSecondSuffixAfterItsBase) {
  test::TempDir dir;
  // Written in an order unlike their age, so the file system's order does not decide.
  for (const char* n :
       {"teleop-session-20261122-101500-2.mcap", "teleop-session-20261121-235959.mcap",
        "teleop-session-20261122-101500.mcap", "teleop-session-20261120-080000.mcap",
        "teleop-session-20261122-101500-10.mcap"}) {
    write_file(dir / n, 100);
  }
  write_file(dir / "teleop-supervisor.log", 100);
  write_file(dir / "notes.mcap", 100);
  // Oldest to newest: 20261120-080000, 20261121-235959, 20261122-101500, ...-2, ...-10 (the
  // current one). At most 2: the three oldest go, the base of the same second among them
  // (by plain name order "-10" < "-2" < "." it would be the newest and stay).
  const auto removed =
      apply_retention(dir.path(), {2, 0}, dir / "teleop-session-20261122-101500-10.mcap");
  EXPECT_EQ(removed.size(), 3u);
  EXPECT_EQ(names_in(dir.path()), (std::set<std::string>{"teleop-session-20261122-101500-2.mcap",
                                                         "teleop-session-20261122-101500-10.mcap",
                                                         "teleop-supervisor.log", "notes.mcap"}));
}

TEST(SessionRetention, ABytesLimitRemovesTheOldestUntilTheRestFits) {
  test::TempDir dir;
  write_file(dir / "teleop-session-20260101-000000.mcap", 4000);
  write_file(dir / "teleop-session-20260102-000000.mcap", 3000);
  write_file(dir / "teleop-session-20260103-000000.mcap", 2500);
  write_file(dir / "teleop-session-20260104-000000.mcap", 10);  // the current, just started
  // 9510 bytes; at most 6000: without the oldest 5510 is within, so only it goes.
  apply_retention(dir.path(), {0, 6000}, dir / "teleop-session-20260104-000000.mcap");
  EXPECT_EQ(names_in(dir.path()), (std::set<std::string>{"teleop-session-20260102-000000.mcap",
                                                         "teleop-session-20260103-000000.mcap",
                                                         "teleop-session-20260104-000000.mcap"}));
  // At most 2600 now: 5510 -> 2510 (the 3000 goes) fits.
  apply_retention(dir.path(), {0, 2600}, dir / "teleop-session-20260104-000000.mcap");
  EXPECT_EQ(names_in(dir.path()), (std::set<std::string>{"teleop-session-20260103-000000.mcap",
                                                         "teleop-session-20260104-000000.mcap"}));
}

TEST(SessionRetention, TheCurrentSessionIsNeverRemovedEvenWhenItIsTheOldestOrAloneTooBig) {
  // The clock went back: the current file's name is the oldest. Limit 1: every other goes.
  const std::vector<std::filesystem::path> removed =
      sessions_to_remove({{"d/teleop-session-20260105-000000.mcap", 1},
                          {"d/teleop-session-20260101-000000.mcap", 1},
                          {"d/teleop-session-20260103-000000.mcap", 1}},
                         {1, 0}, "d/teleop-session-20260101-000000.mcap");
  EXPECT_EQ(removed, (std::vector<std::filesystem::path>{"d/teleop-session-20260103-000000.mcap",
                                                         "d/teleop-session-20260105-000000.mcap"}));
  // A current file alone above the bytes limit stays, and so the limit stays exceeded.
  EXPECT_TRUE(sessions_to_remove({{"d/teleop-session-20260101-000000.mcap", 5000}}, {0, 100},
                                 "d/teleop-session-20260101-000000.mcap")
                  .empty());
}

TEST(SessionRetention, NoLimitRemovesNothing) {
  EXPECT_TRUE(sessions_to_remove({{"d/teleop-session-20260101-000000.mcap", 1'000'000'000},
                                  {"d/teleop-session-20260102-000000.mcap", 1'000'000'000}},
                                 {0, 0}, "d/teleop-session-20260102-000000.mcap")
                  .empty());
}

TEST(SessionRetention, WithTheRecordersOwnFilesTheOneJustStartedStays) {
  test::TempDir dir;
  write_file(dir / "teleop-session-20000101-000000.mcap", 100);
  write_file(dir / "teleop-session-20000102-000000.mcap", 100);
  std::unique_ptr<SessionSink> sink = make_session_recorder(dir.path());
  const auto removed = apply_retention(dir.path(), {1, 0}, sink->file());
  EXPECT_EQ(removed.size(), 2u);
  EXPECT_EQ(names_in(dir.path()),
            (std::set<std::string>{std::filesystem::path(sink->file()).filename().string()}));
}

}  // namespace
}  // namespace teleop::record
