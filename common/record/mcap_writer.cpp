#include "common/record/mcap_writer.hpp"

#include <fcntl.h>
#include <sys/uio.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "common/record/mcap_format.hpp"

namespace teleop::record {

namespace {

using mcap::Op;
using mcap::put;

std::string describe(const std::filesystem::path& path) { return path.string(); }

void put_schema(std::string& out, std::uint16_t id, const SchemaDef& schema) {
  const std::size_t at = mcap::begin_record(out, Op::kSchema);
  put<std::uint16_t>(out, id);
  mcap::put_string(out, schema.name);
  mcap::put_string(out, schema.encoding);
  put<std::uint32_t>(out, mcap::length32(schema.data.size()));
  out.append(schema.data);
  mcap::end_record(out, at);
}

void put_channel(std::string& out, std::uint16_t id, const ChannelDef& channel) {
  const std::size_t at = mcap::begin_record(out, Op::kChannel);
  put<std::uint16_t>(out, id);
  put<std::uint16_t>(out, channel.schema_id);
  mcap::put_string(out, channel.topic);
  mcap::put_string(out, channel.message_encoding);
  mcap::put_string_map(out, channel.metadata);
  mcap::end_record(out, at);
}

}  // namespace

McapWriter::McapWriter(const std::filesystem::path& path, WriterOptions options)
    : path_(path), options_(std::move(options)) {
  fd_ = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    throw std::runtime_error(describe(path_) + ": cannot create: " + std::strerror(errno));
  }
  std::string head{mcap::kMagic};
  const std::size_t at = mcap::begin_record(head, Op::kHeader);
  mcap::put_string(head, options_.profile);
  mcap::put_string(head, options_.library);
  mcap::end_record(head, at);
  if (!write_out({head})) {
    const std::string what = error_;
    ::close(fd_);
    fd_ = -1;
    throw std::runtime_error(what);
  }
  data_crc_ = mcap::crc32(0, head);
  chunk_records_.reserve(options_.chunk_size_bytes + options_.chunk_size_bytes / 8);
}

McapWriter::~McapWriter() {
  if (!closed_) (void)close();
  if (fd_ >= 0) ::close(fd_);
}

std::uint16_t McapWriter::add_schema(SchemaDef schema) {
  if (schemas_.size() >= std::numeric_limits<std::uint16_t>::max()) {
    throw std::invalid_argument(describe(path_) + ": more than 65535 schemas");
  }
  schemas_.push_back(SchemaState{std::move(schema), false});
  return static_cast<std::uint16_t>(schemas_.size());
}

std::uint16_t McapWriter::add_channel(ChannelDef channel) {
  if (channels_.size() >= std::numeric_limits<std::uint16_t>::max()) {
    throw std::invalid_argument(describe(path_) + ": more than 65535 channels");
  }
  if (channel.schema_id > schemas_.size()) {
    throw std::invalid_argument(describe(path_) + ": channel '" + channel.topic +
                                "' names unknown schema id " + std::to_string(channel.schema_id));
  }
  ChannelState state{};
  state.def = std::move(channel);
  channels_.push_back(std::move(state));
  return static_cast<std::uint16_t>(channels_.size());
}

bool McapWriter::write(std::uint16_t channel_id, std::uint64_t log_time_ns, std::string_view data) {
  if (channel_id == 0 || channel_id > channels_.size()) {
    throw std::invalid_argument(describe(path_) + ": unknown channel id " +
                                std::to_string(channel_id));
  }
  const std::uint32_t sequence = channels_[channel_id - 1u].next_sequence;
  return write(channel_id, log_time_ns, log_time_ns, sequence, data);
}

bool McapWriter::write(std::uint16_t channel_id, std::uint64_t log_time_ns,
                       std::uint64_t publish_time_ns, std::string_view data) {
  if (channel_id == 0 || channel_id > channels_.size()) {
    throw std::invalid_argument(describe(path_) + ": unknown channel id " +
                                std::to_string(channel_id));
  }
  const std::uint32_t sequence = channels_[channel_id - 1u].next_sequence;
  return write(channel_id, log_time_ns, publish_time_ns, sequence, data);
}

