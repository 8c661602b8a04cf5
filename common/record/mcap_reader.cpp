#include "common/record/mcap_reader.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <limits>
#include <queue>
#include <tuple>

#include "common/record/mcap_format.hpp"
#include "common/record/mcap_writer.hpp"

namespace teleop::record {

using mcap::Cursor;
using mcap::Op;
using mcap::Truncated;

struct McapReader::Mapping {
  int fd{-1};
  void* addr{nullptr};
  std::size_t size{0};
  Mapping() = default;
  Mapping(const Mapping&) = delete;
  Mapping& operator=(const Mapping&) = delete;
  ~Mapping() {
    if (addr != nullptr) ::munmap(addr, size);
    if (fd >= 0) ::close(fd);
  }
};

namespace {

std::string hex32(std::uint32_t v) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "0x%08x", v);
  return buf;
}

std::string op_name(std::uint8_t op) {
  static constexpr const char* kNames[] = {
      "invalid opcode 0", "Header",        "Footer",          "Schema",
      "Channel",          "Message",       "Chunk",           "MessageIndex",
      "ChunkIndex",       "Attachment",    "AttachmentIndex", "Statistics",
      "Metadata",         "MetadataIndex", "SummaryOffset",   "DataEnd"};
  if (op < std::size(kNames)) return kNames[op];
  return "opcode " + hex32(op);
}

[[noreturn]] void bad(const std::filesystem::path& path, std::uint64_t offset,
                      const std::string& what) {
  throw McapError(path.string() + ": offset " + std::to_string(offset) + ": " + what);
}

std::unique_ptr<McapReader::Mapping> map_file(const std::filesystem::path& path) {
  auto m = std::make_unique<McapReader::Mapping>();
  m->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (m->fd < 0) throw McapError(path.string() + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(m->fd, &st) != 0) {
    throw McapError(path.string() + ": cannot stat: " + std::strerror(errno));
  }
  m->size = static_cast<std::size_t>(st.st_size);
  if (m->size > 0) {
    void* addr = ::mmap(nullptr, m->size, PROT_READ, MAP_PRIVATE, m->fd, 0);
    if (addr == MAP_FAILED) {
      throw McapError(path.string() + ": cannot map: " + std::strerror(errno));
    }
    m->addr = addr;
  }
  return m;
}

// One record's frame, checked against the bytes available.
struct Frame {
  std::uint8_t op{0};
  std::uint64_t offset{0};  // of the opcode
  std::string_view content{};
  [[nodiscard]] std::uint64_t end() const { return offset + mcap::kRecordPrefix + content.size(); }
};

// The record at `pos` of `bytes` (which start at file offset `base`); throws Truncated.
Frame frame_at(std::string_view bytes, std::size_t pos, std::uint64_t base) {
  if (pos >= bytes.size()) throw Truncated("no record at the end of the bytes", base + pos);
  Cursor c(bytes.substr(pos), base + pos);
  Frame f{};
  f.offset = base + pos;
  try {
    f.op = c.get<std::uint8_t>();
    const auto length = c.get<std::uint64_t>();
    f.content = c.bytes(length);
  } catch (const Truncated& t) {
    throw Truncated(
        op_name(static_cast<std::uint8_t>(bytes[pos])) + " record cut short (" + t.what() + ")",
        base + pos);
  }
  return f;
}

Schema parse_schema(const Frame& f) {
  Cursor c(f.content, f.offset + mcap::kRecordPrefix);
  Schema s{};
  s.id = c.get<std::uint16_t>();
  s.name = std::string{c.string()};
  s.encoding = std::string{c.string()};
  s.data = std::string{c.bytes(c.get<std::uint32_t>())};
  return s;
}

Channel parse_channel(const Frame& f) {
  Cursor c(f.content, f.offset + mcap::kRecordPrefix);
  Channel ch{};
  ch.id = c.get<std::uint16_t>();
  ch.schema_id = c.get<std::uint16_t>();
  ch.topic = std::string{c.string()};
  ch.message_encoding = std::string{c.string()};
  ch.metadata = c.string_map();
  return ch;
}

struct RawMessage {
  std::uint16_t channel_id{0};
  std::uint32_t sequence{0};
  std::uint64_t log_time{0};
  std::uint64_t publish_time{0};
  std::string_view data{};
};

