// Test support for teleop_record: the MCAP layout written out from the spec (mcap.dev/spec)
// independently of the library (little-endian fields built and read byte by byte), temp
// directories, file helpers and a fake clock.
#pragma once

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>
#include <zlib.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "common/record/mcap_writer.hpp"

namespace teleop::record::test {

// ---- building bytes as the spec lays them out ------------------------------------------

class Bytes {
 public:
  Bytes& u8(std::uint64_t v) { return le(v, 1); }
  Bytes& u16(std::uint64_t v) { return le(v, 2); }
  Bytes& u32(std::uint64_t v) { return le(v, 4); }
  Bytes& u64(std::uint64_t v) { return le(v, 8); }
  Bytes& raw(std::string_view s) {
    s_.append(s);
    return *this;
  }
  // String: uint32 byte length, then the bytes.
  Bytes& str(std::string_view s) { return u32(s.size()).raw(s); }
  [[nodiscard]] const std::string& s() const { return s_; }
  [[nodiscard]] std::size_t size() const { return s_.size(); }

 private:
  Bytes& le(std::uint64_t v, int n) {
    for (int i = 0; i < n; ++i) s_.push_back(static_cast<char>((v >> (8 * i)) & 0xFFu));
    return *this;
  }
  std::string s_;
};

// <opcode u8><content length u64><content>
inline std::string record_bytes(std::uint8_t op, const std::string& content) {
  return Bytes{}.u8(op).u64(content.size()).raw(content).s();
}

inline const std::string kMagicBytes{"\x89MCAP0\r\n", 8};

inline std::uint32_t zcrc(std::string_view bytes) {
  return static_cast<std::uint32_t>(
      ::crc32(0, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(bytes.size())));
}

// ---- reading bytes as the spec lays them out -------------------------------------------

class Le {
 public:
  Le(std::string_view s, std::size_t pos = 0) : s_(s), pos_(pos) {}
  std::uint64_t u(int n) {
    if (pos_ + static_cast<std::size_t>(n) > s_.size()) throw std::out_of_range("Le: past end");
    std::uint64_t v = 0;
    for (int i = 0; i < n; ++i) {
      v |= std::uint64_t{static_cast<unsigned char>(s_[pos_ + static_cast<std::size_t>(i)])}
           << (8 * i);
    }
    pos_ += static_cast<std::size_t>(n);
    return v;
  }
  std::uint64_t u8() { return u(1); }
  std::uint64_t u16() { return u(2); }
  std::uint64_t u32() { return u(4); }
  std::uint64_t u64() { return u(8); }
  std::string_view take(std::uint64_t n) {
    if (pos_ + n > s_.size()) throw std::out_of_range("Le: past end");
    const std::string_view out = s_.substr(pos_, static_cast<std::size_t>(n));
    pos_ += static_cast<std::size_t>(n);
    return out;
  }
  std::string str() { return std::string{take(u32())}; }
  [[nodiscard]] std::size_t pos() const { return pos_; }
  [[nodiscard]] bool done() const { return pos_ == s_.size(); }

 private:
  std::string_view s_;
  std::size_t pos_;
};

struct Rec {
  std::uint8_t op{0};
  std::size_t offset{0};  // of the opcode
  std::string_view content{};
  [[nodiscard]] std::size_t end() const { return offset + 9 + content.size(); }
};

// The top-level records of a whole file, from after the leading magic through the Footer.
inline std::vector<Rec> walk(std::string_view file) {
  std::vector<Rec> out;
  Le le(file, 8);
  while (true) {
    Rec r{};
    r.offset = le.pos();
    r.op = static_cast<std::uint8_t>(le.u8());
    r.content = le.take(le.u64());
    out.push_back(r);
    if (r.op == 0x02) break;
  }
  return out;
}

// The records inside a chunk's records field.
inline std::vector<Rec> walk_records(std::string_view records) {
  std::vector<Rec> out;
  Le le(records);
  while (!le.done()) {
    Rec r{};
    r.offset = le.pos();
    r.op = static_cast<std::uint8_t>(le.u8());
    r.content = le.take(le.u64());
    out.push_back(r);
  }
  return out;
}

// A Chunk's fields.
struct ChunkFields {
  std::uint64_t start{0}, end{0}, uncompressed_size{0};
  std::uint32_t crc{0};
  std::string compression{};
  std::string_view records{};
  std::size_t records_offset_in_content{0};
};
inline ChunkFields chunk_fields(std::string_view content) {
  Le le(content);
  ChunkFields c{};
  c.start = le.u64();
  c.end = le.u64();
  c.uncompressed_size = le.u64();
  c.crc = static_cast<std::uint32_t>(le.u32());
  c.compression = le.str();
  const std::uint64_t n = le.u64();
  c.records_offset_in_content = le.pos();
  c.records = le.take(n);
  return c;
}

// ---- files --------------------------------------------------------------------------------

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) throw std::runtime_error("cannot read " + p.string());
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

inline void spit(const std::filesystem::path& p, std::string_view bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw std::runtime_error("cannot write " + p.string());
}

// A fresh directory, removed with everything in it.
class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "teleop_record_XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] std::filesystem::path operator/(const std::string& name) const {
    return path_ / name;
  }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// A clock that moves only when told to.
class FakeClock {
 public:
  [[nodiscard]] Clock clock() const {
    return [ns = ns_] {
      return std::chrono::steady_clock::time_point{std::chrono::nanoseconds{ns->load()}};
    };
  }
  void advance(std::chrono::nanoseconds d) { ns_->fetch_add(d.count()); }

 private:
  std::shared_ptr<std::atomic<std::int64_t>> ns_ = std::make_shared<std::atomic<std::int64_t>>(0);
};

}  // namespace teleop::record::test
