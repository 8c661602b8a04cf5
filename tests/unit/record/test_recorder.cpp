// The Recorder: producers on several threads, chunk age on a fake clock, a writer stalled on a
// full pipe (producers drop, never wait), a process killed mid-recording, a file-size limit
// hit mid-recording (the disk-full path) — each leaving a file whose complete chunks recover.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "common/record/recorder.hpp"
#include "tests/unit/record/record_test_util.hpp"

namespace teleop::record {
namespace {

using namespace std::chrono_literals;

std::string payload(std::uint64_t i, std::size_t size) {
  std::string p = "message " + std::to_string(i) + " ";
  p.resize(std::max(size, p.size()), static_cast<char>('a' + i % 26));
  return p;
}

// Every recovered message is the next one written: a prefix, nothing lost in between.
void expect_prefix(const McapReader& r, std::size_t count, std::size_t size) {
  const std::vector<MessageView> got = r.messages(Order::kFile);
  ASSERT_EQ(got.size(), count);
  for (std::size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(got[i].data, payload(i, size)) << i;
    ASSERT_EQ(got[i].log_time_ns, i) << i;
  }
}

TEST(Recorder, ProducersOnSeveralThreadsRoundTrip) {
  test::TempDir dir;
  const auto path = dir / "threads.mcap";
  constexpr int kThreads = 4;
  constexpr std::uint64_t kEach = 5000;
  std::uint64_t bytes = 0;
  {
    RecorderOptions o{};
    o.writer.chunk_size_bytes = 32 * 1024;
    Recorder rec(path, o);
    const auto schema = rec.add_schema({"t.T", "protobuf", "fds"});
    std::array<std::uint16_t, kThreads> channels{};
    for (int t = 0; t < kThreads; ++t) {
      channels[static_cast<std::size_t>(t)] =
          rec.add_channel({schema, "/producer/" + std::to_string(t), "protobuf", {}});
    }
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&rec, ch = channels[static_cast<std::size_t>(t)]] {
        for (std::uint64_t i = 0; i < kEach; ++i) {
          EXPECT_TRUE(rec.record(ch, i, payload(i, 60)));
        }
      });
    }
    for (auto& th : threads) th.join();
    for (std::uint64_t i = 0; i < kEach; ++i) bytes += kThreads * payload(i, 60).size();
    EXPECT_TRUE(rec.close()) << rec.error();
    EXPECT_EQ(rec.drops(), 0u);
    EXPECT_EQ(rec.written(), kThreads * kEach);
    EXPECT_EQ(rec.bytes_written(), bytes);
    EXPECT_EQ(rec.file_size(), std::filesystem::file_size(path));
    EXPECT_EQ(rec.error(), "");
  }
  const McapReader r = McapReader::open(path);
  EXPECT_TRUE(r.validate().empty());
  EXPECT_EQ(r.statistics()->message_count, kThreads * kEach);
  std::map<std::string, std::uint64_t> next;
  for (const MessageView& m : r.messages(Order::kFile)) {
    std::uint64_t& i = next[m.channel->topic];
    ASSERT_EQ(m.data, payload(i, 60)) << m.channel->topic;
    ASSERT_EQ(m.sequence, i);
    ++i;
  }
  ASSERT_EQ(next.size(), static_cast<std::size_t>(kThreads));
  for (const auto& [topic, n] : next) EXPECT_EQ(n, kEach) << topic;
}

TEST(Recorder, OpenChunkIsFlushedByAgeOnTheInjectedClock) {
  test::TempDir dir;
  const auto path = dir / "age.mcap";
  test::FakeClock clock;
  RecorderOptions o{};
  o.writer.clock = clock.clock();
  o.writer.max_chunk_age = 200ms;
  Recorder rec(path, o);
  const auto ch = rec.add_channel({0, "/t", "json", {}});
  for (std::uint64_t i = 0; i < 3; ++i) ASSERT_TRUE(rec.record(ch, i, payload(i, 30)));
  ASSERT_TRUE(rec.sync());
  EXPECT_EQ(rec.written(), 0u) << "younger than 200 ms on the fake clock";
  const std::uint64_t header_only = rec.file_size();
  clock.advance(199ms);
  ASSERT_TRUE(rec.sync());
  EXPECT_EQ(rec.written(), 0u);
  clock.advance(1ms);
  ASSERT_TRUE(rec.sync());
  EXPECT_EQ(rec.written(), 3u);
  EXPECT_GT(rec.file_size(), header_only);
  // Readable while the recording goes on.
  const McapReader r = McapReader::recover(path);
  expect_prefix(r, 3, 30);
  EXPECT_EQ(r.recovery()->data_end, rec.file_size());
}