RawMessage parse_message(const Frame& f) {
  Cursor c(f.content, f.offset + mcap::kRecordPrefix);
  RawMessage m{};
  m.channel_id = c.get<std::uint16_t>();
  m.sequence = c.get<std::uint32_t>();
  m.log_time = c.get<std::uint64_t>();
  m.publish_time = c.get<std::uint64_t>();
  m.data = c.bytes(c.remaining());
  return m;
}

struct ChunkView {
  std::uint64_t start{0};
  std::uint64_t end{0};
  std::uint64_t uncompressed_size{0};
  std::uint32_t crc{0};
  std::string_view compression{};
  std::string_view records{};
  std::uint64_t records_offset{0};
};

// Parses a Chunk and checks what makes its records usable: no compression, sizes, CRC.
ChunkView parse_chunk(const std::filesystem::path& path, const Frame& f) {
  Cursor c(f.content, f.offset + mcap::kRecordPrefix);
  ChunkView v{};
  v.start = c.get<std::uint64_t>();
  v.end = c.get<std::uint64_t>();
  v.uncompressed_size = c.get<std::uint64_t>();
  v.crc = c.get<std::uint32_t>();
  v.compression = c.string();
  const auto size = c.get<std::uint64_t>();
  v.records_offset = c.offset();
  v.records = c.bytes(size);
  if (!v.compression.empty()) {
    bad(path, f.offset,
        "chunk compressed with '" + std::string{v.compression} + "', which is not supported");
  }
  if (v.uncompressed_size != v.records.size()) {
    bad(path, f.offset,
        "chunk uncompressed_size " + std::to_string(v.uncompressed_size) + " but " +
            std::to_string(v.records.size()) + " bytes of records");
  }
  if (v.crc != 0) {
    const std::uint32_t computed = mcap::crc32(0, v.records);
    if (computed != v.crc) {
      bad(path, f.offset,
          "chunk CRC mismatch (stored " + hex32(v.crc) + ", computed " + hex32(computed) + ")");
    }
  }
  return v;
}

// The Chunk record a Chunk Index points at (file offset `at`), checked as parse_chunk does.
ChunkView indexed_chunk(const std::filesystem::path& path, std::string_view file,
                        std::uint64_t at) {
  const Frame f = frame_at(file, static_cast<std::size_t>(at), 0);
  if (f.op != static_cast<std::uint8_t>(Op::kChunk)) {
    bad(path, f.offset, "Chunk Index points at " + op_name(f.op) + ", not a Chunk");
  }
  return parse_chunk(path, f);
}

void parse_header(const Frame& f, Header& h) {
  Cursor c(f.content, f.offset + mcap::kRecordPrefix);
  h.profile = std::string{c.string()};
  h.library = std::string{c.string()};
}

// The schemas, channels and message times of data records (one record, or a chunk's), each
// checked against the definitions before it; they count once all of them are good.
struct DataRecords {
  std::map<std::uint16_t, Schema> schemas;
  std::map<std::uint16_t, Channel> channels;
  std::vector<std::pair<std::uint16_t, std::uint64_t>> times;  // (channel, log time) a Message
};

// Adds a Schema, Channel or Message record to `into` (other records are not data); throws
// McapError for a channel or message naming what is not defined before it (in `schemas` and
// `channels`, or earlier in `into`).
void read_data_record(const std::filesystem::path& path, const Frame& f,
                      const std::map<std::uint16_t, Schema>& schemas,
                      const std::map<std::uint16_t, Channel>& channels, DataRecords& into) {
  switch (static_cast<Op>(f.op)) {
    case Op::kSchema: {
      Schema s = parse_schema(f);
      if (s.id != 0) into.schemas[s.id] = std::move(s);
      break;
    }
    case Op::kChannel: {
      Channel ch = parse_channel(f);
      if (ch.schema_id != 0 && !schemas.contains(ch.schema_id) &&
          !into.schemas.contains(ch.schema_id)) {
        bad(path, f.offset,
            "Channel " + std::to_string(ch.id) + " names schema " + std::to_string(ch.schema_id) +
                ", not defined before it");
      }
      into.channels[ch.id] = std::move(ch);
      break;
    }
    case Op::kMessage: {
      const RawMessage m = parse_message(f);
      if (!channels.contains(m.channel_id) && !into.channels.contains(m.channel_id)) {
        bad(path, f.offset,
            "Message on channel " + std::to_string(m.channel_id) + ", not defined before it");
      }
      into.times.emplace_back(m.channel_id, m.log_time);
      break;
    }
    default:
      break;
  }
}

