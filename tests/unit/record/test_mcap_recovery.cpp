// Recovery of cut and damaged files: every complete chunk before the damage is kept, nothing
// after it. Chunk boundaries come from the test's own reading of the spec layout.
#include <gtest/gtest.h>

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "common/record/mcap_writer.hpp"
#include "tests/unit/record/record_test_util.hpp"

namespace teleop::record {
namespace {

struct Layout {
  std::string file{};
  std::size_t header_end{0};
  struct Chunk {
    std::size_t end{0};  // end of the Chunk record
    std::size_t messages_before_and_in{0};
  };
  std::vector<Chunk> chunks{};
  std::size_t data_end_end{0};          // end of the Data End record
  std::vector<std::string> payloads{};  // in write order
};

// ~60 messages of 20..60 bytes on 3 channels, 512-byte chunks: a small file with ~8 chunks,
// small enough to cut at every offset.
Layout write_small(const std::filesystem::path& path) {
  Layout l{};
  test::FakeClock clock;
  WriterOptions o{};
  o.chunk_size_bytes = 512;
  o.clock = clock.clock();
  {
    McapWriter w(path, o);
    const auto s = w.add_schema({"x.Y", "protobuf", "descriptor"});
    const std::uint16_t ch[3] = {w.add_channel({s, "/a", "protobuf", {}}),
                                 w.add_channel({s, "/b", "protobuf", {{"rate", "1000"}}}),
                                 w.add_channel({0, "/c", "json", {}})};
    for (int i = 0; i < 60; ++i) {
      std::string payload = "message " + std::to_string(i) +
                            std::string(static_cast<std::size_t>(20 + (i * 7) % 41), '*');
      EXPECT_TRUE(w.write(ch[i % 3], static_cast<std::uint64_t>(1000 + i), payload));
      l.payloads.push_back(std::move(payload));
    }
    EXPECT_TRUE(w.close());
  }
  l.file = test::slurp(path);
  std::size_t messages = 0;
  for (const test::Rec& r : test::walk(l.file)) {
    if (r.op == 0x01) l.header_end = r.end();
    if (r.op == 0x06) {
      for (const test::Rec& inner : test::walk_records(test::chunk_fields(r.content).records)) {
        if (inner.op == 0x05) ++messages;
      }
      l.chunks.push_back({r.end(), messages});
    }
    if (r.op == 0x0F) l.data_end_end = r.end();
  }
  return l;
}

TEST(McapRecovery, CutAtEveryOffsetKeepsExactlyTheCompleteChunksBeforeIt) {
  test::TempDir dir;
  const Layout l = write_small(dir / "full.mcap");
  ASSERT_GE(l.chunks.size(), 6u);
  ASSERT_EQ(l.chunks.back().messages_before_and_in, 60u);
  const auto cut_path = dir / "cut.mcap";
  for (std::size_t cut = 0; cut <= l.file.size(); ++cut) {
    SCOPED_TRACE("cut at " + std::to_string(cut) + " of " + std::to_string(l.file.size()));
    test::spit(cut_path, std::string_view(l.file).substr(0, cut));
    if (cut < 8) {
      EXPECT_THROW((void)McapReader::recover(cut_path), McapError);
      continue;
    }
    if (cut < l.file.size()) {
      try {
        (void)McapReader::open(cut_path);
        ADD_FAILURE() << "open() must refuse a file without its footer";
      } catch (const McapError& e) {
        EXPECT_NE(std::string(e.what()).find("cut.mcap"), std::string::npos) << e.what();
      }
    }
    const McapReader r = McapReader::recover(cut_path);
    const RecoveryReport& rep = *r.recovery();
    std::size_t chunks = 0, messages = 0, kept_end = l.header_end;
    for (const Layout::Chunk& c : l.chunks) {
      if (c.end <= cut) {
        ++chunks;
        messages = c.messages_before_and_in;
        kept_end = c.end;
      }
    }
    ASSERT_EQ(rep.chunks, chunks);
    ASSERT_EQ(rep.messages, messages);
    EXPECT_EQ(rep.file_size, cut);
    EXPECT_LE(rep.data_end, cut);
    EXPECT_GE(rep.data_end, cut >= l.header_end ? kept_end : 8);
    EXPECT_EQ(rep.complete, cut >= l.data_end_end);
    EXPECT_EQ(rep.stopped.empty(), rep.complete);
    if (!rep.complete) {
      EXPECT_NE(rep.stopped.find("cut.mcap: offset "), std::string::npos);
    }
    const std::vector<MessageView> got = r.messages(Order::kFile);
    ASSERT_EQ(got.size(), messages);
    for (std::size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i].data, l.payloads[i]) << i;
  }
}

TEST(McapRecovery, RecoverFileWritesAValidIndexedFile) {
  const std::array<std::string, 3> kTopics{"/a", "/b", "/c"};
  test::TempDir dir;
  const Layout l = write_small(dir / "full.mcap");
  // Mid-way through the fourth chunk.
  const std::size_t cut = l.chunks[3].end - 100;
  test::spit(dir / "cut.mcap", std::string_view(l.file).substr(0, cut));
  const RecoveryReport rep = recover_file(dir / "cut.mcap", dir / "fixed.mcap");
  EXPECT_EQ(rep.chunks, 3u);
  EXPECT_EQ(rep.messages, l.chunks[2].messages_before_and_in);
  EXPECT_GE(rep.data_end, l.chunks[2].end);  // the third chunk and its Message Indexes
  EXPECT_LE(rep.data_end, cut);
  EXPECT_FALSE(rep.complete);

  const McapReader fixed = McapReader::open(dir / "fixed.mcap");
  EXPECT_TRUE(fixed.indexed());
  EXPECT_TRUE(fixed.validate().empty());
  EXPECT_EQ(fixed.statistics()->message_count, rep.messages);
  ASSERT_EQ(fixed.channels().size(), 3u);
  EXPECT_EQ(fixed.channels().at(2).metadata.at("rate"), "1000");
  EXPECT_EQ(fixed.schemas().at(1).data, "descriptor");
  const std::vector<MessageView> got = fixed.messages(Order::kFile);
  ASSERT_EQ(got.size(), rep.messages);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].data, l.payloads[i]);
    EXPECT_EQ(got[i].log_time_ns, 1000 + i);
    EXPECT_EQ(got[i].sequence, i / 3) << "per-channel sequence kept";
    EXPECT_EQ(got[i].channel->topic, kTopics[i % 3]);
  }
}

