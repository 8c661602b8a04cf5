#include "common/record/recorder.hpp"

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <utility>

namespace teleop::record {

Recorder::Recorder(const std::filesystem::path& path, RecorderOptions options)
    : options_(std::move(options)), writer_(std::make_unique<McapWriter>(path, options_.writer)) {
  file_size_.store(writer_->file_size(), std::memory_order_release);
  queue_.reserve(std::min<std::size_t>(options_.queue_bytes, std::size_t{1} << 20));
  thread_ = std::thread([this] { run(); });
}

Recorder::~Recorder() { close(); }

std::uint16_t Recorder::add_schema(SchemaDef schema) {
  std::uint16_t id = 0;
  {
    const std::lock_guard lock(mutex_);
    if (schema_count_ == std::numeric_limits<std::uint16_t>::max()) {
      throw std::invalid_argument("Recorder: more than 65535 schemas");
    }
    id = ++schema_count_;
    Registration r;
    r.kind = Registration::Kind::kSchema;
    r.schema = std::move(schema);
    registrations_.push_back(std::move(r));
  }
  wake_.notify_one();
  return id;
}

std::uint16_t Recorder::add_channel(ChannelDef channel) {
  std::uint16_t id = 0;
  {
    const std::lock_guard lock(mutex_);
    if (channel_count_ == std::numeric_limits<std::uint16_t>::max()) {
      throw std::invalid_argument("Recorder: more than 65535 channels");
    }
    if (channel.schema_id > schema_count_) {
      throw std::invalid_argument("Recorder: channel '" + channel.topic +
                                  "' names unknown schema id " + std::to_string(channel.schema_id));
    }
    id = ++channel_count_;
    Registration r;
    r.kind = Registration::Kind::kChannel;
    r.channel = std::move(channel);
    registrations_.push_back(std::move(r));
    // Published after the registration is queued: a message on this id always queues after it.
    channels_known_.store(id, std::memory_order_release);
  }
  wake_.notify_one();
  return id;
}

void Recorder::metadata(std::string name, std::map<std::string, std::string> values) {
  Registration r;
  r.kind = Registration::Kind::kMetadata;
  r.metadata_name = std::move(name);
  r.metadata = std::move(values);
  register_record(std::move(r));
}

void Recorder::attachment(AttachmentDef attachment) {
  Registration r;
  r.kind = Registration::Kind::kAttachment;
  r.attachment = std::move(attachment);
  register_record(std::move(r));
}

void Recorder::register_record(Registration r) {
  {
    const std::lock_guard lock(mutex_);
    if (stop_) return;
    registrations_.push_back(std::move(r));
  }
  wake_.notify_one();
}

void Recorder::apply(Registration& r) {
  switch (r.kind) {
    case Registration::Kind::kSchema:
      (void)writer_->add_schema(std::move(r.schema));
      break;
    case Registration::Kind::kChannel:
      (void)writer_->add_channel(std::move(r.channel));
      break;
    case Registration::Kind::kMetadata:
      (void)writer_->write_metadata(r.metadata_name, r.metadata);
      break;
    case Registration::Kind::kAttachment:
      (void)writer_->write_attachment(r.attachment);
      break;
  }
}

bool Recorder::record(std::uint16_t channel_id, std::uint64_t log_time_ns, std::string_view bytes) {
  return enqueue(channel_id, log_time_ns, log_time_ns, bytes);
}

bool Recorder::record(std::uint16_t channel_id, std::uint64_t log_time_ns,
                      std::span<const std::byte> bytes) {
  return enqueue(channel_id, log_time_ns, log_time_ns,
                 std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
}

bool Recorder::record(std::uint16_t channel_id, std::uint64_t log_time_ns,
                      std::uint64_t publish_time_ns, std::string_view bytes) {
  return enqueue(channel_id, log_time_ns, publish_time_ns, bytes);
}

namespace {
constexpr std::size_t kEntryHead = 2 + 8 + 8 + 4;  // channel, log time, publish time, size
}  // namespace

bool Recorder::enqueue(std::uint16_t channel_id, std::uint64_t log_time_ns,
                       std::uint64_t publish_time_ns, std::string_view bytes) {
  if (closed_.load(std::memory_order_acquire) || failed_.load(std::memory_order_acquire) ||
      channel_id == 0 || channel_id > channels_known_.load(std::memory_order_acquire) ||
      bytes.size() > std::numeric_limits<std::uint32_t>::max()) {
    drops_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  if (queued_messages_hint_.load(std::memory_order_relaxed) >= options_.queue_messages ||
      queued_bytes_hint_.load(std::memory_order_relaxed) + kEntryHead + bytes.size() >
          options_.queue_bytes) {
    drops_.fetch_add(1, std::memory_order_relaxed);
    return false;
  }
  char head[kEntryHead];
  const auto size = static_cast<std::uint32_t>(bytes.size());
  std::memcpy(head, &channel_id, 2);
  std::memcpy(head + 2, &log_time_ns, 8);
  std::memcpy(head + 10, &publish_time_ns, 8);
  std::memcpy(head + 18, &size, 4);
  bool was_empty = false;
  {
    const std::lock_guard lock(mutex_);
    if (stop_ || queued_messages_ >= options_.queue_messages ||
        queue_.size() + kEntryHead + bytes.size() > options_.queue_bytes) {
      drops_.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    was_empty = queued_messages_ == 0;
    ++queued_messages_;
    queue_.append(head, kEntryHead);
    queue_.append(bytes);
    queued_messages_hint_.store(queued_messages_, std::memory_order_relaxed);
    queued_bytes_hint_.store(queue_.size(), std::memory_order_relaxed);
  }
  // The writer thread re-checks the queue before it sleeps: one wake per empty -> non-empty.
  if (was_empty) wake_.notify_one();
  return true;
}

bool Recorder::sync() { return request(false); }
bool Recorder::flush() { return request(true); }

bool Recorder::request(bool force_flush) {
  std::unique_lock lock(mutex_);
  if (exited_) return ok();
  const std::uint64_t target = ++sync_requested_;
  if (force_flush) force_flush_ = true;
  wake_.notify_one();
  progress_.wait(lock, [&] { return sync_done_ >= target || exited_; });
  return ok();
}

bool Recorder::wait_written(std::uint64_t count, std::chrono::milliseconds timeout) {
  std::unique_lock lock(mutex_);
  progress_.wait_for(lock, timeout, [&] {
    return written_.load(std::memory_order_acquire) >= count || exited_ ||
           failed_.load(std::memory_order_acquire);
  });
  return written_.load(std::memory_order_acquire) >= count;
}

bool Recorder::close() {
  const std::lock_guard close_lock(close_mutex_);
  if (!closed_.exchange(true, std::memory_order_acq_rel)) {
    {
      const std::lock_guard lock(mutex_);
      stop_ = true;
    }
    wake_.notify_one();
  }
  if (thread_.joinable()) thread_.join();
  return ok();
}

std::string Recorder::error() const {
  const std::lock_guard lock(mutex_);
  return error_;
}

void Recorder::publish_progress() {
  written_.store(writer_->messages_written(), std::memory_order_release);
  bytes_written_.store(writer_->message_bytes_written(), std::memory_order_release);
  file_size_.store(writer_->file_size(), std::memory_order_release);
}

void Recorder::run() {
  std::string batch;
  batch.reserve(queue_.capacity());
  std::size_t batch_messages = 0;
  std::vector<Registration> registrations;
  std::unique_lock lock(mutex_);
  while (true) {
    wake_.wait_for(lock, options_.wake_period, [&] {
      return stop_ || queued_messages_ != 0 || !registrations_.empty() ||
             sync_requested_ != sync_done_;
    });
    batch.swap(queue_);
    batch_messages = std::exchange(queued_messages_, 0);
    queued_messages_hint_.store(0, std::memory_order_relaxed);
    queued_bytes_hint_.store(0, std::memory_order_relaxed);
    registrations.swap(registrations_);
    const std::uint64_t sync_target = sync_requested_;
    const bool force = std::exchange(force_flush_, false);
    const bool stop = stop_;
    lock.unlock();

    std::string failure;
    std::uint64_t done = 0;
    try {
      for (Registration& r : registrations) apply(r);
      std::size_t pos = 0;
      while (writer_->ok() && done < batch_messages) {
        std::uint16_t channel_id = 0;
        std::uint64_t log_time_ns = 0;
        std::uint64_t publish_time_ns = 0;
        std::uint32_t size = 0;
        std::memcpy(&channel_id, batch.data() + pos, 2);
        std::memcpy(&log_time_ns, batch.data() + pos + 2, 8);
        std::memcpy(&publish_time_ns, batch.data() + pos + 10, 8);
        std::memcpy(&size, batch.data() + pos + 18, 4);
        pos += kEntryHead;
        ++done;
        if (!writer_->write(channel_id, log_time_ns, publish_time_ns,
                            std::string_view(batch).substr(pos, size))) {
          break;
        }
        pos += size;
      }
      if (writer_->ok()) (void)(force ? writer_->flush() : writer_->poll());
      if (stop) (void)writer_->close();
    } catch (const std::exception& e) {
      failure = e.what();
    }
    std::uint64_t lost = batch_messages - done;
    registrations.clear();
    batch.clear();
    publish_progress();
    if (failure.empty() && !writer_->ok()) failure = writer_->error();

    lock.lock();
    if (!failure.empty() && error_.empty()) {
      error_ = failure;
      failed_.store(true, std::memory_order_release);
    }
    if (failed_.load(std::memory_order_relaxed)) {
      // Recording has stopped: what is queued will never be written.
      lost += std::exchange(queued_messages_, 0);
      queue_.clear();
      queued_messages_hint_.store(0, std::memory_order_relaxed);
      queued_bytes_hint_.store(0, std::memory_order_relaxed);
    }
    drops_.fetch_add(lost, std::memory_order_relaxed);
    sync_done_ = sync_target;
    if (stop) exited_ = true;
    progress_.notify_all();
    if (stop) return;
  }
}

}  // namespace teleop::record