void count_message(Statistics& stats, std::uint16_t channel, std::uint64_t time) {
  stats.message_start_time =
      stats.message_count == 0 ? time : std::min(stats.message_start_time, time);
  stats.message_end_time = std::max(stats.message_end_time, time);
  ++stats.message_count;
  ++stats.channel_message_counts[channel];
}

// The index of a chunk the scan read whole: the times the chunk holds, not the ones its header
// claims (a header whose start lies after its messages would otherwise put them out of
// log-time order).
ChunkIndex index_of_chunk(const Frame& f, const ChunkView& v,
                          const std::vector<std::pair<std::uint16_t, std::uint64_t>>& times) {
  ChunkIndex ci{};
  ci.message_start_time = v.start;
  ci.message_end_time = v.end;
  if (!times.empty()) {
    ci.message_start_time = times.front().second;
    ci.message_end_time = times.front().second;
    for (const auto& [channel, time] : times) {
      ci.message_start_time = std::min(ci.message_start_time, time);
      ci.message_end_time = std::max(ci.message_end_time, time);
    }
  }
  ci.chunk_start_offset = f.offset;
  ci.chunk_length = f.end() - f.offset;
  ci.compressed_size = v.records.size();
  ci.uncompressed_size = v.records.size();
  return ci;
}

// Calls fn(frame) for each record in `bytes`; throws Truncated on a record cut short.
template <typename Fn>
void for_each_record(std::string_view bytes, std::uint64_t base, Fn&& fn) {
  std::size_t pos = 0;
  while (pos < bytes.size()) {
    const Frame f = frame_at(bytes, pos, base);
    fn(f);
    pos += mcap::kRecordPrefix + f.content.size();
  }
}

}  // namespace

McapReader::McapReader(McapReader&&) noexcept = default;
McapReader& McapReader::operator=(McapReader&&) noexcept = default;
McapReader::~McapReader() = default;

std::uint64_t McapReader::file_size() const { return file_.size(); }

McapReader::McapReader(const std::filesystem::path& path)
    : path_(path), map_(map_file(path)), file_(static_cast<const char*>(map_->addr), map_->size) {
  if (file_.size() < mcap::kMagic.size() || file_.substr(0, mcap::kMagic.size()) != mcap::kMagic) {
    bad(path, 0, "not an MCAP file (no magic)");
  }
}

McapReader McapReader::open(const std::filesystem::path& path) {
  McapReader r(path);
  const std::string_view file = r.file_;
  const std::size_t minimum = 2 * mcap::kMagic.size() + mcap::kFooterRecord;
  if (file.size() < minimum || file.substr(file.size() - mcap::kMagic.size()) != mcap::kMagic) {
    bad(path, file.size(),
        "no closing magic: the file was cut short or is still being written "
        "(McapReader::recover reads what it holds)");
  }
  const std::uint64_t footer_at = file.size() - mcap::kMagic.size() - mcap::kFooterRecord;
  Cursor footer(file.substr(footer_at, mcap::kFooterRecord), footer_at);
  if (footer.get<std::uint8_t>() != static_cast<std::uint8_t>(Op::kFooter) ||
      footer.get<std::uint64_t>() != mcap::kFooterContent) {
    bad(path, footer_at, "no Footer record before the closing magic");
  }
  r.footer_offset_ = footer_at;
  const auto summary_start = footer.get<std::uint64_t>();
  const auto summary_offset_start = footer.get<std::uint64_t>();
  r.summary_start_ = summary_start;
  r.summary_crc_ = footer.get<std::uint32_t>();

  try {
    const Frame head = frame_at(file, mcap::kMagic.size(), 0);
    if (head.op != static_cast<std::uint8_t>(Op::kHeader)) {
      bad(path, head.offset, "first record is " + op_name(head.op) + ", not Header");
    }
    parse_header(head, r.header_);
  } catch (const Truncated& t) {
    bad(path, t.offset, std::string("Header: ") + t.what());
  }

  if (summary_start == 0) {
    r.scan(false);
    return r;
  }
  if (summary_start > footer_at ||
      (summary_offset_start != 0 &&
       (summary_offset_start < summary_start || summary_offset_start > footer_at))) {
    bad(path, footer_at,
        "Footer points outside the file (summary_start " + std::to_string(summary_start) +
            ", summary_offset_start " + std::to_string(summary_offset_start) + ")");
  }
  if (r.summary_crc_ != 0) {
    const std::uint64_t crc_end = footer_at + mcap::kRecordPrefix + 16;
    const std::uint32_t computed =
        mcap::crc32(0, file.substr(summary_start, crc_end - summary_start));
    if (computed != r.summary_crc_) {
      bad(path, summary_start,
          "summary CRC mismatch (stored " + hex32(r.summary_crc_) + ", computed " +
              hex32(computed) + "); McapReader::recover reads the data section without it");
    }
  }
  r.read_summary(summary_start, summary_offset_start != 0 ? summary_offset_start : footer_at);
  // Data End sits just before the summary when it has the spec's 4-byte content.
  if (summary_start >= mcap::kRecordPrefix + 4) {
    const std::uint64_t at = summary_start - mcap::kRecordPrefix - 4;
    Cursor c(file.substr(at, mcap::kRecordPrefix + 4), at);
    if (c.get<std::uint8_t>() == static_cast<std::uint8_t>(Op::kDataEnd) &&
        c.get<std::uint64_t>() == 4) {
      r.data_end_offset_ = at;
      r.data_section_crc_ = c.get<std::uint32_t>();
    }
  }
  if (r.chunks_.empty() && (!r.statistics_ || r.statistics_->message_count > 0)) {
    // A summary without chunk indexes cannot find the messages: scan for them, keeping
    // the summary's statistics.
    auto statistics = r.statistics_;
    r.scan(false);
    if (statistics) r.statistics_ = statistics;
    return r;
  }
  r.indexed_ = true;
  return r;
}

