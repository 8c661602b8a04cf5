// Every input the fuzzers found a bug with, and every seed of the corpora, through the same
// harnesses libFuzzer runs (fuzz/harness/), plus each bug fed straight to the parser it broke,
// asserting the clean refusal the parser documents.
//
// fuzz/regressions/<target>/ holds the minimised crashing inputs (scripts/fuzz.sh says where a
// new one was written; minimise it with -minimize_crash=1 and copy it there).
#include <google/protobuf/text_format.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/record/mcap_reader.hpp"
#include "fuzz/harness/fuzz_check.hpp"

namespace {

namespace fs = std::filesystem;
using teleop::record::McapError;
using teleop::record::McapReader;
using teleop::record::MessageView;
using teleop::record::Order;

const fs::path kFuzzDir{TELEOP_FUZZ_DIR};

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

std::vector<fs::path> files_in(const fs::path& dir) {
  std::vector<fs::path> out;
  if (!fs::is_directory(dir)) return out;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.is_regular_file()) out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

struct Target {
  const char* name;
  int (*harness)(const std::uint8_t*, std::size_t);
};

void PrintTo(const Target& target, std::ostream* os) { *os << target.name; }

const Target kTargets[] = {
    {"node_state", teleop::fuzz::node_state},
    {"commands", teleop::fuzz::commands},
    {"config", teleop::fuzz::config},
    {"mcap", teleop::fuzz::mcap},
    {"usb", teleop::fuzz::usb},
};

void replay(const Target& target, const fs::path& dir) {
  for (const fs::path& file : files_in(dir)) {
    SCOPED_TRACE(file.string());
    const std::string bytes = read_bytes(file);
    try {
      EXPECT_EQ(target.harness(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size()),
                0);
    } catch (const std::exception& e) {
      ADD_FAILURE() << file.string() << ": " << e.what();
    }
  }
}

class FuzzInputs : public ::testing::TestWithParam<Target> {};

// The seeds pass the harness's invariants (a seed that fails is a bug, or a stale seed).
TEST_P(FuzzInputs, CorpusPasses) {
  const fs::path dir = kFuzzDir / "corpus" / GetParam().name;
  ASSERT_FALSE(files_in(dir).empty()) << dir << " is empty";
  replay(GetParam(), dir);
}

// Every crash found so far is fixed.
TEST_P(FuzzInputs, RegressionsPass) {
  replay(GetParam(), kFuzzDir / "regressions" / GetParam().name);
}

INSTANTIATE_TEST_SUITE_P(Targets, FuzzInputs, ::testing::ValuesIn(kTargets),
                         [](const ::testing::TestParamInfo<Target>& param) {
                           return std::string(param.param.name);
                         });

// ---- the bugs, each fed to the parser itself ---------------------------------------------

// The messages of `order`, or McapError: either is a clean answer; unsorted is not.
void expect_log_time_order_or_refusal(const McapReader& reader) {
  std::vector<std::uint64_t> times;
  try {
    reader.for_each_message(Order::kLogTime,
                            [&](const MessageView& m) { times.push_back(m.log_time_ns); });
  } catch (const McapError&) {
    return;  // a refusal naming the chunk is fine
  }
  EXPECT_TRUE(std::is_sorted(times.begin(), times.end()))
      << "Order::kLogTime gave " << ::testing::PrintToString(times);
}

class McapFile : public ::testing::Test {
 protected:
  fs::path copy(const std::string& name) {
    const fs::path out = fs::temp_directory_path() /
                         ("teleop_fuzz_regression_" + std::to_string(::getpid()) + "_" + name);
    fs::copy_file(kFuzzDir / "regressions" / "mcap" / name, out,
                  fs::copy_options::overwrite_existing);
    paths_.push_back(out);
    return out;
  }
  void TearDown() override {
    for (const fs::path& p : paths_) fs::remove(p);
  }