TEST(Recorder, AQuietChannelIsFlushedWithoutNewMessages) {
  test::TempDir dir;
  test::FakeClock clock;
  RecorderOptions o{};
  o.writer.clock = clock.clock();
  o.wake_period = 1ms;
  Recorder rec(dir / "quiet.mcap", o);
  const auto ch = rec.add_channel({0, "/t", "json", {}});
  for (std::uint64_t i = 0; i < 3; ++i) ASSERT_TRUE(rec.record(ch, i, payload(i, 30)));
  ASSERT_TRUE(rec.sync());  // the chunk opens at fake time 0
  EXPECT_EQ(rec.written(), 0u);
  clock.advance(1s);
  // No sync(), no new message: the writer thread's own periodic wake must flush the chunk.
  EXPECT_TRUE(rec.wait_written(3, 60s));
}

TEST(Recorder, FlushBoundariesAreRecoveryPoints) {
  test::TempDir dir;
  const auto path = dir / "b.mcap";
  test::FakeClock clock;
  RecorderOptions o{};
  o.writer.clock = clock.clock();
  std::vector<std::pair<std::uint64_t, std::uint64_t>> boundaries;  // (file size, written)
  {
    Recorder rec(path, o);
    const auto ch = rec.add_channel({0, "/t", "json", {}});
    std::uint64_t i = 0;
    for (int batch = 0; batch < 12; ++batch) {
      for (int k = 0; k <= batch * 5; ++k, ++i) ASSERT_TRUE(rec.record(ch, i, payload(i, 50)));
      ASSERT_TRUE(rec.flush());
      boundaries.emplace_back(rec.file_size(), rec.written());
      EXPECT_EQ(rec.written(), i);
    }
    ASSERT_TRUE(rec.close());
  }
  const std::string file = test::slurp(path);
  for (const auto& [size, written] : boundaries) {
    SCOPED_TRACE("cut at " + std::to_string(size));
    test::spit(dir / "cut.mcap", std::string_view(file).substr(0, size));
    const McapReader r = McapReader::recover(dir / "cut.mcap");
    EXPECT_EQ(r.recovery()->data_end, size);
    expect_prefix(r, written, 50);
  }
}

TEST(Recorder, DropsAndRefusesWhatItCannotRecord) {
  test::TempDir dir;
  Recorder rec(dir / "d.mcap");
  EXPECT_FALSE(rec.record(1, 0, std::string("no channel yet")));
  const auto ch = rec.add_channel({0, "/t", "json", {}});
  EXPECT_FALSE(rec.record(0, 0, std::string("channel 0")));
  EXPECT_FALSE(rec.record(static_cast<std::uint16_t>(ch + 1), 0, std::string("unknown")));
  const std::array<std::byte, 3> raw{std::byte{1}, std::byte{2}, std::byte{3}};
  EXPECT_TRUE(rec.record(ch, 5, std::span<const std::byte>(raw)));
  EXPECT_THROW((void)rec.add_channel({7, "/bad", "protobuf", {}}), std::invalid_argument);
  EXPECT_TRUE(rec.close());
  EXPECT_TRUE(rec.close()) << "idempotent";
  EXPECT_FALSE(rec.record(ch, 6, std::string("after close")));
  EXPECT_EQ(rec.drops(), 4u);
  EXPECT_EQ(rec.written(), 1u);
  const McapReader r = McapReader::open(dir / "d.mcap");
  ASSERT_EQ(r.messages().size(), 1u);
  EXPECT_EQ(r.messages()[0].data, std::string("\x01\x02\x03"));
}