void McapReader::read_summary(std::uint64_t summary_start, std::uint64_t summary_end) {
  try {
    for_each_record(file_.substr(summary_start, summary_end - summary_start), summary_start,
                    [&](const Frame& f) {
                      Cursor c(f.content, f.offset + mcap::kRecordPrefix);
                      switch (static_cast<Op>(f.op)) {
                        case Op::kSchema: {
                          Schema s = parse_schema(f);
                          if (s.id != 0) schemas_[s.id] = std::move(s);
                          break;
                        }
                        case Op::kChannel: {
                          Channel ch = parse_channel(f);
                          channels_[ch.id] = std::move(ch);
                          break;
                        }
                        case Op::kStatistics: {
                          Statistics s{};
                          s.message_count = c.get<std::uint64_t>();
                          s.schema_count = c.get<std::uint16_t>();
                          s.channel_count = c.get<std::uint32_t>();
                          s.attachment_count = c.get<std::uint32_t>();
                          s.metadata_count = c.get<std::uint32_t>();
                          s.chunk_count = c.get<std::uint32_t>();
                          s.message_start_time = c.get<std::uint64_t>();
                          s.message_end_time = c.get<std::uint64_t>();
                          s.channel_message_counts = c.int_map<std::uint16_t, std::uint64_t>();
                          statistics_ = std::move(s);
                          break;
                        }
                        case Op::kChunkIndex: {
                          ChunkIndex ci{};
                          ci.message_start_time = c.get<std::uint64_t>();
                          ci.message_end_time = c.get<std::uint64_t>();
                          ci.chunk_start_offset = c.get<std::uint64_t>();
                          ci.chunk_length = c.get<std::uint64_t>();
                          ci.message_index_offsets = c.int_map<std::uint16_t, std::uint64_t>();
                          ci.message_index_length = c.get<std::uint64_t>();
                          ci.compression = std::string{c.string()};
                          ci.compressed_size = c.get<std::uint64_t>();
                          ci.uncompressed_size = c.get<std::uint64_t>();
                          if (ci.chunk_start_offset > file_.size() ||
                              ci.chunk_length > file_.size() - ci.chunk_start_offset) {
                            bad(path_, f.offset,
                                "Chunk Index points outside the file (chunk at " +
                                    std::to_string(ci.chunk_start_offset) + ", " +
                                    std::to_string(ci.chunk_length) + " bytes)");
                          }
                          chunks_.push_back(std::move(ci));
                          break;
                        }
                        default:
                          break;  // other summary records are not needed here
                      }
                    });
  } catch (const Truncated& t) {
    bad(path_, t.offset, std::string("summary: ") + t.what());
  }
  std::stable_sort(chunks_.begin(), chunks_.end(), [](const ChunkIndex& a, const ChunkIndex& b) {
    return a.chunk_start_offset < b.chunk_start_offset;
  });
}

