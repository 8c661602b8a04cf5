// Round trips through McapWriter and McapReader, with the file's structure, CRCs and summary
// checked by the test's own reading of the spec layout; chunk flushing by size and by age on
// a fake clock; protobuf schemas.
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/proto_schema.hpp"
#include "teleop/v1/node_state.pb.h"
#include "teleop/v1/telemetry.pb.h"
#include "tests/unit/record/record_test_util.hpp"

namespace teleop::record {
namespace {

using namespace std::chrono_literals;
using test::Le;
using test::Rec;

struct Sent {
  std::uint16_t channel{0};
  std::uint64_t log_time{0};
  std::string data{};
  std::uint32_t sequence{0};
};

const std::vector<std::string> kTopics{"/master/state", "/slave/state", "/master/telemetry",
                                       "/slave/telemetry", "/events"};

// 5 channels on 3 schemas, messages of random sizes; log times advance per channel with
// jitter, so chunks overlap in time and the log-time order differs from the file order.
std::vector<Sent> write_sample(const std::filesystem::path& path, std::size_t count,
                               std::size_t chunk_size, test::FakeClock* clock = nullptr) {
  WriterOptions o{};
  o.chunk_size_bytes = chunk_size;
  test::FakeClock fixed;
  o.clock = clock != nullptr ? clock->clock() : fixed.clock();
  McapWriter w(path, o);
  const std::uint16_t s1 = w.add_schema({"a.A", "protobuf", "schema-a"});
  const std::uint16_t s2 = w.add_schema({"b.B", "jsonschema", "{\"type\":\"object\"}"});
  const std::uint16_t s3 = w.add_schema({"c.C", "protobuf", std::string(300, 'c')});
  const std::uint16_t schema_of[5] = {s1, s1, s2, s2, s3};
  for (std::size_t i = 0; i < kTopics.size(); ++i) {
    EXPECT_EQ(w.add_channel({schema_of[i], kTopics[i], "protobuf", {{"index", std::to_string(i)}}}),
              i + 1);
  }
  std::mt19937_64 rng(20240605);
  std::uniform_int_distribution<int> channel_pick(1, 5);
  std::uniform_int_distribution<int> size_pick(0, 400);
  std::uniform_int_distribution<int> jitter(0, 3'000'000);
  std::uint64_t base = 1'700'000'000'000'000'000ULL;
  std::map<std::uint16_t, std::uint32_t> sequence;
  std::vector<Sent> sent;
  for (std::size_t i = 0; i < count; ++i) {
    const auto ch = static_cast<std::uint16_t>(channel_pick(rng));
    std::string data(static_cast<std::size_t>(size_pick(rng)), '\0');
    for (char& c : data) c = static_cast<char>(rng());
    base += 100'000;
    const std::uint64_t t = base + static_cast<std::uint64_t>(jitter(rng));
    EXPECT_TRUE(w.write(ch, t, data));
    sent.push_back({ch, t, data, sequence[ch]++});
  }
  EXPECT_TRUE(w.close()) << w.error();
  return sent;
}

void expect_same(const MessageView& got, const Sent& want, std::size_t i) {
  ASSERT_NE(got.channel, nullptr);
  EXPECT_EQ(got.channel->id, want.channel) << i;
  EXPECT_EQ(got.channel->topic, kTopics[want.channel - 1u]) << i;
  EXPECT_EQ(got.log_time_ns, want.log_time) << i;
  EXPECT_EQ(got.publish_time_ns, want.log_time) << i;
  EXPECT_EQ(got.sequence, want.sequence) << i;
  EXPECT_EQ(got.data, want.data) << i;
}

TEST(McapRoundTrip, ManyMessagesOverSeveralChannelsAndChunks) {
  test::TempDir dir;
  const auto path = dir / "rt.mcap";
  const std::vector<Sent> sent = write_sample(path, 20000, 16 * 1024);

  const McapReader r = McapReader::open(path);
  EXPECT_TRUE(r.indexed());
  EXPECT_EQ(r.header().library, "teleop-record");
  ASSERT_EQ(r.schemas().size(), 3u);
  EXPECT_EQ(r.schemas().at(2).name, "b.B");
  EXPECT_EQ(r.schemas().at(2).encoding, "jsonschema");
  EXPECT_EQ(r.schemas().at(3).data, std::string(300, 'c'));
  ASSERT_EQ(r.channels().size(), 5u);
  EXPECT_EQ(r.channels().at(4).topic, "/slave/telemetry");
  EXPECT_EQ(r.channels().at(4).schema_id, 2);
  EXPECT_EQ(r.channels().at(4).metadata.at("index"), "3");
  EXPECT_GT(r.chunk_indexes().size(), 50u);
  EXPECT_TRUE(r.validate().empty());

  const std::vector<MessageView> in_file = r.messages(Order::kFile);
  ASSERT_EQ(in_file.size(), sent.size());
  for (std::size_t i = 0; i < sent.size(); ++i) expect_same(in_file[i], sent[i], i);

  std::vector<Sent> by_time = sent;
  std::stable_sort(by_time.begin(), by_time.end(),
                   [](const Sent& a, const Sent& b) { return a.log_time < b.log_time; });
  ASSERT_NE(by_time[0].log_time, sent[0].log_time) << "the sample must not be in time order";
  const std::vector<MessageView> in_time = r.messages(Order::kLogTime);
  ASSERT_EQ(in_time.size(), sent.size());
  for (std::size_t i = 0; i < sent.size(); ++i) expect_same(in_time[i], by_time[i], i);
}

TEST(McapRoundTrip, StructureCrcsAndSummaryMatchTheSpec) {
  test::TempDir dir;
  const auto path = dir / "s.mcap";
  const std::vector<Sent> sent = write_sample(path, 3000, 8 * 1024);
  const std::string file = test::slurp(path);
  const std::vector<Rec> recs = test::walk(file);

  // Data section: Header, then Chunk followed by its Message Indexes, ..., Data End.
  ASSERT_EQ(recs.front().op, 0x01);
  std::size_t i = 1;
  std::vector<std::size_t> chunk_offsets;
  std::map<std::size_t, std::map<std::uint64_t, std::size_t>> index_offsets;  // chunk -> ch -> at
  std::map<std::size_t, std::size_t> index_lengths;
  std::map<std::uint16_t, std::uint64_t> counted;
  std::uint64_t first_time = UINT64_MAX, last_time = 0;
  for (; recs[i].op != 0x0F; ++i) {
    ASSERT_EQ(recs[i].op, 0x06) << "record " << i << " at " << recs[i].offset;
    const test::ChunkFields c = test::chunk_fields(recs[i].content);
    EXPECT_EQ(c.compression, "");
    EXPECT_EQ(c.uncompressed_size, c.records.size());
    EXPECT_EQ(c.crc, test::zcrc(c.records)) << "chunk at " << recs[i].offset;
    std::map<std::uint64_t, std::vector<std::pair<std::uint64_t, std::uint64_t>>> expected_index;
    std::uint64_t lo = UINT64_MAX, hi = 0;
    for (const Rec& inner : test::walk_records(c.records)) {
      if (inner.op != 0x05) continue;
      Le m(inner.content);
      const auto ch = static_cast<std::uint16_t>(m.u16());
      m.u32();
      const std::uint64_t t = m.u64();
      expected_index[ch].emplace_back(t, inner.offset);
      ++counted[ch];
      lo = std::min(lo, t);
      hi = std::max(hi, t);
    }
    EXPECT_EQ(c.start, lo);
    EXPECT_EQ(c.end, hi);
    first_time = std::min(first_time, lo);
    last_time = std::max(last_time, hi);
    const std::size_t chunk_at = recs[i].offset;
    chunk_offsets.push_back(chunk_at);
    // One Message Index per channel in the chunk, entries sorted by log time.
    std::size_t length = 0;
    while (recs[i + 1].op == 0x07) {
      ++i;
      Le mi(recs[i].content);
      const std::uint64_t ch = mi.u16();
      const std::uint64_t bytes = mi.u32();
      std::vector<std::pair<std::uint64_t, std::uint64_t>> entries;
      for (std::uint64_t k = 0; k < bytes / 16; ++k) {
        const std::uint64_t t = mi.u64();
        entries.emplace_back(t, mi.u64());
      }
      EXPECT_TRUE(mi.done());
      auto want = expected_index[ch];
      std::stable_sort(want.begin(), want.end(),
                       [](const auto& a, const auto& b) { return a.first < b.first; });
      EXPECT_EQ(entries, want) << "message index of channel " << ch << " after " << chunk_at;
      expected_index.erase(ch);
      index_offsets[chunk_at][ch] = recs[i].offset;
      length += recs[i].end() - recs[i].offset;
    }
    EXPECT_TRUE(expected_index.empty())
        << "a channel of the chunk at " << chunk_at << " has no Message Index";
    index_lengths[chunk_at] = length;
  }
  const Rec& data_end = recs[i];
  EXPECT_EQ(Le(data_end.content).u32(),
            test::zcrc(std::string_view(file).substr(0, data_end.offset)));

  // Footer and summary CRC.
  const Rec& footer = recs.back();
  ASSERT_EQ(footer.end() + 8, file.size());
  Le fl(footer.content);
  const std::uint64_t summary_start = fl.u64();
  const std::uint64_t summary_offset_start = fl.u64();
  const std::uint64_t summary_crc = fl.u32();
  EXPECT_EQ(summary_start, data_end.end());
  EXPECT_EQ(summary_crc, test::zcrc(std::string_view(file).substr(
                             summary_start, footer.offset + 9 + 16 - summary_start)));

  // Summary: groups by opcode; Summary Offsets point at each group exactly.
  std::map<std::uint8_t, std::pair<std::size_t, std::size_t>> groups;  // op -> [start, end)
  std::vector<std::uint8_t> order;
  std::size_t j = i + 1;
  for (; recs[j].offset < summary_offset_start; ++j) {
    auto [it, fresh] = groups.try_emplace(recs[j].op, recs[j].offset, recs[j].end());
    if (fresh) {
      order.push_back(recs[j].op);
    } else {
      EXPECT_EQ(it->second.second, recs[j].offset)
          << "opcode " << int{recs[j].op} << " not grouped";
      it->second.second = recs[j].end();
    }
  }
  EXPECT_EQ(order, (std::vector<std::uint8_t>{0x03, 0x04, 0x0B, 0x08}));
  std::size_t offsets_seen = 0;
  for (; recs[j].op == 0x0E; ++j, ++offsets_seen) {
    Le so(recs[j].content);
    const auto op = static_cast<std::uint8_t>(so.u8());
    const std::uint64_t start = so.u64();
    const std::uint64_t length = so.u64();
    ASSERT_TRUE(groups.contains(op));
    EXPECT_EQ(start, groups[op].first);
    EXPECT_EQ(length, groups[op].second - groups[op].first);
  }
  EXPECT_EQ(offsets_seen, groups.size());
  EXPECT_EQ(&recs[j], &footer);

  // Statistics.
  std::size_t chunk_index_seen = 0;
  for (std::size_t k = i + 1; recs[k].op != 0x0E; ++k) {
    Le s(recs[k].content);
    if (recs[k].op == 0x0B) {
      EXPECT_EQ(s.u64(), sent.size());
      EXPECT_EQ(s.u16(), 3u);
      EXPECT_EQ(s.u32(), 5u);
      EXPECT_EQ(s.u32(), 0u);
      EXPECT_EQ(s.u32(), 0u);
      EXPECT_EQ(s.u32(), chunk_offsets.size());
      EXPECT_EQ(s.u64(), first_time);
      EXPECT_EQ(s.u64(), last_time);
      EXPECT_EQ(s.u32(), 5u * 10u);
      for (std::uint16_t ch = 1; ch <= 5; ++ch) {
        EXPECT_EQ(s.u16(), ch);
        EXPECT_EQ(s.u64(), counted[ch]);
      }
      EXPECT_TRUE(s.done());
    } else if (recs[k].op == 0x08) {
      const std::size_t at = chunk_offsets.at(chunk_index_seen++);
      const Rec* chunk = nullptr;
      for (const Rec& r : recs) {
        if (r.offset == at) chunk = &r;
      }
      const test::ChunkFields c = test::chunk_fields(chunk->content);
      EXPECT_EQ(s.u64(), c.start);
      EXPECT_EQ(s.u64(), c.end);
      EXPECT_EQ(s.u64(), at);
      EXPECT_EQ(s.u64(), chunk->end() - chunk->offset);
      const std::uint64_t map_bytes = s.u32();
      std::map<std::uint64_t, std::size_t> got;
      for (std::uint64_t e = 0; e < map_bytes / 10; ++e) {
        const std::uint64_t ch = s.u16();
        got[ch] = s.u64();
      }
      EXPECT_EQ(got, index_offsets[at]);
      EXPECT_EQ(s.u64(), index_lengths[at]);
      EXPECT_EQ(s.str(), "");
      EXPECT_EQ(s.u64(), c.records.size());
      EXPECT_EQ(s.u64(), c.records.size());
      EXPECT_TRUE(s.done());
    }
  }
  EXPECT_EQ(chunk_index_seen, chunk_offsets.size());

  // The reader's statistics agree.
  const McapReader r = McapReader::open(path);
  ASSERT_TRUE(r.statistics().has_value());
  EXPECT_EQ(r.statistics()->message_count, sent.size());
  EXPECT_EQ(r.statistics()->chunk_count, chunk_offsets.size());
  EXPECT_EQ(r.statistics()->message_start_time, first_time);
  EXPECT_EQ(r.statistics()->message_end_time, last_time);
  EXPECT_EQ(r.statistics()->channel_message_counts.at(3), counted[3]);
}

TEST(McapRoundTrip, CrcMismatchesAreReportedWithTheirOffsets) {
  test::TempDir dir;
  const auto path = dir / "c.mcap";
  (void)write_sample(path, 500, 4 * 1024);
  const std::string good = test::slurp(path);
  const std::vector<Rec> recs = test::walk(good);
  std::vector<std::size_t> chunks;
  for (std::size_t k = 0; k < recs.size(); ++k) {
    if (recs[k].op == 0x06) chunks.push_back(k);
  }
  ASSERT_GE(chunks.size(), 3u);
  const Rec& chunk = recs[chunks[1]];
  const Rec& index = recs[chunks[1] + 1];

  // A byte inside a chunk's records.
  std::string bad = good;
  bad[chunk.end() - 5] = static_cast<char>(bad[chunk.end() - 5] ^ 0x40);
  test::spit(dir / "chunk.mcap", bad);
  {
    const McapReader r = McapReader::open(dir / "chunk.mcap");
    const std::vector<std::string> errors = r.validate();
    ASSERT_EQ(errors.size(), 2u);  // the chunk, and so the data section
    EXPECT_NE(errors[0].find("chunk.mcap: offset " + std::to_string(chunk.offset)),
              std::string::npos)
        << errors[0];
    EXPECT_NE(errors[0].find("chunk CRC mismatch"), std::string::npos) << errors[0];
    EXPECT_NE(errors[1].find("data section CRC mismatch"), std::string::npos) << errors[1];
    try {
      (void)r.messages();
      FAIL() << "a damaged chunk must not be read";
    } catch (const McapError& e) {
      EXPECT_NE(std::string(e.what()).find("offset " + std::to_string(chunk.offset)),
                std::string::npos)
          << e.what();
    }
  }

  // A byte in a Message Index: outside every chunk, caught by the data section CRC.
  ASSERT_EQ(index.op, 0x07);
  bad = good;
  bad[index.end() - 1] = static_cast<char>(bad[index.end() - 1] ^ 0x01);
  test::spit(dir / "index.mcap", bad);
  {
    const McapReader r = McapReader::open(dir / "index.mcap");
    const std::vector<std::string> errors = r.validate();
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_NE(errors[0].find("data section CRC mismatch"), std::string::npos) << errors[0];
  }

  // A byte in the summary: open refuses, naming the summary's offset.
  const Rec& footer = recs.back();
  const std::uint64_t summary_start = Le(footer.content).u64();
  bad = good;
  bad[summary_start + 20] = static_cast<char>(bad[summary_start + 20] ^ 0x01);
  test::spit(dir / "summary.mcap", bad);
  try {
    (void)McapReader::open(dir / "summary.mcap");
    FAIL() << "a damaged summary must not be used";
  } catch (const McapError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("summary.mcap: offset " + std::to_string(summary_start)), std::string::npos)
        << what;
    EXPECT_NE(what.find("summary CRC mismatch"), std::string::npos) << what;
  }
}

TEST(McapReaderErrors, NamesTheFileAndWhatIsWrong) {
  test::TempDir dir;
  test::spit(dir / "text.mcap", "hello, this is not mcap");
  try {
    (void)McapReader::open(dir / "text.mcap");
    FAIL();
  } catch (const McapError& e) {
    EXPECT_NE(std::string(e.what()).find("text.mcap: offset 0: not an MCAP file"),
              std::string::npos)
        << e.what();
  }
  EXPECT_THROW((void)McapReader::open(dir / "missing.mcap"), McapError);
  EXPECT_THROW((void)McapReader::recover(dir / "text.mcap"), McapError);
}

TEST(McapReaderScan, ReadsAHandBuiltFileWithoutSummaryAndWithMessagesOutsideChunks) {
  // Written from the spec by hand: Schema, Channel and a Message directly in the data
  // section, then a Chunk with a second channel and two messages, Data End, a Footer with no
  // summary (summary_start = summary_offset_start = summary_crc = 0).
  using test::Bytes;
  using test::record_bytes;
  Bytes f;
  f.raw(test::kMagicBytes).raw(record_bytes(0x01, Bytes{}.str("").str("hand").s()));
  f.raw(record_bytes(0x03, Bytes{}.u16(7).str("m.M").str("protobuf").str("fds").s()));
  f.raw(record_bytes(0x04, Bytes{}.u16(3).u16(7).str("/loose").str("protobuf").u32(0).s()));
  f.raw(record_bytes(0x05, Bytes{}.u16(3).u32(9).u64(300).u64(299).raw("L").s()));
  const std::string records =
      record_bytes(0x04, Bytes{}.u16(4).u16(0).str("/chunked").str("json").u32(0).s()) +
      record_bytes(0x05, Bytes{}.u16(4).u32(0).u64(500).u64(500).raw("A").s()) +
      record_bytes(0x05, Bytes{}.u16(3).u32(10).u64(100).u64(100).raw("B").s());
  f.raw(record_bytes(0x06, Bytes{}
                               .u64(100)
                               .u64(500)
                               .u64(records.size())
                               .u32(test::zcrc(records))
                               .str("")
                               .u64(records.size())
                               .raw(records)
                               .s()));
  f.raw(record_bytes(0x0F, Bytes{}.u32(test::zcrc(f.s())).s()));
  f.raw(record_bytes(0x02, Bytes{}.u64(0).u64(0).u32(0).s())).raw(test::kMagicBytes);
  test::TempDir dir;
  test::spit(dir / "hand.mcap", f.s());

  const McapReader r = McapReader::open(dir / "hand.mcap");
  EXPECT_FALSE(r.indexed());
  EXPECT_EQ(r.header().library, "hand");
  EXPECT_TRUE(r.validate().empty());
  ASSERT_EQ(r.channels().size(), 2u);
  EXPECT_EQ(r.schemas().at(7).name, "m.M");
  EXPECT_EQ(r.statistics()->message_count, 3u);
  EXPECT_EQ(r.statistics()->message_start_time, 100u);
  EXPECT_EQ(r.statistics()->message_end_time, 500u);
  std::string order;
  for (const MessageView& m : r.messages(Order::kFile)) order += m.data;
  EXPECT_EQ(order, "LAB");
  order.clear();
  for (const MessageView& m : r.messages(Order::kLogTime)) order += m.data;
  EXPECT_EQ(order, "BLA");
  const MessageView loose = r.messages(Order::kFile)[0];
  EXPECT_EQ(loose.channel->topic, "/loose");
  ASSERT_NE(loose.schema, nullptr);
  EXPECT_EQ(loose.schema->data, "fds");
  EXPECT_EQ(loose.sequence, 9u);
  EXPECT_EQ(loose.publish_time_ns, 299u);
  EXPECT_EQ(r.messages(Order::kFile)[1].schema, nullptr) << "channel without schema";
}

TEST(McapFlush, FdatasyncOptionStillWritesAValidFile) {
  test::TempDir dir;
  WriterOptions o{};
  o.fdatasync = true;
  o.chunk_size_bytes = 64;
  {
    McapWriter w(dir / "sync.mcap", o);
    const auto ch = w.add_channel({0, "/t", "json", {}});
    for (std::uint64_t i = 0; i < 20; ++i) ASSERT_TRUE(w.write(ch, i, std::string(40, 'x')));
    EXPECT_EQ(w.chunks_written(), 20u);
    ASSERT_TRUE(w.close()) << w.error();
  }
  const McapReader r = McapReader::open(dir / "sync.mcap");
  EXPECT_TRUE(r.validate().empty());
  EXPECT_EQ(r.statistics()->message_count, 20u);
}

TEST(McapFlush, ChunkIsFlushedWhenItReachesTheSizeLimit) {
  test::TempDir dir;
  test::FakeClock clock;
  WriterOptions o{};
  o.chunk_size_bytes = 1000;
  o.clock = clock.clock();
  McapWriter w(dir / "size.mcap", o);
  const auto s = w.add_schema({"S", "protobuf", "0123456789"});
  const auto ch = w.add_channel({s, "/t", "protobuf", {}});
  const std::uint64_t header_end = w.file_size();
  // Per spec: Schema 9+2+(4+1)+(4+8)+(4+10) = 42, Channel 9+2+2+(4+2)+(4+8)+4 = 35,
  // Message 9+22+100 = 131. The first chunk's records reach 1000 bytes at message
  // ceil((1000-77)/131) = 8; later chunks at ceil(1000/131) = 8 too.
  const std::string data(100, 'd');
  for (int i = 1; i <= 7; ++i) {
    ASSERT_TRUE(w.write(ch, static_cast<std::uint64_t>(i), data));
    EXPECT_EQ(w.chunks_written(), 0u) << i;
    EXPECT_EQ(w.file_size(), header_end) << "nothing reaches the file before the chunk is full";
  }
  ASSERT_TRUE(w.write(ch, 8, data));
  EXPECT_EQ(w.chunks_written(), 1u);
  EXPECT_EQ(w.messages_written(), 8u);
  EXPECT_EQ(w.messages_pending(), 0u);
  // Chunk record: 9 + 8+8+8+4+4+8 + records (42+35+8*131); one Message Index: 9+2+4+8*16.
  const std::uint64_t first_chunk = 9 + 40 + (42 + 35 + 8 * 131) + (9 + 6 + 8 * 16);
  EXPECT_EQ(w.file_size(), header_end + first_chunk);
  for (int i = 9; i <= 15; ++i) ASSERT_TRUE(w.write(ch, static_cast<std::uint64_t>(i), data));
  EXPECT_EQ(w.chunks_written(), 1u);
  ASSERT_TRUE(w.write(ch, 16, data));
  EXPECT_EQ(w.chunks_written(), 2u);
  EXPECT_EQ(w.messages_written(), 16u);
}

TEST(McapFlush, ChunkIsFlushedWhenItsOldestMessageIsOlderThanTheMaxAge) {
  test::TempDir dir;
  test::FakeClock clock;
  WriterOptions o{};
  o.max_chunk_age = 200ms;
  o.clock = clock.clock();
  McapWriter w(dir / "age.mcap", o);
  const auto ch = w.add_channel({0, "/t", "json", {}});
  ASSERT_TRUE(w.write(ch, 1, "a"));
  clock.advance(150ms);
  ASSERT_TRUE(w.write(ch, 2, "b"));
  clock.advance(49ms);
  ASSERT_TRUE(w.poll());
  EXPECT_EQ(w.chunks_written(), 0u) << "the oldest message is 199 ms old";
  clock.advance(1ms);
  ASSERT_TRUE(w.poll());
  EXPECT_EQ(w.chunks_written(), 1u);
  EXPECT_EQ(w.messages_written(), 2u);

  // A message arriving after the age passed goes out with the chunk it joins.
  ASSERT_TRUE(w.write(ch, 3, "c"));
  clock.advance(300ms);
  ASSERT_TRUE(w.write(ch, 4, "d"));
  EXPECT_EQ(w.chunks_written(), 2u);
  EXPECT_EQ(w.messages_written(), 4u);
  // An empty chunk has no age.
  clock.advance(1s);
  ASSERT_TRUE(w.poll());
  EXPECT_EQ(w.chunks_written(), 2u);
}

TEST(McapFlush, FlushedChunksAreInTheFileAndReadableWhileWriting) {
  test::TempDir dir;
  test::FakeClock clock;
  WriterOptions o{};
  o.clock = clock.clock();
  const auto path = dir / "live.mcap";
  McapWriter w(path, o);
  const auto ch = w.add_channel({0, "/t", "json", {}});
  for (int i = 0; i < 10; ++i) ASSERT_TRUE(w.write(ch, static_cast<std::uint64_t>(i), "{}"));
  ASSERT_TRUE(w.flush());
  ASSERT_TRUE(w.write(ch, 10, "{}"));  // pending, not in the file
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(static_cast<std::uint64_t>(st.st_size), w.file_size()) << "no user-space buffering";
  const McapReader r = McapReader::recover(path);
  EXPECT_EQ(r.recovery()->chunks, 1u);
  EXPECT_EQ(r.recovery()->messages, 10u);
  EXPECT_EQ(r.recovery()->data_end, w.file_size());
}

TEST(ProtoSchema, FileDescriptorSetHoldsTheFileAndItsImportsInOrder) {
  const auto* descriptor = teleop::v1::Telemetry::descriptor();
  const SchemaDef schema = protobuf_schema(descriptor);
  EXPECT_EQ(schema.name, "teleop.v1.Telemetry");
  EXPECT_EQ(schema.encoding, "protobuf");
  EXPECT_EQ(schema.data, file_descriptor_set(descriptor));

  google::protobuf::FileDescriptorSet set;
  ASSERT_TRUE(set.ParseFromString(schema.data));
  // The message's own file last; every file after all the files it imports; each once.
  ASSERT_GE(set.file_size(), 2);
  EXPECT_EQ(set.file(set.file_size() - 1).name(), "teleop/v1/telemetry.proto");
  std::set<std::string> earlier;
  for (const auto& file : set.file()) {
    for (const auto& dependency : file.dependency()) {
      EXPECT_TRUE(earlier.contains(dependency)) << file.name() << " before " << dependency;
    }
    EXPECT_TRUE(earlier.insert(file.name()).second) << file.name() << " twice";
  }
  EXPECT_TRUE(earlier.contains("teleop/v1/node_state.proto"));

  // A pool built from the set alone, in its order, decodes a real message.
  google::protobuf::DescriptorPool pool;
  for (const auto& file : set.file()) ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
  const auto* found = pool.FindMessageTypeByName("teleop.v1.Telemetry");
  ASSERT_NE(found, nullptr);
  teleop::v1::Telemetry t;
  t.set_mode(teleop::v1::ENGAGED);
  t.set_mode_reason("engaged by operator");
  t.add_cycles()->set_sequence(77);
  google::protobuf::DynamicMessageFactory factory(&pool);
  std::unique_ptr<google::protobuf::Message> m(factory.GetPrototype(found)->New());
  ASSERT_TRUE(m->ParseFromString(t.SerializeAsString()));
  EXPECT_EQ(m->SerializeAsString(), t.SerializeAsString());

  const SchemaDef state = protobuf_schema(teleop::v1::NodeState::descriptor());
  ASSERT_TRUE(set.ParseFromString(state.data));
  EXPECT_EQ(set.file_size(), 1);
  EXPECT_THROW((void)file_descriptor_set(nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace teleop::record
