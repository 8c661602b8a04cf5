// Session files in MCAP (mcap.dev/spec): an uncompressed, chunked, indexed writer.
//
// Layout written: magic, Header, then per chunk [Chunk][Message Index per channel], Data End,
// the summary (Schemas, Channels, Statistics, Chunk Indexes), one Summary Offset per group,
// Footer, magic. A Schema and a Channel first appear inside the chunk that first carries a
// message on them, so a file cut anywhere keeps every complete chunk readable without the
// summary. A chunk goes to the OS (one write, then optionally fdatasync) when it reaches
// chunk_size_bytes or when its oldest message is older than max_chunk_age on the injected
// clock: a crash loses at most the open chunk.
//
// Not thread-safe (the Recorder gives it a thread of its own); allocates; not for the RT path.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace teleop::record {

// The clock chunk ages are measured by; tests inject a fake one.
using Clock = std::function<std::chrono::steady_clock::time_point()>;

struct SchemaDef {
  std::string name{};      // protobuf: the message's full name
  std::string encoding{};  // "protobuf", ...; "" means no schema
  std::string data{};      // protobuf: a serialized FileDescriptorSet
};

struct ChannelDef {
  std::uint16_t schema_id{0};  // 0: no schema
  std::string topic{};
  std::string message_encoding{};  // "protobuf", ...
  std::map<std::string, std::string> metadata{};
};

// An Attachment record: a file embedded in the session (e.g. the configuration as read).
struct AttachmentDef {
  std::uint64_t log_time_ns{0};
  std::uint64_t create_time_ns{0};
  std::string name{};
  std::string media_type{};
  std::string data{};
};

struct WriterOptions {
  std::string profile{};
  std::string library{"teleop-record"};
  std::size_t chunk_size_bytes{256 * 1024};
  std::chrono::nanoseconds max_chunk_age{std::chrono::milliseconds{200}};
  // After each chunk: fdatasync, so the chunk survives a power cut, not only a crash.
  bool fdatasync{false};
  // Empty: CLOCK_MONOTONIC (steady_clock's) read coarsely, at the kernel tick.
  Clock clock{};
};

class McapWriter {
 public:
  // Creates (truncates) the file and writes magic and Header; throws std::runtime_error
  // naming the file when it cannot.
  explicit McapWriter(const std::filesystem::path& path, WriterOptions options = {});
  // Closes the file if close() was not called (errors then only latch error()).
  ~McapWriter();
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  // Ids are 1, 2, 3, ... in call order (the Recorder relies on it). Throws
  // std::invalid_argument for an unknown schema id or when 65535 ids are used up.
  std::uint16_t add_schema(SchemaDef schema);
  std::uint16_t add_channel(ChannelDef channel);

  // Appends a message to the open chunk (sequence: a per-channel counter, publish time = log
  // time) and flushes the chunk when it is full or old. False once an I/O error has stopped
  // the file (see error()). Throws std::invalid_argument for an unknown channel id.
  [[nodiscard]] bool write(std::uint16_t channel_id, std::uint64_t log_time_ns,
                           std::string_view data);
  // The same with the sender's publish time.
  [[nodiscard]] bool write(std::uint16_t channel_id, std::uint64_t log_time_ns,
                           std::uint64_t publish_time_ns, std::string_view data);
  [[nodiscard]] bool write(std::uint16_t channel_id, std::uint64_t log_time_ns,
                           std::uint64_t publish_time_ns, std::uint32_t sequence,
                           std::string_view data);
  // A Metadata record (name and key/value strings) or an Attachment record, in the data section
  // between chunks (the open chunk is flushed first), indexed in the summary (Metadata Index,
  // Attachment Index) and counted in Statistics. False once an I/O error stopped the file.
  [[nodiscard]] bool write_metadata(const std::string& name,
                                    const std::map<std::string, std::string>& values);
  [[nodiscard]] bool write_attachment(const AttachmentDef& attachment);
  // Flushes the open chunk if its oldest message is older than max_chunk_age.
  [[nodiscard]] bool poll();
  // Flushes the open chunk now.
  [[nodiscard]] bool flush();
  // Flushes, writes Data End, the summary, Footer and magic, and closes the file. Idempotent.
  [[nodiscard]] bool close();