bool McapWriter::write_record(const std::string& record) {
  if (closed_) throw std::logic_error(describe(path_) + ": write after close");
  if (!ok() || !flush_chunk()) return false;
  const std::uint32_t crc_before = data_crc_;
  if (!write_out({record})) return false;
  data_crc_ = mcap::crc32(crc_before, record);
  return true;
}

bool McapWriter::write_metadata(const std::string& name,
                                const std::map<std::string, std::string>& values) {
  std::string record;
  const std::size_t at = mcap::begin_record(record, Op::kMetadata);
  mcap::put_string(record, name);
  mcap::put_string_map(record, values);
  mcap::end_record(record, at);
  if (!ok() || !flush_chunk()) return false;
  const std::uint64_t offset = file_size_;
  if (!write_record(record)) return false;
  metadata_indexes_.push_back({offset, record.size(), name});
  return true;
}

bool McapWriter::write_attachment(const AttachmentDef& a) {
  std::string record;
  const std::size_t at = mcap::begin_record(record, Op::kAttachment);
  put<std::uint64_t>(record, a.log_time_ns);
  put<std::uint64_t>(record, a.create_time_ns);
  mcap::put_string(record, a.name);
  mcap::put_string(record, a.media_type);
  put<std::uint64_t>(record, a.data.size());
  record.append(a.data);
  // The CRC covers every field before it: from log_time to the end of data.
  const std::uint32_t crc = mcap::crc32(0, std::string_view{record}.substr(at + 8));
  put<std::uint32_t>(record, crc);
  mcap::end_record(record, at);
  if (!ok() || !flush_chunk()) return false;
  const std::uint64_t offset = file_size_;
  if (!write_record(record)) return false;
  attachment_indexes_.push_back({offset, record.size(), a.log_time_ns, a.create_time_ns,
                                 a.data.size(), a.name, a.media_type});
  return true;
}

bool McapWriter::write(std::uint16_t channel_id, std::uint64_t log_time_ns,
                       std::uint64_t publish_time_ns, std::uint32_t sequence,
                       std::string_view data) {
  if (closed_) throw std::logic_error(describe(path_) + ": write after close");
  if (channel_id == 0 || channel_id > channels_.size()) {
    throw std::invalid_argument(describe(path_) + ": unknown channel id " +
                                std::to_string(channel_id));
  }
  if (!ok()) return false;
  ChannelState& channel = channels_[channel_id - 1u];
  if (!channel.in_data) {
    // First message on this channel in the file: its schema and channel go first, inside
    // this chunk, so the chunk decodes without the summary.
    const std::uint16_t schema_id = channel.def.schema_id;
    if (schema_id != 0 && !schemas_[schema_id - 1u].in_data) {
      put_schema(chunk_records_, schema_id, schemas_[schema_id - 1u].def);
      schemas_[schema_id - 1u].in_data = true;
    }
    put_channel(chunk_records_, channel_id, channel.def);
    channel.in_data = true;
  }
  if (channel.index.empty()) chunk_channels_.push_back(channel_id);
  if (!channel.index.empty() && log_time_ns < channel.index.back().first) {
    channel.index_unsorted = true;
  }
  channel.index.emplace_back(log_time_ns, chunk_records_.size());

  // The Message head in one append: this is the per-message path.
  char head[mcap::kRecordPrefix + mcap::kMessageFixed];
  head[0] = static_cast<char>(Op::kMessage);
  const std::uint64_t length = mcap::kMessageFixed + data.size();
  std::memcpy(head + 1, &length, 8);
  std::memcpy(head + 9, &channel_id, 2);
  std::memcpy(head + 11, &sequence, 4);
  std::memcpy(head + 15, &log_time_ns, 8);
  std::memcpy(head + 23, &publish_time_ns, 8);
  chunk_records_.append(head, sizeof(head));
  chunk_records_.append(data);

  channel.next_sequence = sequence + 1u;
  ++channel.message_count;
  if (chunk_messages_ == 0) {
    chunk_start_time_ = log_time_ns;
    chunk_end_time_ = log_time_ns;
    chunk_opened_ = now();
  } else {
    chunk_start_time_ = std::min(chunk_start_time_, log_time_ns);
    chunk_end_time_ = std::max(chunk_end_time_, log_time_ns);
  }
  ++chunk_messages_;
  chunk_message_bytes_ += data.size();

  if (chunk_records_.size() >= options_.chunk_size_bytes) return flush_chunk();
  return poll();
}