McapReader McapReader::recover(const std::filesystem::path& path, const ByteProgress& scanned) {
  McapReader r(path);
  r.scan(true, scanned);
  return r;
}

// scan(): the data section read record by record into the reader's tables. Damage is an
// McapError naming the offset; when recovering, the scan stops there instead and the report
// says why.
struct McapReader::Scan {
  McapReader& reader;
  bool recovering;
  RecoveryReport report{};
  Statistics stats{};

  Scan(McapReader& r, bool recover) : reader(r), recovering(recover) {
    report.file_size = reader.file_.size();
    report.data_end = mcap::kMagic.size();
  }

  void stop(std::uint64_t offset, const std::string& why) {
    if (!recovering) bad(reader.path_, offset, why);
    report.stopped = reader.path_.string() + ": offset " + std::to_string(offset) + ": " + why;
  }

  // The record at `pos`; none when the scan stopped there.
  std::optional<Frame> frame(std::size_t pos) {
    if (pos == reader.file_.size()) {
      stop(pos, "the file ends without a Data End record (cut short)");
      return std::nullopt;
    }
    try {
      return frame_at(reader.file_, pos, 0);
    } catch (const Truncated& t) {
      stop(t.offset, t.what());
      return std::nullopt;
    }
  }

  // The Header record that opens the data; false when the scan stopped there.
  bool header(std::size_t& pos) {
    const std::optional<Frame> f = frame(pos);
    if (!f) return false;
    if (f->op != static_cast<std::uint8_t>(Op::kHeader)) {
      stop(f->offset, "first record is " + op_name(f->op) + ", not Header");
      return false;
    }
    try {
      parse_header(*f, reader.header_);
    } catch (const Truncated& t) {
      stop(t.offset, std::string("Header: ") + t.what());
      return false;
    }
    pos = f->end();
    report.data_end = pos;
    return true;
  }

  void run(const ByteProgress& scanned) {
    std::size_t pos = mcap::kMagic.size();
    if (!header(pos)) return;
    const std::uint64_t size = reader.file_.size();
    while (const std::optional<Frame> f = frame(pos)) {
      bool end_of_data = false;
      try {
        end_of_data = record(*f);
      } catch (const McapError& e) {
        if (!recovering) throw;
        report.stopped = e.what();
        return;
      } catch (const Truncated& t) {
        stop(t.offset, op_name(f->op) + " record at offset " + std::to_string(f->offset) +
                           " is malformed: " + t.what());
        return;
      }
      pos = static_cast<std::size_t>(f->end());
      report.data_end = pos;
      if (scanned) scanned(pos, size);
      if (end_of_data) {
        report.complete = true;
        return;
      }
    }
  }

  // One record after the Header; true when it ends the data.
  bool record(const Frame& f) {
    switch (static_cast<Op>(f.op)) {
      case Op::kSchema:
      case Op::kChannel:
      case Op::kMessage: {
        DataRecords d;
        read_data_record(reader.path_, f, reader.schemas_, reader.channels_, d);
        if (!d.times.empty()) reader.loose_messages_.push_back(f.offset);
        add(d);
        return false;
      }
      case Op::kChunk:
        chunk(f);
        return false;
      case Op::kMessageIndex:
        message_index(f);
        return false;
      case Op::kDataEnd:
        reader.data_end_offset_ = f.offset;
        if (f.content.size() >= 4) {
          Cursor c(f.content, f.offset + mcap::kRecordPrefix);
          reader.data_section_crc_ = c.get<std::uint32_t>();
        }
        return true;
      case Op::kFooter:
        // A file without Data End (older writers): the footer ends the data too.
        return true;
      case Op::kHeader:
        bad(reader.path_, f.offset, "a second Header record");
      default:
        if (f.op == 0) bad(reader.path_, f.offset, "invalid opcode 0 (zeroed or damaged bytes)");
        return false;  // attachments, metadata, unknown records: not needed here
    }
  }

  // Schemas and channels of a chunk count only if the whole chunk is good.
  void chunk(const Frame& f) {
    const ChunkView v = parse_chunk(reader.path_, f);
    DataRecords d;
    for_each_record(v.records, v.records_offset, [&](const Frame& inner) {
      read_data_record(reader.path_, inner, reader.schemas_, reader.channels_, d);
    });
    add(d);
    reader.chunks_.push_back(index_of_chunk(f, v, d.times));
    ++report.chunks;
  }

