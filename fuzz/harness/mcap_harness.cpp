// The MCAP reader (common/record/mcap_reader.hpp) on arbitrary bytes: a session file someone
// hands to `teleopctl replay`, or what a crash left on disk.
//
// The reader takes a path and memory-maps it, so the bytes go to a memfd (one per process,
// rewritten every run) opened as /proc/self/fd/N. Checked:
// - open(): succeeds or throws McapError; its messages, in file and in log-time order, are the
//   same number, the log-time order is sorted, every message has its channel (and the channel's
//   schema when it names one that exists); validate() does not throw;
// - recover(): throws McapError only without the magic (documented: never for damaged
//   content); what it kept iterates without an error, exactly recovery().messages messages, and
//   recover_file() writes a file that open() reads back with the same messages.
#include <sys/mman.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "fuzz/harness/fuzz_check.hpp"

namespace teleop::fuzz {
namespace {

using record::McapError;
using record::McapReader;
using record::MessageView;
using record::Order;

constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

// A memory file reachable by path.
class MemFile {
 public:
  explicit MemFile(const char* name) : fd_(::memfd_create(name, MFD_CLOEXEC)) {
    if (fd_ < 0) fail(__FILE__, __LINE__, "memfd_create failed");
    path_ = "/proc/self/fd/" + std::to_string(fd_);
  }
  MemFile(const MemFile&) = delete;
  MemFile& operator=(const MemFile&) = delete;
  ~MemFile() { ::close(fd_); }

  void write(const std::uint8_t* data, std::size_t size) const {
    if (::ftruncate(fd_, 0) != 0) fail(__FILE__, __LINE__, "ftruncate failed");
    std::size_t done = 0;
    while (done < size) {
      const ssize_t n = ::pwrite(fd_, data + done, size - done, static_cast<off_t>(done));
      if (n <= 0) fail(__FILE__, __LINE__, "pwrite failed");
      done += static_cast<std::size_t>(n);
    }
  }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  int fd_;
  std::filesystem::path path_{};
};

struct Key {
  std::uint16_t channel;
  std::uint32_t sequence;
  std::uint64_t log_time;
  std::string data;
  bool operator==(const Key&) const = default;
};

// All messages in `order`; checks what every view must satisfy.
std::vector<Key> collect(const McapReader& reader, Order order) {
  std::vector<Key> out;
  std::uint64_t last_time = 0;
  reader.for_each_message(order, [&](const MessageView& m) {
    TELEOP_FUZZ_CHECK(m.channel != nullptr, "a message without its channel");
    const auto ch = reader.channels().find(m.channel->id);
    TELEOP_FUZZ_CHECK(ch != reader.channels().end() && &ch->second == m.channel,
                      "a message's channel is not one of the reader's");
    if (m.schema != nullptr) {
      TELEOP_FUZZ_CHECK(m.schema->id == m.channel->schema_id, "a message with another schema");
    }
    if (order == Order::kLogTime) {
      TELEOP_FUZZ_CHECK(out.empty() || m.log_time_ns >= last_time, "log-time order not sorted");
      last_time = m.log_time_ns;
    }
    out.push_back({m.channel->id, m.sequence, m.log_time_ns, std::string(m.data)});
  });
  return out;
}

void check_open(const std::filesystem::path& path) {
  std::optional<McapReader> reader;
  try {
    reader.emplace(McapReader::open(path));
  } catch (const McapError&) {
    return;
  }
  (void)reader->validate();
  std::vector<Key> by_file;
  try {
    by_file = collect(*reader, Order::kFile);
  } catch (const McapError&) {
    // A damaged chunk: documented; the log-time pass must then fail as well.
    bool threw = false;
    try {
      (void)collect(*reader, Order::kLogTime);
    } catch (const McapError&) {
      threw = true;
    }
    TELEOP_FUZZ_CHECK(threw, "file order threw but log-time order read everything");
    return;
  }
  const std::vector<Key> by_time = collect(*reader, Order::kLogTime);
  TELEOP_FUZZ_CHECK(by_time.size() == by_file.size(), "the two orders give different messages");
}

void check_recover(const std::uint8_t* data, std::size_t size, const std::filesystem::path& path,
                   const MemFile& out) {
  const bool has_magic =
      size >= kMagic.size() && std::string_view(reinterpret_cast<const char*>(data), 8) == kMagic;
  std::optional<McapReader> reader;
  try {
    reader.emplace(McapReader::recover(path));
  } catch (const McapError& e) {
    TELEOP_FUZZ_CHECK(!has_magic, std::string("recover() threw on damaged content: ") + e.what());
    return;
  }
  TELEOP_FUZZ_CHECK(has_magic, "recover() accepted a file without the magic");
  TELEOP_FUZZ_CHECK(reader->recovery().has_value(), "recover() without a report");
  const record::RecoveryReport report = *reader->recovery();
  TELEOP_FUZZ_CHECK(report.data_end <= size && report.file_size == size, "report outside the file");
  TELEOP_FUZZ_CHECK(report.complete == report.stopped.empty(), "complete xor stopped");
  (void)reader->validate();
  std::vector<Key> kept;
  try {
    kept = collect(*reader, Order::kFile);
    TELEOP_FUZZ_CHECK(collect(*reader, Order::kLogTime).size() == kept.size(),
                      "the two orders give different messages");
  } catch (const McapError& e) {
    fail(__FILE__, __LINE__, std::string("what recover() kept does not read: ") + e.what());
  }
  TELEOP_FUZZ_CHECK(kept.size() == report.messages, "recovery().messages is not what reads");

  // recover_file(): a complete file with the same messages.
  try {
    (void)record::recover_file(path, out.path());
  } catch (const std::exception& e) {
    fail(__FILE__, __LINE__, std::string("recover_file() failed: ") + e.what());
  }
  try {
    const McapReader written = McapReader::open(out.path());
    TELEOP_FUZZ_CHECK(written.validate().empty(), "recover_file() wrote CRC errors");
    const std::vector<Key> again = collect(written, Order::kFile);
    TELEOP_FUZZ_CHECK(again.size() == kept.size(), "recover_file() changed the message count");
    for (std::size_t i = 0; i < again.size(); ++i) {
      TELEOP_FUZZ_CHECK(again[i].sequence == kept[i].sequence &&
                            again[i].log_time == kept[i].log_time && again[i].data == kept[i].data,
                        "recover_file() changed a message");
    }
  } catch (const McapError& e) {
    fail(__FILE__, __LINE__,
         std::string("recover_file() wrote a file open() refuses: ") + e.what());
  }
}

}  // namespace

int mcap(const std::uint8_t* data, std::size_t size) {
  static const MemFile in("teleop-fuzz-mcap-in");
  static const MemFile out("teleop-fuzz-mcap-out");
  in.write(data, size);
  check_open(in.path());
  check_recover(data, size, in.path(), out);
  return 0;
}

}  // namespace teleop::fuzz
