// Reading session files in MCAP (mcap.dev/spec), and recovering what a crash left.
//
// open(): a file with a valid Footer; its summary (schemas, channels, statistics, chunk
// indexes) is used when present, else the records are scanned from the start. recover(): for
// a file cut short or damaged — scans from the start without the summary, keeps every
// complete chunk whose CRC checks, stops at the first truncated or corrupt record and says
// where. Uncompressed chunks only (what McapWriter writes). The file is memory-mapped;
// message data views stay valid while the reader lives.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace teleop::record {

// A file that is not MCAP, or damaged; the message names the file and the byte offset.
struct McapError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Header {
  std::string profile{};
  std::string library{};
};

struct Schema {
  std::uint16_t id{0};
  std::string name{};
  std::string encoding{};
  std::string data{};
};

struct Channel {
  std::uint16_t id{0};
  std::uint16_t schema_id{0};
  std::string topic{};
  std::string message_encoding{};
  std::map<std::string, std::string> metadata{};
};

struct Statistics {
  std::uint64_t message_count{0};
  std::uint16_t schema_count{0};
  std::uint32_t channel_count{0};
  std::uint32_t attachment_count{0};
  std::uint32_t metadata_count{0};
  std::uint32_t chunk_count{0};
  std::uint64_t message_start_time{0};
  std::uint64_t message_end_time{0};
  std::map<std::uint16_t, std::uint64_t> channel_message_counts{};
};

struct ChunkIndex {
  std::uint64_t message_start_time{0};
  std::uint64_t message_end_time{0};
  std::uint64_t chunk_start_offset{0};
  std::uint64_t chunk_length{0};
  std::map<std::uint16_t, std::uint64_t> message_index_offsets{};
  std::uint64_t message_index_length{0};
  std::string compression{};
  std::uint64_t compressed_size{0};
  std::uint64_t uncompressed_size{0};
};

struct MessageView {
  const Channel* channel{nullptr};
  const Schema* schema{nullptr};  // nullptr: the channel has no schema
  std::uint32_t sequence{0};
  std::uint64_t log_time_ns{0};
  std::uint64_t publish_time_ns{0};
  std::string_view data{};         // valid while the reader lives
  std::uint64_t record_offset{0};  // of the Chunk holding it (of the Message when outside one)
};

enum class Order {
  kLogTime,  // by log time; ties in file order
  kFile,     // as the records lie in the file
};

// What recover() kept.
// How far a pass over a file is: `done_bytes` of `total_bytes` handled, called as the pass
// goes (teleopctl's progress line on a terminal); empty: not called.
using ByteProgress = std::function<void(std::uint64_t done_bytes, std::uint64_t total_bytes)>;

struct RecoveryReport {
  std::uint64_t file_size{0};
  std::uint64_t chunks{0};    // complete chunks whose CRC checked
  std::uint64_t messages{0};  // messages in them
  // Bytes [0, data_end) held only valid, complete records; nothing after it was used.
  std::uint64_t data_end{0};
  // The Data End record was reached: the data section is whole.
  bool complete{false};
  // Why the scan stopped before Data End, naming the file and offset ("" when complete).
  std::string stopped{};
};

class McapReader {
 public:
  // Throws McapError naming the file and offset: not MCAP, no valid Footer (cut short: use
  // recover()), summary CRC mismatch, malformed summary or records.
  [[nodiscard]] static McapReader open(const std::filesystem::path& path);
  // Never throws for damaged content (see recovery()); throws McapError if the file cannot
  // be read or does not start with the MCAP magic. `scanned`: the bytes read so far of the
  // file's size, after each record.
  [[nodiscard]] static McapReader recover(const std::filesystem::path& path,
                                          const ByteProgress& scanned = {});

  McapReader(McapReader&&) noexcept;
  McapReader& operator=(McapReader&&) noexcept;
  ~McapReader();

  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  [[nodiscard]] std::uint64_t file_size() const;
  // The summary was used (else the records were scanned).
  [[nodiscard]] bool indexed() const { return indexed_; }
  [[nodiscard]] const Header& header() const { return header_; }
  [[nodiscard]] const std::map<std::uint16_t, Schema>& schemas() const { return schemas_; }
  [[nodiscard]] const std::map<std::uint16_t, Channel>& channels() const { return channels_; }
  // From the summary; a scan counts its own.
  [[nodiscard]] const std::optional<Statistics>& statistics() const { return statistics_; }
  // From the summary, or rebuilt by the scan; in file order.
  [[nodiscard]] const std::vector<ChunkIndex>& chunk_indexes() const { return chunks_; }
  // Set by recover().
  [[nodiscard]] const std::optional<RecoveryReport>& recovery() const { return recovery_; }

  // Every message, checking each chunk's CRC first; throws McapError naming the chunk's
  // offset on a mismatch or a malformed record.
  void for_each_message(Order order, const std::function<void(const MessageView&)>& fn) const;
  [[nodiscard]] std::vector<MessageView> messages(Order order = Order::kLogTime) const;

  // Checks every CRC the file carries: each chunk's uncompressed_crc, the data_section_crc
  // and the summary_crc. One line per mismatch or damaged record, naming the offset; empty
  // when all hold.
  [[nodiscard]] std::vector<std::string> validate() const;

  struct Mapping;

 private:
  // scan(), record by record (in the .cpp).
  struct Scan;

  // Maps `path`; throws McapError when it cannot, or when the file does not start with the
  // MCAP magic.
  explicit McapReader(const std::filesystem::path& path);
  void read_summary(std::uint64_t summary_start, std::uint64_t summary_end);
  void scan(bool recovering, const ByteProgress& scanned = {});

  std::filesystem::path path_{};
  std::unique_ptr<Mapping> map_{};
  std::string_view file_{};
  bool indexed_{false};
  Header header_{};
  std::map<std::uint16_t, Schema> schemas_{};
  std::map<std::uint16_t, Channel> channels_{};
  std::optional<Statistics> statistics_{};
  std::vector<ChunkIndex> chunks_{};
  // Message records outside chunks (scan only): their offsets.
  std::vector<std::uint64_t> loose_messages_{};
  std::optional<std::uint64_t> data_end_offset_{};  // of the Data End record
  std::uint32_t data_section_crc_{0};
  std::optional<std::uint64_t> footer_offset_{};
  std::uint64_t summary_start_{0};
  std::uint32_t summary_crc_{0};
  std::optional<RecoveryReport> recovery_{};
};

// Writes `out`, a complete MCAP with a summary, from what recover() keeps of `in`: its
// schemas and channels (renumbered 1, 2, ... in id order; ids stay when they were already
// contiguous) and every message of the kept chunks with its times and sequence, in file order.
// Returns the report on `in`; throws McapError / std::runtime_error naming the file on failure.
// The two passes over `in` report their progress: `scanned` the scan of recover() (bytes of
// the file's size), `written` the copy of the kept messages (the offset of the chunk being
// copied, of the data_end the scan found).
RecoveryReport recover_file(const std::filesystem::path& in, const std::filesystem::path& out,
                            const ByteProgress& scanned = {}, const ByteProgress& written = {});

}  // namespace teleop::record