  void add(DataRecords& d) {
    for (auto& [id, s] : d.schemas) reader.schemas_[id] = std::move(s);
    for (auto& [id, ch] : d.channels) reader.channels_[id] = std::move(ch);
    for (const auto& [channel, time] : d.times) count_message(stats, channel, time);
    report.messages += d.times.size();
  }

  // A Message Index right after its chunk (or after the chunk's other indexes) joins its index.
  void message_index(const Frame& f) {
    Cursor c(f.content, f.offset + mcap::kRecordPrefix);
    const auto channel = c.get<std::uint16_t>();
    if (reader.chunks_.empty()) return;
    ChunkIndex& last = reader.chunks_.back();
    if (last.chunk_start_offset + last.chunk_length + last.message_index_length == f.offset) {
      last.message_index_offsets[channel] = f.offset;
      last.message_index_length += f.end() - f.offset;
    }
  }
};

void McapReader::scan(bool recovering, const ByteProgress& scanned) {
  Scan scan(*this, recovering);
  scan.run(scanned);
  Statistics stats = std::move(scan.stats);
  stats.schema_count = static_cast<std::uint16_t>(schemas_.size());
  stats.channel_count = static_cast<std::uint32_t>(channels_.size());
  stats.chunk_count = static_cast<std::uint32_t>(chunks_.size());
  statistics_ = std::move(stats);
  if (recovering) recovery_ = std::move(scan.report);
}

void McapReader::for_each_message(Order order,
                                  const std::function<void(const MessageView&)>& fn) const {
  // A group is a chunk, or one Message record outside chunks.
  struct Group {
    std::uint64_t offset{0};
    std::uint64_t start{0};
    bool chunk{false};
  };
  std::vector<Group> groups;
  groups.reserve(chunks_.size() + loose_messages_.size());
  for (const ChunkIndex& c : chunks_)
    groups.push_back({c.chunk_start_offset, c.message_start_time, true});
  for (const std::uint64_t at : loose_messages_) {
    const Frame f = frame_at(file_, static_cast<std::size_t>(at), 0);
    groups.push_back({at, parse_message(f).log_time, false});
  }

  const auto view = [&](const RawMessage& m, std::uint64_t group_offset, std::uint64_t at) {
    const auto ch = channels_.find(m.channel_id);
    if (ch == channels_.end()) {
      bad(path_, at, "Message on unknown channel " + std::to_string(m.channel_id));
    }
    const auto schema = schemas_.find(ch->second.schema_id);
    MessageView v{};
    v.channel = &ch->second;
    v.schema = schema == schemas_.end() ? nullptr : &schema->second;
    v.sequence = m.sequence;
    v.log_time_ns = m.log_time;
    v.publish_time_ns = m.publish_time;
    v.data = m.data;
    v.record_offset = group_offset;
    return v;
  };
  const auto load = [&](const Group& g) {
    std::vector<MessageView> out;
    try {
      if (!g.chunk) {
        const Frame f = frame_at(file_, static_cast<std::size_t>(g.offset), 0);
        out.push_back(view(parse_message(f), g.offset, g.offset));
        return out;
      }
      const ChunkView c = indexed_chunk(path_, file_, g.offset);
      for_each_record(c.records, c.records_offset, [&](const Frame& inner) {
        if (inner.op == static_cast<std::uint8_t>(Op::kMessage)) {
          out.push_back(view(parse_message(inner), g.offset, inner.offset));
          // A chunk whose index says it starts after its own messages is damaged: read in
          // log-time order they would come out of order. Refused in either order, naming it.
          if (out.back().log_time_ns < g.start) {
            bad(path_, inner.offset,
                "Message at log time " + std::to_string(out.back().log_time_ns) +
                    ", before the start its chunk index declares (" + std::to_string(g.start) +
                    ")");
          }
        }
      });
    } catch (const Truncated& t) {
      bad(path_, t.offset, t.what());
    }
    return out;
  };

  if (order == Order::kFile) {
    std::stable_sort(groups.begin(), groups.end(),
                     [](const Group& a, const Group& b) { return a.offset < b.offset; });
    for (const Group& g : groups) {
      for (const MessageView& m : load(g)) fn(m);
    }
    return;
  }

  // Log-time order: a k-way merge over the groups, opening a group only once the merge has
  // reached its start time, so memory holds the overlapping chunks only.
  std::stable_sort(groups.begin(), groups.end(), [](const Group& a, const Group& b) {
    return std::tie(a.start, a.offset) < std::tie(b.start, b.offset);
  });
  struct Open {
    std::vector<MessageView> messages;
    std::size_t next{0};
    std::uint64_t offset{0};
  };
  std::vector<Open> open;
  using Key = std::tuple<std::uint64_t, std::uint64_t, std::size_t, std::size_t>;
  // (log time, group offset, position in group, slot): ties fall back to file order.
  std::priority_queue<Key, std::vector<Key>, std::greater<>> heap;
  std::size_t next_group = 0;
  while (true) {
    while (next_group < groups.size() &&
           (heap.empty() || groups[next_group].start <= std::get<0>(heap.top()))) {
      const Group& g = groups[next_group++];
      Open o{load(g), 0, g.offset};
      if (o.messages.empty()) continue;
      std::stable_sort(
          o.messages.begin(), o.messages.end(),
          [](const MessageView& a, const MessageView& b) { return a.log_time_ns < b.log_time_ns; });

      heap.emplace(o.messages[0].log_time_ns, o.offset, 0, open.size());
      open.push_back(std::move(o));
    }
    if (heap.empty()) break;
    const auto [time, offset, index, slot] = heap.top();
    heap.pop();
    Open& o = open[slot];
    fn(o.messages[index]);
    if (index + 1 < o.messages.size()) {
      heap.emplace(o.messages[index + 1].log_time_ns, offset, index + 1, slot);
    } else {
      std::vector<MessageView>().swap(o.messages);
    }
  }
}