bool McapWriter::poll() {
  if (!ok()) return false;
  if (chunk_opened_ && now() - *chunk_opened_ >= options_.max_chunk_age) return flush_chunk();
  return true;
}

bool McapWriter::flush() {
  if (!ok()) return false;
  return flush_chunk();
}

bool McapWriter::flush_chunk() {
  if (chunk_records_.empty()) return true;
  const std::uint64_t chunk_offset = file_size_;
  const std::uint32_t records_crc = mcap::crc32(0, chunk_records_);

  std::string& head = header_buffer_;
  head.clear();
  const std::size_t at = mcap::begin_record(head, Op::kChunk);
  put<std::uint64_t>(head, chunk_messages_ > 0 ? chunk_start_time_ : 0);
  put<std::uint64_t>(head, chunk_messages_ > 0 ? chunk_end_time_ : 0);
  put<std::uint64_t>(head, chunk_records_.size());  // uncompressed_size
  put<std::uint32_t>(head, records_crc);            // uncompressed_crc
  mcap::put_string(head, "");                       // compression: none
  put<std::uint64_t>(head, chunk_records_.size());  // records, uint64 length-prefixed
  // The length covers the records that follow the header.
  const std::uint64_t content = head.size() - at - 8 + chunk_records_.size();
  std::memcpy(head.data() + at, &content, sizeof(content));

  ChunkIndexEntry entry{};
  entry.message_start_time = chunk_messages_ > 0 ? chunk_start_time_ : 0;
  entry.message_end_time = chunk_messages_ > 0 ? chunk_end_time_ : 0;
  entry.chunk_start_offset = chunk_offset;
  entry.chunk_length = head.size() + chunk_records_.size();
  entry.records_size = chunk_records_.size();

  std::sort(chunk_channels_.begin(), chunk_channels_.end());
  std::string& indexes = index_buffer_;
  indexes.clear();
  for (const std::uint16_t id : chunk_channels_) {
    ChannelState& channel = channels_[id - 1u];
    if (channel.index_unsorted) {
      std::stable_sort(channel.index.begin(), channel.index.end(),
                       [](const auto& a, const auto& b) { return a.first < b.first; });
    }
    entry.message_index_offsets.emplace_back(id,
                                             chunk_offset + entry.chunk_length + indexes.size());
    const std::size_t index_at = mcap::begin_record(indexes, Op::kMessageIndex);
    put<std::uint16_t>(indexes, id);
    put<std::uint32_t>(indexes, mcap::length32(channel.index.size() * 16));
    for (const auto& [time, offset] : channel.index) {
      put<std::uint64_t>(indexes, time);
      put<std::uint64_t>(indexes, offset);
    }
    mcap::end_record(indexes, index_at);
    channel.index.clear();
    channel.index_unsorted = false;
  }
  entry.message_index_length = indexes.size();

  // The data-section CRC continues over header, records and indexes; the records' CRC is
  // already known, so they are not read a second time.
  const std::uint32_t crc_before = data_crc_;
  if (!write_out({head, chunk_records_, indexes})) return false;
  std::uint32_t crc = mcap::crc32(crc_before, head);
  crc = mcap::crc32_combine(crc, records_crc, chunk_records_.size());
  data_crc_ = mcap::crc32(crc, indexes);

  if (chunk_messages_ > 0) {
    if (messages_written_ == 0) {
      start_time_ = chunk_start_time_;
      end_time_ = chunk_end_time_;
    } else {
      start_time_ = std::min(start_time_, chunk_start_time_);
      end_time_ = std::max(end_time_, chunk_end_time_);
    }
  }
  messages_written_ += chunk_messages_;
  message_bytes_written_ += chunk_message_bytes_;
  chunk_indexes_.push_back(std::move(entry));

  chunk_records_.clear();
  chunk_channels_.clear();
  chunk_messages_ = 0;
  chunk_message_bytes_ = 0;
  chunk_opened_.reset();

  if (options_.fdatasync && ::fdatasync(fd_) != 0) {
    return fail("fdatasync after the chunk at offset " + std::to_string(chunk_offset), errno);
  }
  return true;
}