TEST(RecorderStall, ProducersDropRatherThanWaitForAStalledWriter) {
  // The writer's file is a pipe no one reads: once the pipe's buffer is full its write()
  // blocks, as on a hung disk. Producers must go on, dropping and counting.
  test::TempDir dir;
  const auto fifo = dir / "stalled.mcap";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const int rd = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  ASSERT_GE(rd, 0);
  RecorderOptions o{};
  o.queue_messages = 512;
  o.writer.chunk_size_bytes = 8 * 1024;
  Recorder rec(fifo, o);
  const auto ch = rec.add_channel({0, "/t", "json", {}});
  constexpr std::uint64_t kCount = 50'000;
  std::uint64_t accepted = 0;
  auto slowest = std::chrono::steady_clock::duration::zero();
  for (std::uint64_t i = 0; i < kCount; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const bool ok = rec.record(ch, i, payload(i, 100));
    slowest = std::max(slowest, std::chrono::steady_clock::now() - t0);
    if (ok) ++accepted;
  }
  EXPECT_GT(rec.drops(), 0u);
  EXPECT_EQ(accepted + rec.drops(), kCount);
  EXPECT_LT(accepted, kCount / 10) << "the writer cannot have taken more than a pipe's worth";
  EXPECT_LT(rec.written(), accepted);
  // A stalled writer would hold a blocked producer forever; this bound is only a sanity check.
  EXPECT_LT(slowest, 1s);
  EXPECT_TRUE(rec.ok());

  // Unstall: drain the pipe; close() then writes everything accepted and the summary.
  ASSERT_EQ(::fcntl(rd, F_SETFL, 0), 0);
  std::string drained;
  std::thread reader([&] {
    char buf[65536];
    ssize_t n = 0;
    while ((n = ::read(rd, buf, sizeof(buf))) > 0) drained.append(buf, static_cast<std::size_t>(n));
  });
  EXPECT_TRUE(rec.close()) << rec.error();
  reader.join();
  ::close(rd);
  test::spit(dir / "drained.mcap", drained);
  const McapReader r = McapReader::open(dir / "drained.mcap");
  EXPECT_TRUE(r.validate().empty());
  EXPECT_EQ(r.statistics()->message_count, accepted);
  EXPECT_EQ(rec.written(), accepted);
}

TEST(RecorderErrors, DiskFullAtCreationNamesTheFile) {
  ASSERT_TRUE(std::filesystem::is_character_file("/dev/full"));
  try {
    Recorder rec("/dev/full");
    FAIL() << "/dev/full accepted the header";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("/dev/full"), std::string::npos) << what;
    EXPECT_NE(what.find(std::strerror(ENOSPC)), std::string::npos) << what;
  }
}

// What a child process reports back through a pipe.
struct ChildReport {
  bool ok{true};
  bool record_after_error{true};
  bool close_ok{true};
  std::uint64_t written{0};
  std::uint64_t drops{0};
  std::uint64_t accepted{0};
  char error[512]{};
};

bool read_all(int fd, void* out, std::size_t n) {
  auto* p = static_cast<char*>(out);
  while (n > 0) {
    const ssize_t r = ::read(fd, p, n);
    if (r <= 0) return false;
    p += r;
    n -= static_cast<std::size_t>(r);
  }
  return true;
}