  [[nodiscard]] bool ok() const { return error_.empty(); }
  // "" while ok; else what failed, naming the file and the offset.
  [[nodiscard]] const std::string& error() const { return error_; }
  [[nodiscard]] bool closed() const { return closed_; }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

  // Bytes handed to the OS so far (the file's size, unless a write failed part-way).
  [[nodiscard]] std::uint64_t file_size() const { return file_size_; }
  // Messages (and their data bytes) in chunks handed to the OS.
  [[nodiscard]] std::uint64_t messages_written() const { return messages_written_; }
  [[nodiscard]] std::uint64_t message_bytes_written() const { return message_bytes_written_; }
  [[nodiscard]] std::uint64_t chunks_written() const { return chunk_indexes_.size(); }
  // Messages in the open chunk, not yet in the file.
  [[nodiscard]] std::uint64_t messages_pending() const { return chunk_messages_; }

 private:
  struct SchemaState {
    SchemaDef def{};
    bool in_data{false};  // written to the data section (in a chunk)
  };
  struct ChannelState {
    ChannelDef def{};
    bool in_data{false};
    std::uint32_t next_sequence{0};
    std::uint64_t message_count{0};
    // This chunk's Message Index: (log_time, offset in the chunk's records).
    std::vector<std::pair<std::uint64_t, std::uint64_t>> index{};
    bool index_unsorted{false};
  };
  struct ChunkIndexEntry {
    std::uint64_t message_start_time{0};
    std::uint64_t message_end_time{0};
    std::uint64_t chunk_start_offset{0};
    std::uint64_t chunk_length{0};
    std::vector<std::pair<std::uint16_t, std::uint64_t>> message_index_offsets{};
    std::uint64_t message_index_length{0};
    std::uint64_t records_size{0};
  };

  [[nodiscard]] bool flush_chunk();
  [[nodiscard]] bool write_out(std::initializer_list<std::string_view> parts);
  bool fail(const std::string& what, int err);
  [[nodiscard]] std::chrono::steady_clock::time_point now() const;

  std::filesystem::path path_{};
  WriterOptions options_{};
  int fd_{-1};
  bool closed_{false};
  std::string error_{};
  std::uint64_t file_size_{0};
  std::uint32_t data_crc_{0};  // every byte handed to the OS so far

  std::vector<SchemaState> schemas_{};    // id - 1
  std::vector<ChannelState> channels_{};  // id - 1

  // The open chunk.
  std::string chunk_records_{};
  std::uint64_t chunk_start_time_{0};
  std::uint64_t chunk_end_time_{0};
  std::uint64_t chunk_messages_{0};
  std::uint64_t chunk_message_bytes_{0};
  std::optional<std::chrono::steady_clock::time_point> chunk_opened_{};
  std::vector<std::uint16_t> chunk_channels_{};
  std::string header_buffer_{};
  std::string index_buffer_{};

  struct MetadataIndexEntry {
    std::uint64_t offset{0};
    std::uint64_t length{0};
    std::string name{};
  };
  struct AttachmentIndexEntry {
    std::uint64_t offset{0};
    std::uint64_t length{0};
    std::uint64_t log_time{0};
    std::uint64_t create_time{0};
    std::uint64_t data_size{0};
    std::string name{};
    std::string media_type{};
  };
  // A record outside chunks: written after the open chunk, its CRC folded into the data CRC.
  [[nodiscard]] bool write_record(const std::string& record);
  // The summary's Attachment Index and Metadata Index records.
  void put_attachment_indexes(std::string& out) const;
  void put_metadata_indexes(std::string& out) const;

  std::vector<ChunkIndexEntry> chunk_indexes_{};
  std::vector<MetadataIndexEntry> metadata_indexes_{};
  std::vector<AttachmentIndexEntry> attachment_indexes_{};
  std::uint64_t messages_written_{0};
  std::uint64_t message_bytes_written_{0};
  std::uint64_t start_time_{0};
  std::uint64_t end_time_{0};
};

}  // namespace teleop::record