bool McapWriter::close() {
  if (closed_) return ok();
  closed_ = true;
  if (!ok() || !flush_chunk()) return false;

  std::string tail;
  // Data End: the CRC of every byte before it.
  const std::size_t data_end_at = mcap::begin_record(tail, Op::kDataEnd);
  put<std::uint32_t>(tail, data_crc_);
  mcap::end_record(tail, data_end_at);

  const std::uint64_t summary_start = file_size_ + tail.size();
  const std::size_t summary_begin = tail.size();
  struct Group {
    Op op;
    std::uint64_t start;
    std::uint64_t length;
  };
  std::vector<Group> groups;
  const auto group = [&](Op op, const auto& write_records) {
    const std::size_t begin = tail.size();
    write_records();
    if (tail.size() > begin) {
      groups.push_back({op, file_size_ + begin, tail.size() - begin});
    }
  };
  group(Op::kSchema, [&] {
    for (std::size_t i = 0; i < schemas_.size(); ++i) {
      put_schema(tail, static_cast<std::uint16_t>(i + 1), schemas_[i].def);
    }
  });
  group(Op::kChannel, [&] {
    for (std::size_t i = 0; i < channels_.size(); ++i) {
      put_channel(tail, static_cast<std::uint16_t>(i + 1), channels_[i].def);
    }
  });
  group(Op::kStatistics, [&] {
    const std::size_t at = mcap::begin_record(tail, Op::kStatistics);
    put<std::uint64_t>(tail, messages_written_);
    put<std::uint16_t>(tail, static_cast<std::uint16_t>(schemas_.size()));
    put<std::uint32_t>(tail, static_cast<std::uint32_t>(channels_.size()));
    put<std::uint32_t>(tail, static_cast<std::uint32_t>(attachment_indexes_.size()));
    put<std::uint32_t>(tail, static_cast<std::uint32_t>(metadata_indexes_.size()));
    put<std::uint32_t>(tail, static_cast<std::uint32_t>(chunk_indexes_.size()));
    put<std::uint64_t>(tail, start_time_);
    put<std::uint64_t>(tail, end_time_);
    put<std::uint32_t>(tail, mcap::length32(channels_.size() * 10));
    for (std::size_t i = 0; i < channels_.size(); ++i) {
      put<std::uint16_t>(tail, static_cast<std::uint16_t>(i + 1));
      put<std::uint64_t>(tail, channels_[i].message_count);
    }
    mcap::end_record(tail, at);
  });
  group(Op::kChunkIndex, [&] {
    for (const ChunkIndexEntry& c : chunk_indexes_) {
      const std::size_t at = mcap::begin_record(tail, Op::kChunkIndex);
      put<std::uint64_t>(tail, c.message_start_time);
      put<std::uint64_t>(tail, c.message_end_time);
      put<std::uint64_t>(tail, c.chunk_start_offset);
      put<std::uint64_t>(tail, c.chunk_length);
      put<std::uint32_t>(tail, mcap::length32(c.message_index_offsets.size() * 10));
      for (const auto& [id, offset] : c.message_index_offsets) {
        put<std::uint16_t>(tail, id);
        put<std::uint64_t>(tail, offset);
      }
      put<std::uint64_t>(tail, c.message_index_length);
      mcap::put_string(tail, "");
      put<std::uint64_t>(tail, c.records_size);  // compressed_size
      put<std::uint64_t>(tail, c.records_size);  // uncompressed_size
      mcap::end_record(tail, at);
    }
  });

  group(Op::kAttachmentIndex, [&] { put_attachment_indexes(tail); });
  group(Op::kMetadataIndex, [&] { put_metadata_indexes(tail); });

  const std::uint64_t summary_offset_start = file_size_ + tail.size();
  for (const Group& g : groups) {
    const std::size_t at = mcap::begin_record(tail, Op::kSummaryOffset);
    put<std::uint8_t>(tail, static_cast<std::uint8_t>(g.op));
    put<std::uint64_t>(tail, g.start);
    put<std::uint64_t>(tail, g.length);
    mcap::end_record(tail, at);
  }

  // The Footer's length is written up front: the summary CRC covers it.
  tail.push_back(static_cast<char>(Op::kFooter));
  put<std::uint64_t>(tail, mcap::kFooterContent);
  put<std::uint64_t>(tail, summary_start);
  put<std::uint64_t>(tail, summary_offset_start);
  // From the first summary record through summary_offset_start in this Footer.
  const std::uint32_t summary_crc = mcap::crc32(0, std::string_view{tail}.substr(summary_begin));
  put<std::uint32_t>(tail, summary_crc);
  tail.append(mcap::kMagic);

  if (!write_out({tail})) return false;
  if (options_.fdatasync && ::fdatasync(fd_) != 0) return fail("fdatasync at close", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) return fail("close", errno);
  return true;
}