TEST(RecorderErrors, FileSizeLimitMidRecordingStopsWithAnErrorAndLeavesARecoverableFile) {
  // RLIMIT_FSIZE makes write() fail with EFBIG past 64 KiB, as a full disk fails with ENOSPC:
  // the same path through the writer. Set in a child so this process keeps its limits.
  test::TempDir dir;
  const auto path = dir / "limited.mcap";
  constexpr std::uint64_t kLimit = 64 * 1024;
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(fds[0]);
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{kLimit, kLimit};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    ChildReport rep{};
    {
      RecorderOptions o{};
      o.writer.chunk_size_bytes = 4096;
      Recorder rec(path, o);
      const auto ch = rec.add_channel({0, "/t", "json", {}});
      for (std::uint64_t i = 0; i < 2000; ++i) {
        if (rec.record(ch, i, payload(i, 200))) ++rep.accepted;
        if (i % 20 == 19) (void)rec.sync();
      }
      (void)rec.sync();
      rep.ok = rec.ok();
      rep.record_after_error = rec.record(ch, 9999, payload(9999, 200));
      rep.close_ok = rec.close();
      rep.written = rec.written();
      rep.drops = rec.drops();
      std::snprintf(rep.error, sizeof(rep.error), "%s", rec.error().c_str());
    }
    (void)!::write(fds[1], &rep, sizeof(rep));
    ::_exit(0);
  }
  ::close(fds[1]);
  ChildReport rep{};
  const bool got = read_all(fds[0], &rep, sizeof(rep));
  ::close(fds[0]);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(got) << "the child did not report (status " << status << ")";
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;

  EXPECT_FALSE(rep.ok);
  EXPECT_FALSE(rep.record_after_error);
  EXPECT_FALSE(rep.close_ok);
  const std::string error = rep.error;
  EXPECT_NE(error.find(path.string()), std::string::npos) << error;
  EXPECT_NE(error.find(std::strerror(EFBIG)), std::string::npos) << error;
  EXPECT_GT(rep.written, 0u);
  EXPECT_LT(rep.written, 2000u);
  EXPECT_EQ(std::filesystem::file_size(path), kLimit);

  const McapReader r = McapReader::recover(path);
  EXPECT_FALSE(r.recovery()->complete);
  EXPECT_EQ(r.recovery()->messages, rep.written) << "every chunk written before the error";
  expect_prefix(r, rep.written, 200);
  const RecoveryReport fixed = recover_file(path, dir / "fixed.mcap");
  EXPECT_EQ(fixed.messages, rep.written);
  EXPECT_TRUE(McapReader::open(dir / "fixed.mcap").validate().empty());
}

TEST(RecorderCrash, AKilledRecorderLeavesEveryChunkItHadWritten) {
  test::TempDir dir;
  const auto path = dir / "killed.mcap";
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t pid = ::fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    ::close(fds[0]);
    RecorderOptions o{};
    o.writer.chunk_size_bytes = 4096;
    Recorder rec(path, o);
    const auto ch = rec.add_channel({0, "/t", "json", {}});
    // Bounded, in case the parent never kills: ~10^7 messages.
    for (std::uint64_t i = 0; i < 10'000'000; ++i) {
      // Never drop: the recovered messages must be an unbroken prefix.
      while (!rec.record(ch, i, payload(i, 80))) (void)rec.sync();
      if (i % 250 == 249) {
        (void)rec.sync();
        const std::uint64_t written = rec.written();
        if (::write(fds[1], &written, sizeof(written)) != sizeof(written)) ::_exit(2);
      }
    }
    ::_exit(0);
  }
  ::close(fds[1]);
  std::uint64_t reported = 0;
  while (reported < 20'000 && read_all(fds[0], &reported, sizeof(reported))) {
  }
  ASSERT_EQ(::kill(pid, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(::waitpid(pid, &status, 0), pid);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << status;
  // Reports already in the pipe were all made before the kill.
  std::uint64_t later = 0;
  while (read_all(fds[0], &later, sizeof(later))) reported = std::max(reported, later);
  ::close(fds[0]);
  ASSERT_GE(reported, 20'000u);

  const McapReader r = McapReader::recover(path);
  EXPECT_FALSE(r.recovery()->complete);
  EXPECT_GE(r.recovery()->messages, reported);
  expect_prefix(r, r.recovery()->messages, 80);
  const RecoveryReport fixed = recover_file(path, dir / "fixed.mcap");
  const McapReader f = McapReader::open(dir / "fixed.mcap");
  EXPECT_TRUE(f.validate().empty());
  EXPECT_EQ(f.statistics()->message_count, fixed.messages);
}

}  // namespace
}  // namespace teleop::record
