// The MCAP byte layout (mcap.dev/spec, major version 0): opcodes, the record frame and the
// serialisation of its field types, shared by the writer and the reader of teleop_record.
// Everything is little-endian; integers are copied as they are in memory, so the library
// refuses to build on a big-endian host rather than write files no one else can read.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>

namespace teleop::record::mcap {

static_assert(std::endian::native == std::endian::little,
              "MCAP is little-endian and this codec copies integers as they lie in memory");

// 0x89 'M' 'C' 'A' 'P' '0' '\r' '\n': begins and ends every file.
inline constexpr std::string_view kMagic{"\x89MCAP0\r\n", 8};

enum class Op : std::uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

// Every record: <opcode u8><content length u64><content>.
inline constexpr std::size_t kRecordPrefix = 9;
// Footer content: summary_start u64, summary_offset_start u64, summary_crc u32.
inline constexpr std::size_t kFooterContent = 20;
inline constexpr std::size_t kFooterRecord = kRecordPrefix + kFooterContent;
// Message content before its data: channel_id u16, sequence u32, log_time u64, publish_time u64.
inline constexpr std::size_t kMessageFixed = 2 + 4 + 8 + 8;

// zlib's CRC-32 (the one the spec means), over any length. crc32_combine joins the CRC of
// one block to that of the next without reading the bytes again.
[[nodiscard]] std::uint32_t crc32(std::uint32_t crc, std::string_view bytes);
[[nodiscard]] std::uint32_t crc32_combine(std::uint32_t first, std::uint32_t second,
                                          std::uint64_t second_length);

// ---- writing ----------------------------------------------------------------------------

template <typename T>
requires std::is_integral_v<T>
inline void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  out.append(bytes, sizeof(T));
}

// uint32 length prefix: Strings, Arrays and Maps.
inline std::uint32_t length32(std::size_t n) {
  if (n > std::numeric_limits<std::uint32_t>::max()) {
    throw std::length_error("MCAP: a string, array or map exceeds 4 GiB");
  }
  return static_cast<std::uint32_t>(n);
}

inline void put_string(std::string& out, std::string_view s) {
  put<std::uint32_t>(out, length32(s.size()));
  out.append(s);
}

inline void put_string_map(std::string& out, const std::map<std::string, std::string>& map) {
  std::size_t bytes = 0;
  for (const auto& [k, v] : map) bytes += 8 + k.size() + v.size();
  put<std::uint32_t>(out, length32(bytes));
  for (const auto& [k, v] : map) {
    put_string(out, k);
    put_string(out, v);
  }
}

// Starts a record; returns where its length goes, for end_record to fill in.
inline std::size_t begin_record(std::string& out, Op op) {
  out.push_back(static_cast<char>(op));
  const std::size_t at = out.size();
  put<std::uint64_t>(out, 0);
  return at;
}

inline void end_record(std::string& out, std::size_t length_at) {
  const std::uint64_t length = out.size() - length_at - 8;
  std::memcpy(out.data() + length_at, &length, sizeof(length));
}

// ---- reading ----------------------------------------------------------------------------

// Reading past the end of a record or of the file.
struct Truncated : std::runtime_error {
  Truncated(const std::string& what, std::uint64_t at) : std::runtime_error(what), offset(at) {}
  std::uint64_t offset;
};

// Bounds-checked reads over bytes that start at file offset `base`; throws Truncated.
class Cursor {
 public:
  Cursor(std::string_view bytes, std::uint64_t base) : bytes_(bytes), base_(base) {}

  template <typename T>
  requires std::is_integral_v<T> T get() {
    need(sizeof(T));
    T value{};
    std::memcpy(&value, bytes_.data() + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }
  std::string_view bytes(std::uint64_t n) {
    need(n);
    const std::string_view out = bytes_.substr(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return out;
  }
  std::string_view string() { return bytes(get<std::uint32_t>()); }
  std::map<std::string, std::string> string_map() {
    Cursor entries(bytes(get<std::uint32_t>()), offset());
    std::map<std::string, std::string> out;
    while (!entries.done()) {
      std::string key{entries.string()};
      out[std::move(key)] = std::string{entries.string()};
    }
    return out;
  }
  template <typename K, typename V>
  std::map<K, V> int_map() {
    Cursor entries(bytes(get<std::uint32_t>()), offset());
    std::map<K, V> out;
    while (!entries.done()) {
      const K key = entries.get<K>();
      out[key] = entries.get<V>();
    }
    return out;
  }

  [[nodiscard]] bool done() const { return pos_ == bytes_.size(); }
  [[nodiscard]] std::size_t remaining() const { return bytes_.size() - pos_; }
  [[nodiscard]] std::uint64_t offset() const { return base_ + pos_; }

 private:
  void need(std::uint64_t n) const {
    if (n > bytes_.size() - pos_) {
      throw Truncated("needs " + std::to_string(n) + " bytes, " +
                          std::to_string(bytes_.size() - pos_) + " left",
                      base_ + pos_);
    }
  }
  std::string_view bytes_{};
  std::uint64_t base_{0};
  std::size_t pos_{0};
};

}  // namespace teleop::record::mcap
