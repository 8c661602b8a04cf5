// The systemd watchdog decision (issue 8): fed every half interval while the loop's heartbeat
// advances, not fed once it has stalled for longer than the limit (with a status saying so),
// fed again when it resumes — on a fake clock, expectations worked out by hand. Then the
// notifier's datagrams on a fake NOTIFY_SOCKET, and nothing at all without one.
#include <gtest/gtest.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "common/runtime/service_notify.hpp"

namespace teleop::runtime {
namespace {

using namespace std::chrono_literals;
using std::chrono::milliseconds;
using std::chrono::nanoseconds;

struct Look {
  std::uint64_t heartbeat;
  milliseconds at;
  bool feed;
  std::string status_starts;  // "" : no status
};

TEST(WatchdogFeeder, FeedsWhileAdvancingStopsWhenStalledResumes) {
  // WATCHDOG_USEC 200 ms: fed every 100 ms; stalled after 50 ms without an advance.
  WatchdogFeeder w(200ms, 50ms, 0ns);
  EXPECT_EQ(w.feed_every(), 100ms);
  const std::vector<Look> looks = {
      {5, 0ms, false, ""},      // the baseline: nothing known about advancing yet
      {30, 25ms, true, ""},     // advanced: first feed
      {55, 50ms, false, ""},    // advanced, but fed 25 ms ago
      {130, 125ms, true, ""},   // 100 ms since the last feed
      {130, 150ms, false, ""},  // unchanged for 25 ms: within the limit, not due
      {130, 175ms, false, ""},  // 50 ms: at the limit, still not stalled
      {130, 180ms, false, "stalled: its cycle counter has stayed at 130 for 55 ms (limit 50 ms)"},
      {130, 225ms, false, ""},  // due, but stalled (and said once)
      {130, 400ms, false, ""},
      {131, 420ms, true, "running again after 295 ms without a cycle"},
      {140, 440ms, false, ""},
      {150, 520ms, true, ""},
  };
  for (const Look& l : looks) {
    const WatchdogAction a = w.observe(l.heartbeat, l.at);
    EXPECT_EQ(a.feed, l.feed) << "at " << l.at.count() << " ms";
    if (l.status_starts.empty()) {
      EXPECT_EQ(a.status, "") << "at " << l.at.count() << " ms";
    } else {
      EXPECT_EQ(a.status.rfind(l.status_starts, 0), 0u) << a.status;
    }
    EXPECT_EQ(w.stalled(), l.at >= 180ms && l.at < 420ms) << "at " << l.at.count() << " ms";
  }
}

TEST(WatchdogFeeder, StallStatusNamesTheNumbers) {
  WatchdogFeeder w(4000ms, WatchdogFeeder::default_stall_limit(4000ms), 0ns);
  EXPECT_EQ(w.stall_limit(), 1000ms);                       // a quarter of 4 s
  EXPECT_EQ(WatchdogFeeder::default_stall_limit(20s), 1s);  // at most 1 s
  (void)w.observe(7, 0ms);
  EXPECT_TRUE(w.observe(8, 10ms).feed);
  const WatchdogAction a = w.observe(8, 1500ms);
  EXPECT_FALSE(a.feed);
  EXPECT_EQ(a.status,
            "stalled: its cycle counter has stayed at 8 for 1490 ms (limit 1000 ms); not feeding "
            "the watchdog (WATCHDOG_USEC 4000 ms)");
}

TEST(WatchdogFeeder, WaitsUntilTheNextFeedAndLooksOftenEnoughForAStall) {
  WatchdogFeeder w(200ms, 50ms, 0ns);
  EXPECT_EQ(w.wait_after(0ns), 25ms);  // nothing fed yet: look again after half the limit
  (void)w.observe(1, 0ms);
  EXPECT_TRUE(w.observe(2, 25ms).feed);
  EXPECT_EQ(w.wait_after(25ms), 25ms);   // next feed at 125 ms, but look every 25 ms
  EXPECT_EQ(w.wait_after(110ms), 15ms);  // the feed is due at 125 ms
  EXPECT_EQ(w.wait_after(130ms), 25ms);  // overdue (stalled or late): look again soon
  // A long interval: looks at most every 100 ms.
  WatchdogFeeder slow(10s, WatchdogFeeder::default_stall_limit(10s), 0ns);
  EXPECT_EQ(slow.wait_after(0ns), 100ms);
}

// The daemons' thread as it runs: look, wait what the feeder says, look again — against a 1 kHz
// loop on a simulated clock that freezes between 5 s and 6 s. Feeds come exactly every 100 ms
// while the loop runs; systemd (200 ms) would see the stall; they resume within one look.
TEST(WatchdogFeeder, DrivenLoopFeedsEveryHalfIntervalAndStopsDuringAStall) {
  WatchdogFeeder w(200ms, 50ms, 0ns);
  const nanoseconds freeze_from = 5s;
  const nanoseconds freeze_to = 6s;
  auto heartbeat = [&](nanoseconds t) {
    const nanoseconds running = t < freeze_from ? t : (t < freeze_to ? freeze_from : t - 1s);
    return static_cast<std::uint64_t>(running / 1ms);
  };
  std::vector<nanoseconds> feeds;
  std::vector<std::string> statuses;
  for (nanoseconds t = 0ns; t < 10s; t += w.wait_after(t)) {
    const WatchdogAction a = w.observe(heartbeat(t), t);
    if (a.feed) feeds.push_back(t);
    if (!a.status.empty()) statuses.push_back(a.status);
  }
  ASSERT_FALSE(feeds.empty());
  EXPECT_EQ(feeds.front(), 25ms);  // the first look after the baseline
  // Every gap is 100 ms but one: the stall's.
  std::vector<std::pair<nanoseconds, nanoseconds>> long_gaps;
  for (std::size_t i = 1; i < feeds.size(); ++i) {
    if (feeds[i] - feeds[i - 1] != 100ms) long_gaps.emplace_back(feeds[i - 1], feeds[i]);
  }
  ASSERT_EQ(long_gaps.size(), 1u);
  const auto [before_stall, after_stall] = long_gaps.front();
  // Fed at most until the stall limit (50 ms) after the last advance (5 s); systemd's 200 ms
  // pass without a feed; the first feed after the loop resumes comes within a look (25 ms).
  EXPECT_EQ(before_stall, 5025ms);
  EXPECT_GT(after_stall - before_stall, 200ms);
  EXPECT_EQ(after_stall, 6025ms);
  ASSERT_EQ(statuses.size(), 2u);
  EXPECT_EQ(statuses[0],
            "stalled: its cycle counter has stayed at 5000 for 75 ms (limit 50 ms); "
            "not feeding the watchdog (WATCHDOG_USEC 200 ms)");
  EXPECT_EQ(statuses[1].rfind("running again after 1025 ms without a cycle", 0), 0u) << statuses[1];
  // 25 ms .. 5025 ms and 6025 ms .. 9925 ms, every 100 ms.
  EXPECT_EQ(feeds.size(), 51u + 40u);
}

// A datagram socket standing in for systemd's notify socket.
class FakeNotifySocket {
 public:
  FakeNotifySocket() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "teleop-notify-XXXXXX").string();
    dir_ = ::mkdtemp(tmpl.data());
    path_ = (std::filesystem::path(dir_) / "notify").string();
    fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_un a{};
    a.sun_family = AF_UNIX;
    path_.copy(a.sun_path, sizeof(a.sun_path) - 1);
    bound_ = ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
  }
  ~FakeNotifySocket() {
    ::close(fd_);
    std::filesystem::remove_all(dir_);
  }
  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] bool bound() const { return bound_; }
  // The datagram already queued (sd_notify's sendmsg has returned), if any.
  std::optional<std::string> take() const {
    char buf[4096];
    const ssize_t n = ::recv(fd_, buf, sizeof(buf), MSG_DONTWAIT);
    if (n < 0) return std::nullopt;
    return std::string(buf, static_cast<std::size_t>(n));
  }

 private:
  std::string dir_;
  std::string path_;
  int fd_{-1};
  bool bound_{false};
};