void McapWriter::put_attachment_indexes(std::string& out) const {
  for (const AttachmentIndexEntry& a : attachment_indexes_) {
    const std::size_t at = mcap::begin_record(out, Op::kAttachmentIndex);
    put<std::uint64_t>(out, a.offset);
    put<std::uint64_t>(out, a.length);
    put<std::uint64_t>(out, a.log_time);
    put<std::uint64_t>(out, a.create_time);
    put<std::uint64_t>(out, a.data_size);
    mcap::put_string(out, a.name);
    mcap::put_string(out, a.media_type);
    mcap::end_record(out, at);
  }
}

void McapWriter::put_metadata_indexes(std::string& out) const {
  for (const MetadataIndexEntry& m : metadata_indexes_) {
    const std::size_t at = mcap::begin_record(out, Op::kMetadataIndex);
    put<std::uint64_t>(out, m.offset);
    put<std::uint64_t>(out, m.length);
    mcap::put_string(out, m.name);
    mcap::end_record(out, at);
  }
}

bool McapWriter::write_out(std::initializer_list<std::string_view> parts) {
  std::array<iovec, 4> iov{};
  std::size_t count = 0;
  for (const std::string_view part : parts) {
    if (part.empty()) continue;
    // writev takes non-const bases; it only reads them.
    iov[count++] = iovec{const_cast<char*>(part.data()), part.size()};
  }
  std::size_t first = 0;
  while (first < count) {
    const ssize_t n = ::writev(fd_, iov.data() + first, static_cast<int>(count - first));
    if (n < 0) {
      if (errno == EINTR) continue;
      return fail("write at offset " + std::to_string(file_size_), errno);
    }
    if (n == 0) return fail("write at offset " + std::to_string(file_size_) + " wrote nothing", 0);
    auto left = static_cast<std::size_t>(n);
    file_size_ += left;
    while (first < count && left >= iov[first].iov_len) {
      left -= iov[first].iov_len;
      ++first;
    }
    if (first < count) {
      iov[first].iov_base = static_cast<char*>(iov[first].iov_base) + left;
      iov[first].iov_len -= left;
    }
  }
  return true;
}

bool McapWriter::fail(const std::string& what, int err) {
  if (error_.empty()) {
    error_ =
        describe(path_) + ": " + what + (err != 0 ? std::string(": ") + std::strerror(err) : "");
  }
  return false;
}

std::chrono::steady_clock::time_point McapWriter::now() const {
  if (options_.clock) return options_.clock();
  // steady_clock's own CLOCK_MONOTONIC at tick resolution (a few ms, ample for a 200 ms age):
  // read on every write, and the precise clock costs as much as the rest of the write.
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC_COARSE, &ts);
  return std::chrono::steady_clock::time_point{std::chrono::seconds{ts.tv_sec} +
                                               std::chrono::nanoseconds{ts.tv_nsec}};
}

}  // namespace teleop::record