TEST(McapRecovery, RecoverFileReportsBothPassesInBytes) {
  test::TempDir dir;
  const Layout l = write_small(dir / "full.mcap");
  const std::size_t cut = l.chunks[3].end - 100;
  test::spit(dir / "cut.mcap", std::string_view(l.file).substr(0, cut));
  // The top-level records wholly before the cut, by the test's own walk: where the scan is
  // after each, and the offsets of the chunks (the copy goes chunk by chunk).
  std::vector<std::uint64_t> record_ends;
  std::vector<std::uint64_t> chunk_starts;
  for (const test::Rec& r : test::walk(l.file)) {
    if (r.end() > cut) break;
    if (r.op != 0x01) record_ends.push_back(r.end());  // the Header is not a step of the scan
    if (r.op == 0x06) chunk_starts.push_back(r.offset);
  }
  std::vector<std::pair<std::uint64_t, std::uint64_t>> scanned;
  std::vector<std::pair<std::uint64_t, std::uint64_t>> copied;
  const RecoveryReport rep = recover_file(
      dir / "cut.mcap", dir / "fixed.mcap",
      [&](std::uint64_t done, std::uint64_t total) { scanned.emplace_back(done, total); },
      [&](std::uint64_t done, std::uint64_t total) { copied.emplace_back(done, total); });
  // The scan: after each record, of the damaged file's size, up to where the data is whole.
  ASSERT_EQ(scanned.size(), record_ends.size());
  for (std::size_t i = 0; i < scanned.size(); ++i) {
    EXPECT_EQ(scanned[i].first, record_ends[i]) << i;
    EXPECT_EQ(scanned[i].second, cut) << i;
  }
  EXPECT_EQ(scanned.back().first, rep.data_end);
  // The copy: each kept message at its chunk's offset, of data_end, then data_end itself.
  ASSERT_EQ(copied.size(), rep.messages + 1);
  for (std::size_t i = 0; i + 1 < copied.size(); ++i) {
    const std::size_t m = i + 1;  // messages so far: the chunk holding the i-th is the first
                                  // whose messages_before_and_in reaches m
    std::size_t chunk = 0;
    while (l.chunks[chunk].messages_before_and_in < m) ++chunk;
    EXPECT_EQ(copied[i].first, chunk_starts.at(chunk)) << i;
    EXPECT_EQ(copied[i].second, rep.data_end) << i;
  }
  EXPECT_EQ(copied.back(), std::make_pair(rep.data_end, rep.data_end));
}

TEST(McapRecovery, ACorruptChunkStopsRecoveryThere) {
  test::TempDir dir;
  const Layout l = write_small(dir / "full.mcap");
  std::string bad = l.file;
  const std::size_t at = l.chunks[3].end - 10;  // inside the fourth chunk's records
  bad[at] = static_cast<char>(bad[at] ^ 0x20);
  test::spit(dir / "bad.mcap", bad);
  const McapReader r = McapReader::recover(dir / "bad.mcap");
  EXPECT_EQ(r.recovery()->chunks, 3u);
  EXPECT_EQ(r.recovery()->messages, l.chunks[2].messages_before_and_in);
  EXPECT_FALSE(r.recovery()->complete);
  EXPECT_NE(r.recovery()->stopped.find("chunk CRC mismatch"), std::string::npos)
      << r.recovery()->stopped;
  EXPECT_EQ(r.messages().size(), l.chunks[2].messages_before_and_in);
}

TEST(McapRecovery, AZeroFilledTailStopsRecovery) {
  // What a filesystem can show after a crash: the size grew, the data never landed.
  test::TempDir dir;
  const Layout l = write_small(dir / "full.mcap");
  std::string torn = l.file.substr(0, l.chunks[1].end + 3) + std::string(4096, '\0');
  test::spit(dir / "torn.mcap", torn);
  const McapReader r = McapReader::recover(dir / "torn.mcap");
  EXPECT_EQ(r.recovery()->chunks, 2u);
  EXPECT_EQ(r.recovery()->messages, l.chunks[1].messages_before_and_in);
  EXPECT_FALSE(r.recovery()->stopped.empty());
}

TEST(McapRecovery, ACompleteFileRecoversWhole) {
  test::TempDir dir;
  const Layout l = write_small(dir / "full.mcap");
  const McapReader r = McapReader::recover(dir / "full.mcap");
  EXPECT_TRUE(r.recovery()->complete);
  EXPECT_EQ(r.recovery()->stopped, "");
  EXPECT_EQ(r.recovery()->chunks, l.chunks.size());
  EXPECT_EQ(r.recovery()->data_end, l.data_end_end);
  EXPECT_TRUE(r.validate().empty());
  EXPECT_EQ(r.statistics()->message_count, 60u);
}

}  // namespace
}  // namespace teleop::record