class Environment {
 public:
  explicit Environment(const std::vector<std::pair<std::string, std::string>>& set) {
    for (const char* name : {"NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID"}) {
      ::unsetenv(name);
    }
    for (const auto& [k, v] : set) ::setenv(k.c_str(), v.c_str(), 1);
  }
  ~Environment() {
    for (const char* name : {"NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID"}) {
      ::unsetenv(name);
    }
  }
};

TEST(ServiceNotifier, SpeaksTheProtocolOnTheSocket) {
  FakeNotifySocket sock;
  ASSERT_TRUE(sock.bound());
  const Environment env({{"NOTIFY_SOCKET", sock.path()}, {"WATCHDOG_USEC", "200000"}});
  ServiceNotifier n("RT loop");
  EXPECT_TRUE(n.notify_socket());
  ASSERT_TRUE(n.watchdog_interval().has_value());
  EXPECT_EQ(*n.watchdog_interval(), 200ms);

  n.ready("master loop at 1000 Hz\nsession 1");
  EXPECT_EQ(sock.take(), "READY=1\nSTATUS=master loop at 1000 Hz session 1");
  const nanoseconds t0 = monotonic_now();
  EXPECT_EQ(n.heartbeat(10, t0), 25ms);  // the baseline
  EXPECT_EQ(sock.take(), std::nullopt);
  (void)n.heartbeat(20, t0 + 10ms);
  EXPECT_EQ(sock.take(), "WATCHDOG=1");
  (void)n.heartbeat(30, t0 + 60ms);
  EXPECT_EQ(sock.take(), std::nullopt);
  (void)n.heartbeat(40, t0 + 110ms);
  EXPECT_EQ(sock.take(), "WATCHDOG=1");
  (void)n.heartbeat(40, t0 + 170ms);  // 60 ms without an advance
  const std::optional<std::string> stalled = sock.take();
  ASSERT_TRUE(stalled.has_value());
  EXPECT_EQ(
      stalled->rfind("STATUS=RT loop stalled: its cycle counter has stayed at 40 for 60 ms", 0), 0u)
      << *stalled;
  (void)n.heartbeat(40, t0 + 300ms);
  EXPECT_EQ(sock.take(), std::nullopt);
  (void)n.heartbeat(41, t0 + 320ms);
  const std::optional<std::string> resumed = sock.take();
  ASSERT_TRUE(resumed.has_value());
  EXPECT_EQ(resumed->rfind("WATCHDOG=1\nSTATUS=RT loop running again after 210 ms", 0), 0u)
      << *resumed;
  EXPECT_EQ(n.feeds(), 3u);
  n.stopping("signal 15: stopping");
  EXPECT_EQ(sock.take(), "STOPPING=1\nSTATUS=signal 15: stopping");
}