std::vector<MessageView> McapReader::messages(Order order) const {
  std::vector<MessageView> out;
  for_each_message(order, [&](const MessageView& m) { out.push_back(m); });
  return out;
}

std::vector<std::string> McapReader::validate() const {
  std::vector<std::string> errors;
  for (const ChunkIndex& c : chunks_) {
    try {
      (void)indexed_chunk(path_, file_, c.chunk_start_offset);
    } catch (const McapError& e) {
      errors.emplace_back(e.what());
    } catch (const Truncated& t) {
      errors.push_back(path_.string() + ": offset " + std::to_string(t.offset) + ": " + t.what());
    }
  }

  std::optional<std::uint64_t> data_end = data_end_offset_;
  std::uint32_t stored = data_section_crc_;
  if (!data_end) {
    // Walk the record frames to the Data End.
    std::size_t pos = mcap::kMagic.size();
    try {
      while (pos < file_.size()) {
        const Frame f = frame_at(file_, pos, 0);
        if (f.op == static_cast<std::uint8_t>(Op::kDataEnd)) {
          data_end = f.offset;
          Cursor c(f.content, f.offset + mcap::kRecordPrefix);
          stored = c.get<std::uint32_t>();
          break;
        }
        if (f.op == static_cast<std::uint8_t>(Op::kFooter)) break;
        pos = static_cast<std::size_t>(f.end());
      }
    } catch (const Truncated& t) {
      errors.push_back(path_.string() + ": offset " + std::to_string(t.offset) + ": " + t.what());
    }
  }
  if (data_end && stored != 0) {
    const std::uint32_t computed =
        mcap::crc32(0, file_.substr(0, static_cast<std::size_t>(*data_end)));
    if (computed != stored) {
      errors.push_back(path_.string() + ": offset " + std::to_string(*data_end) +
                       ": data section CRC mismatch (stored " + hex32(stored) + ", computed " +
                       hex32(computed) + ")");
    }
  }

  if (footer_offset_ && summary_start_ != 0 && summary_crc_ != 0) {
    const std::uint64_t crc_end = *footer_offset_ + mcap::kRecordPrefix + 16;
    const std::uint32_t computed =
        mcap::crc32(0, file_.substr(summary_start_, crc_end - summary_start_));
    if (computed != summary_crc_) {
      errors.push_back(path_.string() + ": offset " + std::to_string(summary_start_) +
                       ": summary CRC mismatch (stored " + hex32(summary_crc_) + ", computed " +
                       hex32(computed) + ")");
    }
  }
  return errors;
}

}  // namespace teleop::record