 private:
  std::vector<fs::path> paths_{};
};

// fuzz_mcap: a Chunk whose header says message_start_time 34359738368 while its one message is
// at 1000, followed by a Message outside chunks at 1010 (331 bytes, no Data End: recover()).
// recover() indexes the chunk by the start time in its header; the log-time merge opens groups
// by that start, so it gives 1010 then 1000.
TEST_F(McapFile, RecoverWithAChunkStartAfterItsMessagesStillOrdersByLogTime) {
  const McapReader reader =
      McapReader::recover(copy("recover_chunk_start_after_its_messages.mcap"));
  expect_log_time_order_or_refusal(reader);
}

// The same through open() and the summary: a writer's file whose first Chunk Index says
// message_start_time 2000 (its chunk's message is at 1000; summary CRC recomputed).
TEST_F(McapFile, OpenWithAChunkIndexStartAfterItsMessagesStillOrdersByLogTime) {
  const McapReader reader =
      McapReader::open(copy("open_chunk_index_start_after_its_messages.mcap"));
  ASSERT_TRUE(reader.indexed());
  expect_log_time_order_or_refusal(reader);
}

// fuzz_config, on edge values: the loader accepts link times and sample rates whose conversion
// to integer nanoseconds (std::llround(ms * 1e6), std::llround(1e9 / rate_hz) in
// node_loader.cpp) rounds to 0 or overflows int64 (LLONG_MIN on x86-64), so a node gets a loop
// period of 0 or < 0 (PeriodicLoop then throws std::invalid_argument, not a ConfigError naming
// the field), a peer timeout <= 0 (the peer is never fresh) or an engage ramp < 0 (full
// coupling at once instead of the slowest ramp). Either a ConfigError or sane values.
TEST(ConfigRegression, NodeTimesThatDoNotFitNanosecondsAreRefused) {
  using std::chrono::nanoseconds;
  for (const char* name :
       {"node_period_rounds_to_zero.textproto", "node_period_overflows.textproto",
        "peer_timeout_overflows.textproto", "peer_timeout_rounds_to_zero.textproto",
        "engage_ramp_overflows.textproto"}) {
    SCOPED_TRACE(name);
    const std::string text = read_bytes(kFuzzDir / "regressions" / "config" / name);
    for (const auto role : {teleop::transport::Role::kMaster, teleop::transport::Role::kSlave}) {
      try {
        const teleop::config::NodeSetup n =
            teleop::config::to_node_setup(teleop::config::load_config_text(text, name), role);
        EXPECT_GT(n.settings.period, nanoseconds{0});
        EXPECT_GT(n.settings.machine.peer_timeout, nanoseconds{0});
        EXPECT_GE(n.settings.machine.engage_ramp, nanoseconds{0});
      } catch (const teleop::config::ConfigError&) {
        // The clean refusal.
      }
    }
  }
}

// fuzz_config's set_fields invariant: set_fields() is documented to reproduce a configuration
// when its assignments are applied to an empty one, values exactly. apply_override trims the
// value and splits repeated values at commas, so a string with a leading space or a trailing
// tab (fuzz_config found "/var/lib/teleo\t" in supervisor.record_dir, minimised to the empty
// element), a repeated string holding a comma, and an empty element of a repeated string come
// back changed.
TEST(ConfigRegression, SetFieldsReproducesStringsExactlyOrRefusesThem) {
  for (const char* name : {"set_fields_repeated_string_with_comma.textproto",
                           "set_fields_string_with_leading_space.textproto",
                           "set_fields_string_with_trailing_tab.textproto",
                           "set_fields_repeated_empty_string.textproto"}) {
    SCOPED_TRACE(name);
    const teleop::config::LoadedConfig loaded = teleop::config::load_config_text(
        read_bytes(kFuzzDir / "regressions" / "config" / name), name);
    std::vector<teleop::config::FieldAssignment> fields;
    try {
      fields = teleop::config::set_fields(loaded.config);
    } catch (const std::invalid_argument& e) {
      // The documented refusal: it names the field and says why.
      EXPECT_NE(std::string(e.what()).find("cannot be written as PATH=VALUE"), std::string::npos)
          << e.what();
      continue;
    }
    teleop::config::LoadedConfig rebuilt;
    for (const teleop::config::FieldAssignment& f : fields) {
      EXPECT_NO_THROW(teleop::config::apply_override(rebuilt, f.path + "=" + f.value));
    }
    std::string want;
    std::string got;
    google::protobuf::TextFormat::PrintToString(loaded.config, &want);
    google::protobuf::TextFormat::PrintToString(rebuilt.config, &got);
    EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(loaded.config, rebuilt.config))
        << "loaded:\n"
        << want << "rebuilt:\n"
        << got;
  }
}

}  // namespace
