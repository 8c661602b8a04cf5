// Byte-exact checks of what McapWriter writes against the layout in the MCAP specification,
// spelled out here field by field (record_test_util.hpp's Bytes), never read back through the
// library.
#include <gtest/gtest.h>

#include <string>

#include "common/record/mcap_writer.hpp"
#include "tests/unit/record/record_test_util.hpp"

namespace teleop::record {
namespace {

using test::Bytes;
using test::kMagicBytes;
using test::record_bytes;
using test::zcrc;

// Names the first differing byte, which a plain EXPECT_EQ on two binary strings does not.
void expect_same_bytes(const std::string& actual, const std::string& expected) {
  ASSERT_EQ(actual.size(), expected.size()) << "file size";
  for (std::size_t i = 0; i < expected.size(); ++i) {
    ASSERT_EQ(static_cast<unsigned>(static_cast<unsigned char>(actual[i])),
              static_cast<unsigned>(static_cast<unsigned char>(expected[i])))
        << "first difference at byte " << i;
  }
}

WriterOptions options(const std::string& library) {
  WriterOptions o{};
  o.library = library;
  return o;
}

TEST(McapLayout, MagicIsTheSpecifiedEightBytes) {
  // 0x89, M, C, A, P, 0x30, \r, \n
  EXPECT_EQ(kMagicBytes, std::string({'\x89', 'M', 'C', 'A', 'P', '\x30', '\r', '\n'}));
  test::TempDir dir;
  { McapWriter w(dir / "m.mcap"); }
  const std::string file = test::slurp(dir / "m.mcap");
  EXPECT_EQ(file.substr(0, 8), kMagicBytes);
  EXPECT_EQ(file.substr(file.size() - 8), kMagicBytes);
}

TEST(McapLayout, HeaderRecordBytes) {
  test::TempDir dir;
  {
    WriterOptions o = options("teleop-test 1.0");
    o.profile = "";
    McapWriter w(dir / "h.mcap", o);
    EXPECT_TRUE(w.close());
  }
  // Header (op 0x01): profile String, library String.
  const std::string expected_header = std::string("\x01", 1) +
                                      // content length: 4 + 0 + 4 + 15 = 23
                                      std::string("\x17\0\0\0\0\0\0\0", 8) +
                                      std::string("\0\0\0\0", 4) +  // profile ""
                                      std::string("\x0f\0\0\0", 4) + "teleop-test 1.0";
  const std::string file = test::slurp(dir / "h.mcap");
  EXPECT_EQ(file.substr(8, expected_header.size()), expected_header);

  WriterOptions ros = options("x");
  ros.profile = "ros2";
  { McapWriter w(dir / "p.mcap", ros); }
  const std::string p = test::slurp(dir / "p.mcap");
  EXPECT_EQ(p.substr(8, 9 + 4 + 4 + 4 + 1), record_bytes(0x01, Bytes{}.str("ros2").str("x").s()));
}

TEST(McapLayout, EmptyFileIsExactlyAsSpecified) {
  test::TempDir dir;
  {
    McapWriter w(dir / "e.mcap", options("L"));
    ASSERT_TRUE(w.close());
  }
  Bytes f;
  f.raw(kMagicBytes).raw(record_bytes(0x01, Bytes{}.str("").str("L").s()));
  // Data End (0x0F): data_section_crc = CRC32 of every byte before it.
  f.raw(record_bytes(0x0F, Bytes{}.u32(zcrc(f.s())).s()));
  const std::size_t summary_start = f.size();
  // Statistics (0x0B) with no messages: counts 0, times 0, empty channel_message_counts.
  const std::string stats = record_bytes(
      0x0B, Bytes{}.u64(0).u16(0).u32(0).u32(0).u32(0).u32(0).u64(0).u64(0).u32(0).s());
  f.raw(stats);
  const std::size_t summary_offset_start = f.size();
  // Summary Offset (0x0E): group_opcode u8, group_start u64, group_length u64.
  f.raw(record_bytes(0x0E, Bytes{}.u8(0x0B).u64(summary_start).u64(stats.size()).s()));
  // Footer (0x02): summary_start, summary_offset_start, summary_crc over everything from
  // the summary start through summary_offset_start.
  const std::string footer_head =
      Bytes{}.u8(0x02).u64(20).u64(summary_start).u64(summary_offset_start).s();
  const std::string crc_span = f.s().substr(summary_start) + footer_head;
  f.raw(footer_head).u32(zcrc(crc_span)).raw(kMagicBytes);
  expect_same_bytes(test::slurp(dir / "e.mcap"), f.s());
}

TEST(McapLayout, SingleMessageFileIsExactlyAsSpecified) {
  test::TempDir dir;
  {
    McapWriter w(dir / "one.mcap", options("L"));
    const auto schema = w.add_schema({"pkg.Msg", "protobuf", std::string("\x0a\x01\x02", 3)});
    const auto channel = w.add_channel({schema, "/topic", "protobuf", {{"k", "v"}}});
    ASSERT_TRUE(w.write(channel, 1000, "hello"));
    ASSERT_TRUE(w.close());
  }
  // Schema (0x03): id u16, name String, encoding String, data uint32-prefixed bytes.
  const std::string schema =
      record_bytes(0x03, Bytes{}.u16(1).str("pkg.Msg").str("protobuf").str("\x0a\x01\x02").s());
  // Channel (0x04): id u16, schema_id u16, topic, message_encoding, metadata Map<string,string>
  // (uint32 byte length, then key String, value String).
  const std::string channel = record_bytes(
      0x04, Bytes{}.u16(1).u16(1).str("/topic").str("protobuf").u32(10).str("k").str("v").s());
  // Message (0x05): channel_id u16, sequence u32, log_time u64, publish_time u64, data.
  const std::string message =
      record_bytes(0x05, Bytes{}.u16(1).u32(0).u64(1000).u64(1000).raw("hello").s());
  const std::string records = schema + channel + message;

  Bytes f;
  f.raw(kMagicBytes).raw(record_bytes(0x01, Bytes{}.str("").str("L").s()));
  const std::size_t chunk_offset = f.size();
  // Chunk (0x06): start, end, uncompressed_size, uncompressed_crc, compression String,
  // records uint64-prefixed.
  const std::string chunk = record_bytes(0x06, Bytes{}
                                                   .u64(1000)
                                                   .u64(1000)
                                                   .u64(records.size())
                                                   .u32(zcrc(records))
                                                   .str("")
                                                   .u64(records.size())
                                                   .raw(records)
                                                   .s());
  f.raw(chunk);
  const std::size_t index_offset = f.size();
  // Message Index (0x07): channel_id, Array<Tuple<Timestamp, uint64>> (uint32 byte length);
  // the offset is the message's within the chunk's records.
  const std::string index =
      record_bytes(0x07, Bytes{}.u16(1).u32(16).u64(1000).u64(schema.size() + channel.size()).s());
  f.raw(index);
  f.raw(record_bytes(0x0F, Bytes{}.u32(zcrc(f.s())).s()));

  const std::size_t summary_start = f.size();
  f.raw(schema);
  const std::size_t channels_at = f.size();
  f.raw(channel);
  const std::size_t stats_at = f.size();
  // Statistics: message_count u64, schema_count u16, channel_count u32, attachment_count u32,
  // metadata_count u32, chunk_count u32, start, end, channel_message_counts Map<u16, u64>.
  const std::string stats = record_bytes(0x0B, Bytes{}
                                                   .u64(1)
                                                   .u16(1)
                                                   .u32(1)
                                                   .u32(0)
                                                   .u32(0)
                                                   .u32(1)
                                                   .u64(1000)
                                                   .u64(1000)
                                                   .u32(10)
                                                   .u16(1)
                                                   .u64(1)
                                                   .s());
  f.raw(stats);
  const std::size_t chunk_index_at = f.size();
  // Chunk Index (0x08): start, end, chunk_start_offset, chunk_length, message_index_offsets
  // Map<u16, u64>, message_index_length, compression, compressed_size, uncompressed_size.
  const std::string chunk_index = record_bytes(0x08, Bytes{}
                                                         .u64(1000)
                                                         .u64(1000)
                                                         .u64(chunk_offset)
                                                         .u64(chunk.size())
                                                         .u32(10)
                                                         .u16(1)
                                                         .u64(index_offset)
                                                         .u64(index.size())
                                                         .str("")
                                                         .u64(records.size())
                                                         .u64(records.size())
                                                         .s());
  f.raw(chunk_index);
  const std::size_t summary_offset_start = f.size();
  const auto offset_record = [](std::uint8_t op, std::size_t start, std::size_t length) {
    return record_bytes(0x0E, Bytes{}.u8(op).u64(start).u64(length).s());
  };
  f.raw(offset_record(0x03, summary_start, schema.size()));
  f.raw(offset_record(0x04, channels_at, channel.size()));
  f.raw(offset_record(0x0B, stats_at, stats.size()));
  f.raw(offset_record(0x08, chunk_index_at, chunk_index.size()));
  const std::string footer_head =
      Bytes{}.u8(0x02).u64(20).u64(summary_start).u64(summary_offset_start).s();
  const std::string crc_span = f.s().substr(summary_start) + footer_head;
  f.raw(footer_head).u32(zcrc(crc_span)).raw(kMagicBytes);

  expect_same_bytes(test::slurp(dir / "one.mcap"), f.s());
}

TEST(McapLayout, MessageRecordCarriesGivenSequenceAndPublishTime) {
  test::TempDir dir;
  {
    McapWriter w(dir / "m.mcap");
    const auto ch = w.add_channel({0, "/raw", "json", {}});
    ASSERT_TRUE(w.write(ch, 5, 7, 42, "xy"));
    ASSERT_TRUE(w.write(ch, 0x0102030405060708ULL, "z"));  // sequence continues: 43
  }
  const std::string file = test::slurp(dir / "m.mcap");
  const std::string first = record_bytes(0x05, Bytes{}.u16(1).u32(42).u64(5).u64(7).raw("xy").s());
  const std::string second =
      std::string("\x05\x17\0\0\0\0\0\0\0\x01\0\x2b\0\0\0", 15) +
      std::string("\x08\x07\x06\x05\x04\x03\x02\x01\x08\x07\x06\x05\x04\x03\x02\x01z", 17);
  EXPECT_NE(file.find(first), std::string::npos);
  EXPECT_NE(file.find(first + second), std::string::npos) << "consecutive in the chunk";
  // A channel without a schema: schema_id 0, and no Schema record anywhere.
  EXPECT_NE(file.find(record_bytes(0x04, Bytes{}.u16(1).u16(0).str("/raw").str("json").u32(0).s())),
            std::string::npos);
  for (const test::Rec& r : test::walk(file)) EXPECT_NE(r.op, 0x03);
}

TEST(McapLayout, SchemaAndChannelFirstAppearInTheChunkOfTheirFirstMessage) {
  test::TempDir dir;
  WriterOptions o{};
  o.chunk_size_bytes = 1;  // every message its own chunk
  {
    McapWriter w(dir / "c.mcap", o);
    const auto s = w.add_schema({"A", "jsonschema", "{}"});
    const auto a = w.add_channel({s, "/a", "json", {}});
    const auto b = w.add_channel({s, "/b", "json", {}});
    ASSERT_TRUE(w.write(a, 1, "1"));
    ASSERT_TRUE(w.write(a, 2, "2"));
    ASSERT_TRUE(w.write(b, 3, "3"));
  }
  const std::string file = test::slurp(dir / "c.mcap");
  std::vector<std::vector<std::uint8_t>> chunk_ops;
  for (const test::Rec& r : test::walk(file)) {
    if (r.op == 0x0F) break;
    if (r.op != 0x06) continue;
    std::vector<std::uint8_t> ops;
    for (const test::Rec& inner : test::walk_records(test::chunk_fields(r.content).records)) {
      ops.push_back(inner.op);
    }
    chunk_ops.push_back(ops);
  }
  ASSERT_EQ(chunk_ops.size(), 3u);
  EXPECT_EQ(chunk_ops[0], (std::vector<std::uint8_t>{0x03, 0x04, 0x05}));
  EXPECT_EQ(chunk_ops[1], (std::vector<std::uint8_t>{0x05}));
  EXPECT_EQ(chunk_ops[2], (std::vector<std::uint8_t>{0x04, 0x05}));
}

}  // namespace
}  // namespace teleop::record
