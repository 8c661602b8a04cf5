// The live front end of session recording: producers hand messages over without ever waiting
// for the disk; a background thread owns the McapWriter.
//
// record() takes a short mutex (held by the writer thread only to swap queues, O(1)), copies
// the bytes into the queue's buffer, and never waits for I/O: when the bounded queue is full, or
// recording has stopped on an error, the message is dropped and counted. Not for the RT thread (it
// allocates and locks): the RT thread hands plain records to a lock-free queue, and an I/O thread
// serializes and records. The writer thread wakes every wake_period even with nothing queued, so an
// open chunk is flushed by age on a quiet channel too. An I/O error (disk full, EIO) stops
// recording with error() set; the file keeps every chunk written before it, readable by
// McapReader::recover.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "common/record/mcap_writer.hpp"

namespace teleop::record {

struct RecorderOptions {
  WriterOptions writer{};
  // Bounds of the queue between producers and the writer thread.
  std::size_t queue_messages{65536};
  std::size_t queue_bytes{std::size_t{64} << 20};
  // How often the writer thread looks at the open chunk's age with nothing queued.
  std::chrono::milliseconds wake_period{20};
};

class Recorder {
 public:
  // Creates the file (throws std::runtime_error naming it when it cannot) and starts the
  // writer thread.
  explicit Recorder(const std::filesystem::path& path, RecorderOptions options = {});
  // close().
  ~Recorder();
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;

  // Thread-safe; ids as McapWriter assigns them (1, 2, ...). Throws std::invalid_argument for
  // an unknown schema id.
  std::uint16_t add_schema(SchemaDef schema);
  std::uint16_t add_channel(ChannelDef channel);

  // Thread-safe, never blocks on I/O; the bytes are copied. False when the message was
  // dropped: queue full, unknown channel, recording stopped by an error, or closed. Counted in
  // drops().
  [[nodiscard]] bool record(std::uint16_t channel_id, std::uint64_t log_time_ns,
                            std::string_view bytes);
  [[nodiscard]] bool record(std::uint16_t channel_id, std::uint64_t log_time_ns,
                            std::span<const std::byte> bytes);
  // The same with the sender's publish time (the others: publish time = log time).
  [[nodiscard]] bool record(std::uint16_t channel_id, std::uint64_t log_time_ns,
                            std::uint64_t publish_time_ns, std::string_view bytes);
  // A Metadata or Attachment record (McapWriter::write_metadata, write_attachment), written by
  // the writer thread before the messages queued after it. Thread-safe; not counted as
  // messages; lost (without a drop count) only when recording has stopped.
  void metadata(std::string name, std::map<std::string, std::string> values);
  void attachment(AttachmentDef attachment);

  // Waits until everything recorded before the call has reached the writer and the open
  // chunk's age has been checked (flush() also flushes it). For tests, shutdown paths and
  // operator requests, not producers. Returns ok().
  bool sync();
  bool flush();
  // Waits until written() >= count, recording stopped, or `timeout`; returns written() >= count.
  bool wait_written(std::uint64_t count, std::chrono::milliseconds timeout);
  // Drains the queue, writes the summary and closes the file; idempotent. Returns ok().
  bool close();

  // Messages dropped (see record()).
  [[nodiscard]] std::uint64_t drops() const { return drops_.load(std::memory_order_relaxed); }
  // Messages, and their data bytes, in chunks handed to the OS.
  [[nodiscard]] std::uint64_t written() const { return written_.load(std::memory_order_acquire); }
  [[nodiscard]] std::uint64_t bytes_written() const {
    return bytes_written_.load(std::memory_order_acquire);
  }
  // Bytes of the file handed to the OS.
  [[nodiscard]] std::uint64_t file_size() const {
    return file_size_.load(std::memory_order_acquire);
  }
  [[nodiscard]] bool ok() const { return !failed_.load(std::memory_order_acquire); }
  // "" while ok; else the writer's error, naming the file.
  [[nodiscard]] std::string error() const;

 private:
  struct Registration {
    enum class Kind { kSchema, kChannel, kMetadata, kAttachment };
    Kind kind{Kind::kSchema};
    SchemaDef schema{};
    ChannelDef channel{};
    std::string metadata_name{};
    std::map<std::string, std::string> metadata{};
    AttachmentDef attachment{};
  };

  bool enqueue(std::uint16_t channel_id, std::uint64_t log_time_ns, std::uint64_t publish_time_ns,
               std::string_view bytes);
  void register_record(Registration r);
  void apply(Registration& r);
  bool request(bool force_flush);
  void run();
  void publish_progress();

  RecorderOptions options_{};
  std::unique_ptr<McapWriter> writer_{};  // the writer thread's once started

  std::mutex close_mutex_{};  // one close() joins; others wait for it
  mutable std::mutex mutex_{};
  std::condition_variable wake_{};      // to the writer thread
  std::condition_variable progress_{};  // from it
  // Queued messages packed back to back, [channel u16][log time u64][publish time u64][size
  // u32][bytes]: the
  // writer thread swaps the whole buffer out and back, so steady state allocates nothing.
  std::string queue_{};
  std::size_t queued_messages_{0};
  std::vector<Registration> registrations_{};
  std::uint16_t schema_count_{0};
  std::uint16_t channel_count_{0};
  std::uint64_t sync_requested_{0};
  std::uint64_t sync_done_{0};
  bool force_flush_{false};
  bool stop_{false};
  bool exited_{false};
  std::string error_{};

  // queued_messages_ and queue_.size(), readable without the mutex: a full queue rejects
  // without taking it, so overloaded producers do not slow the writer thread's swaps.
  std::atomic<std::size_t> queued_messages_hint_{0};
  std::atomic<std::size_t> queued_bytes_hint_{0};
  std::atomic<std::uint16_t> channels_known_{0};
  std::atomic<bool> failed_{false};
  std::atomic<bool> closed_{false};
  std::atomic<std::uint64_t> drops_{0};
  std::atomic<std::uint64_t> written_{0};
  std::atomic<std::uint64_t> bytes_written_{0};
  std::atomic<std::uint64_t> file_size_{0};

  std::thread thread_{};
};

}  // namespace teleop::record