TEST(ServiceNotifier, WatchdogForAnotherProcessIsOff) {
  FakeNotifySocket sock;
  ASSERT_TRUE(sock.bound());
  const Environment env({{"NOTIFY_SOCKET", sock.path()},
                         {"WATCHDOG_USEC", "200000"},
                         {"WATCHDOG_PID", std::to_string(::getpid() + 1)}});
  ServiceNotifier n("main loop");
  EXPECT_TRUE(n.notify_socket());
  EXPECT_FALSE(n.watchdog_interval().has_value());
  const nanoseconds t0 = monotonic_now();
  EXPECT_EQ(n.heartbeat(1, t0), 100ms);
  EXPECT_EQ(n.heartbeat(2, t0 + 200ms), 100ms);
  EXPECT_EQ(sock.take(), std::nullopt);
  n.ready("up");
  EXPECT_EQ(sock.take(), "READY=1\nSTATUS=up");
}

TEST(ServiceNotifier, NoSocketNoDatagrams) {
  FakeNotifySocket sock;
  ASSERT_TRUE(sock.bound());
  const Environment env({{std::string("WATCHDOG_USEC"), std::string("200000")}});
  ServiceNotifier n("RT loop");
  EXPECT_FALSE(n.notify_socket());
  EXPECT_FALSE(n.watchdog_interval().has_value());
  n.ready("up");
  const nanoseconds t0 = monotonic_now();
  (void)n.heartbeat(1, t0);
  (void)n.heartbeat(2, t0 + 150ms);
  n.stopping("down");
  EXPECT_EQ(n.feeds(), 0u);
  EXPECT_EQ(sock.take(), std::nullopt);
}

}  // namespace
}  // namespace teleop::runtime
