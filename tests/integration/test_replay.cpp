// `teleopctl replay` and `teleopctl identify` on session files written by `teleopctl simulate
// --out FILE.mcap` (issue 5 "Replay and identification"): the real binary, as a user runs it.
// Expected values come from independent paths: the scene's own numbers, `simulate`'s CSV and
// JSON, and the MCAP reader on the original file.
#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <optional>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "common/record/mcap_reader.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/proto_schema.hpp"
#include "common/record/session.hpp"
#include "common/record/session_recorder.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"
#include "tests/integration/cli_harness.hpp"

extern char** environ;

namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using namespace std::chrono_literals;

class TempDir {
 public:
  TempDir() {
    std::string pattern = ::testing::TempDir() + "test_replay_XXXXXX";
    if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  [[nodiscard]] std::string file(const std::string& name) const { return (path_ / name).string(); }

 private:
  fs::path path_;
};

std::string read_text(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

// teleopctl's stdout and stderr, kept apart (the shared CliResult merges or drops stderr).
struct SplitResult {
  int exit_code{-1};
  std::string out{};
  std::string err{};
};

// Runs teleopctl with `args` (no spaces inside an argument), stdout and stderr kept apart.
SplitResult run(const TempDir& dir, const std::string& args) {
  const std::string err_file = dir.file("stderr.txt");
  const teleop::test::CliResult r =
      teleop::test::capture(std::string(TELEOPCTL_PATH) + " " + args + " 2>" + err_file);
  return {r.exit_code, r.out, read_text(err_file)};
}

std::string scene(const char* name) {
  return std::string(TELEOP_SOURCE_DIR) + "/examples/scenes/" + name;
}

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

std::vector<std::string> split(const std::string& s, char sep) {
  std::vector<std::string> parts;
  std::string cur;
  for (const char c : s) {
    if (c == sep) {
      parts.push_back(cur);
      cur.clear();
    } else {
      cur.push_back(c);
    }
  }
  parts.push_back(cur);
  return parts;
}

// A CSV as named columns of strings (numbers parsed where needed).
struct Csv {
  std::vector<std::string> header{};
  std::vector<std::vector<std::string>> rows{};
  [[nodiscard]] std::size_t col(const std::string& name) const {
    for (std::size_t i = 0; i < header.size(); ++i) {
      if (header[i] == name) return i;
    }
    ADD_FAILURE() << "no column " << name;
    return 0;
  }
  [[nodiscard]] double num(std::size_t row, const std::string& name) const {
    return std::stod(rows[row][col(name)]);
  }
};

Csv parse_csv(const std::string& text) {
  Csv csv;
  const std::vector<std::string> lines = lines_of(text);
  if (lines.empty()) return csv;
  csv.header = split(lines[0], ',');
  for (std::size_t i = 1; i < lines.size(); ++i) csv.rows.push_back(split(lines[i], ','));
  return csv;
}

// The sample rate written in a scene file, read from its text (not through the loader).
double scene_rate_hz(const std::string& path) {
  std::smatch m;
  const std::string text = read_text(path);
  const std::regex re(R"((^|\n)sample_rate_hz:\s*([0-9.]+))");
  EXPECT_TRUE(std::regex_search(text, m, re)) << path;
  return std::stod(m[2].str());
}

// A simulated session whose log times are simulated time (--log-start-ns 0): these tests
// compare log times with the simulation's clock. By default a session starts at the wall clock
// (checked by ctest -R replay.simulate_mcap_js with the official reader).
std::string simulate_mcap(const TempDir& dir, const std::string& scene_path,
                          const std::string& extra, const std::string& name) {
  const std::string out = dir.file(name);
  const SplitResult r =
      run(dir, "simulate " + scene_path + " " + extra + " --log-start-ns 0 --out " + out);
  EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 3) << r.out << r.err;
  EXPECT_TRUE(fs::exists(out)) << r.err;
  return out;
}

// --- summary, CSV, print ---------------------------------------------------------------------

TEST(Replay, SummaryCountsWhatSimulateWrote) {
  const TempDir dir;
  const std::string path = scene("paddles_master_fixture.textproto");
  const double duration_s = 3.0;
  const double rate = scene_rate_hz(path);
  const std::string file = simulate_mcap(dir, path, "--duration 3", "s.mcap");
  const auto cycles = static_cast<std::uint64_t>(std::llround(duration_s * rate));
  const std::uint64_t per_side = (cycles + 19) / 20;  // 20 cycles per Telemetry message

  const SplitResult r = run(dir, "replay " + file + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_NEAR(j["duration_s"].get<double>(), duration_s, 1e-9);
  // Both nodes' batches, each cycle once more on its node's /cycle channel (issue 17), the
  // configuration and the report.
  EXPECT_EQ(j["messages"].get<std::uint64_t>(), 2 * per_side + 2 * cycles + 2);
  std::map<std::string, std::pair<std::uint64_t, std::string>> channels;
  for (const json& c : j["channels"]) {
    channels[c["topic"].get<std::string>()] = {c["messages"].get<std::uint64_t>(),
                                               c["schema"].get<std::string>()};
  }
  using P = std::pair<std::uint64_t, std::string>;
  EXPECT_EQ(channels["/config"], (P{1, "teleop.v1.SystemConfig"}));
  EXPECT_EQ(channels["/supervisor/stability"], (P{1, "teleop.v1.StabilityReport"}));
  EXPECT_EQ(channels["/master/telemetry"], (P{per_side, "teleop.v1.Telemetry"}));
  EXPECT_EQ(channels["/slave/telemetry"], (P{per_side, "teleop.v1.Telemetry"}));
  EXPECT_EQ(channels["/master/cycle"], (P{cycles, "teleop.v1.CycleRecord"}));
  EXPECT_EQ(channels["/slave/cycle"], (P{cycles, "teleop.v1.CycleRecord"}));
  for (const char* side : {"master", "slave"}) {
    const json& n = j["nodes"][side];
    EXPECT_EQ(n["cycles"].get<std::uint64_t>(), cycles) << side;
    EXPECT_EQ(n["cycles_missing"].get<std::uint64_t>(), 0U) << side;
    EXPECT_EQ(n["first_sequence"].get<std::uint64_t>(), 1U) << side;
    EXPECT_EQ(n["last_sequence"].get<std::uint64_t>(), cycles) << side;
    EXPECT_EQ(n["modes"]["ENGAGED"].get<std::uint64_t>(), cycles) << side;
  }
  EXPECT_EQ(j["alarms"]["count"].get<std::size_t>(), 0U);
  EXPECT_TRUE(j["parameter_changes"].empty());
  EXPECT_TRUE(j["recorder_drops"].is_null());
  ASSERT_EQ(j["stability"].size(), 1U);

  // The text form says the same.
  const SplitResult text = run(dir, "replay " + file);
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find(std::to_string(cycles) + " cycles (sequences 1.." +
                          std::to_string(cycles) + "), 0 missing"),
            std::string::npos)
      << text.out;
  EXPECT_NE(text.out.find("recorder drops: unknown"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("stability: 1 report"), std::string::npos) << text.out;
}

// The soak report's histograms (issue 7): wake-up latency of every recorded cycle and the
// deadlines the loop skipped per second, from a file whose cycles are laid out here by hand:
// three seconds on a 1 ms grid from t = 10 s, with gaps of known size put into the grid.
TEST(Replay, SummaryHistogramsAreTheRecordedWakeUpLatenciesAndSkippedDeadlines) {
  const TempDir dir;
  const fs::path file = dir.file("hist.mcap");
  std::vector<std::int64_t> latencies;  // what was written, in order
  std::map<std::int64_t, std::uint64_t> skipped_per_second;
  {
    teleop::record::McapWriter w(file);
    const std::uint16_t schema =
        w.add_schema(teleop::record::protobuf_schema(teleop::v1::Telemetry::descriptor()));
    const std::uint16_t channel = w.add_channel({schema, "/master/telemetry", "protobuf", {}});
    teleop::v1::Telemetry t;
    std::int64_t time_ns = 10'000'000'000;
    std::uint64_t sequence = 1;
    // Gaps (in periods) before given cycles: second 10 one gap of 3 periods (2 skipped), second
    // 11 fifteen gaps of 2 periods (1 skipped each), second 12 none.
    std::map<std::uint64_t, int> gap_before = {{500, 3}};
    for (int k = 0; k < 15; ++k) gap_before[1200 + 40 * static_cast<std::uint64_t>(k)] = 2;
    while (time_ns < 13'000'000'000) {
      teleop::v1::CycleRecord* c = t.add_cycles();
      c->set_sequence(sequence);
      c->set_sample_time_ns(time_ns);
      c->set_mode(teleop::v1::ENGAGED);
      // 1 % of cycles 1.5 ms late, 9 % 120 us, the rest 30 us.
      const std::int64_t late =
          sequence % 100 == 0 ? 1'500'000 : (sequence % 10 == 0 ? 120'000 : 30'000);
      c->set_wakeup_latency_ns(late);
      latencies.push_back(late);
      ++sequence;
      const auto g = gap_before.find(sequence);
      const int periods = g == gap_before.end() ? 1 : g->second;
      time_ns += periods * 1'000'000;
      if (periods > 1 && time_ns < 13'000'000'000) {
        skipped_per_second[time_ns / 1'000'000'000] += static_cast<std::uint64_t>(periods - 1);
      }
      if (t.cycles_size() == 20) {
        t.set_session_id(7);
        t.mutable_loop()->set_period_s(0.001);
        ASSERT_TRUE(w.write(channel, static_cast<std::uint64_t>(time_ns), t.SerializeAsString()));
        t.Clear();
      }
    }
    if (t.cycles_size() > 0) {
      t.set_session_id(7);
      t.mutable_loop()->set_period_s(0.001);
      ASSERT_TRUE(w.write(channel, static_cast<std::uint64_t>(time_ns), t.SerializeAsString()));
    }
    ASSERT_TRUE(w.close()) << w.error();
  }
  ASSERT_EQ(skipped_per_second[10], 2u);
  ASSERT_EQ(skipped_per_second[11], 15u);

  const SplitResult r = run(dir, "replay " + file.string() + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(r.out);
  const json& n = j["nodes"]["master"];
  // Latency: counts per bin from the list written, quantiles by nearest rank on it.
  std::vector<std::int64_t> sorted = latencies;
  std::sort(sorted.begin(), sorted.end());
  const auto rank_us = [&](double q) {
    return static_cast<double>(
               sorted[static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size()))) -
                      1]) *
           1e-3;
  };
  const json& w = n["wakeup_latency"];
  EXPECT_DOUBLE_EQ(w["p50_us"].get<double>(), 30.0);
  EXPECT_DOUBLE_EQ(w["p99_us"].get<double>(), rank_us(0.99));
  EXPECT_DOUBLE_EQ(w["p999_us"].get<double>(), 1500.0);
  EXPECT_DOUBLE_EQ(w["max_us"].get<double>(), 1500.0);
  const auto count = [&](std::int64_t v) {
    return static_cast<std::uint64_t>(std::count(latencies.begin(), latencies.end(), v));
  };
  std::map<std::int64_t, std::uint64_t> bins;
  for (const json& b : w["histogram"]) {
    bins[b["from_us"].get<std::int64_t>()] = b["cycles"].get<std::uint64_t>();
  }
  EXPECT_EQ(bins[0], count(30'000));        // [0, 50) us
  EXPECT_EQ(bins[100], count(120'000));     // [100, 200) us
  EXPECT_EQ(bins[1000], count(1'500'000));  // [1, 2) ms
  EXPECT_EQ(bins[50] + bins[200] + bins[500] + bins[2000] + bins[5000], 0u);
  // Overruns: 17 skipped deadlines; seconds 10 (2 skipped), 11 (15) and 12 (none).
  const json& o = n["overruns"];
  EXPECT_EQ(o["total"].get<std::uint64_t>(), 17u);
  EXPECT_EQ(o["seconds"].get<std::uint64_t>(), 3u);
  EXPECT_EQ(o["worst_second"].get<std::uint64_t>(), 15u);
  std::map<std::uint64_t, std::uint64_t> seconds;
  for (const json& b : o["seconds_histogram"]) {
    seconds[b["from"].get<std::uint64_t>()] = b["seconds"].get<std::uint64_t>();
  }
  EXPECT_EQ(seconds[0], 1u);  // second 12
  EXPECT_EQ(seconds[1], 0u);
  EXPECT_EQ(seconds[2], 1u);   // 2-9: second 10
  EXPECT_EQ(seconds[10], 1u);  // 10-99: second 11
  EXPECT_EQ(seconds[100], 0u);
  EXPECT_EQ(n["cycles_missing"].get<std::uint64_t>(), 0u);
  EXPECT_TRUE(j["nodes"]["slave"]["wakeup_latency"].is_null());

  // The text form gives the same lines.
  const SplitResult text = run(dir, "replay " + file.string());
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("master overruns 17 in 3 s (worst second 15); seconds by overruns: 0 1, "
                          "1 0, 2-9 1, 10-99 1, >=100 0"),
            std::string::npos)
      << text.out;
  EXPECT_NE(text.out.find("master wake-up latency p50 30 us"), std::string::npos) << text.out;
}

TEST(Replay, CsvRowsAreTheCyclesAndEqualTheSimulateCsv) {
  const TempDir dir;
  const std::string path = scene("paddles_master_fixture.textproto");
  const double rate = scene_rate_hz(path);
  // One sample of round trip: the slave sees the master's state one cycle late.
  const std::string extra = "--duration 2 --set round_trip_delay_samples=1";
  const std::string file = simulate_mcap(dir, path, extra, "s.mcap");
  const std::string sim_csv_path = dir.file("s.csv");
  ASSERT_EQ(run(dir, "simulate " + path + " " + extra + " --out " + sim_csv_path).exit_code, 0);
  const Csv sim = parse_csv(read_text(sim_csv_path));
  const std::size_t n = sim.rows.size();
  ASSERT_EQ(n, static_cast<std::size_t>(std::llround(2.0 * rate)));

  const SplitResult r = run(dir, "replay " + file + " --csv");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Csv rep = parse_csv(r.out);
  ASSERT_EQ(rep.rows.size(), 2 * n);
  // --out writes the same bytes to a file.
  const std::string out_csv = dir.file("r.csv");
  ASSERT_EQ(run(dir, "replay " + file + " --csv --out " + out_csv).exit_code, 0);
  EXPECT_EQ(read_text(out_csv), r.out);

  // Row k of the simulation is written after its physics step: its *_sensed_m are what the
  // laws read at sample k, its *_force_N the laws' outputs at k, and its human and environment
  // forces the true forces at the step's end, which the load cells read at sample k + 1.
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t m = k;      // master rows first
    const std::size_t s = n + k;  // then the slave's
    ASSERT_EQ(rep.rows[m][rep.col("node")], "master");
    ASSERT_EQ(rep.rows[s][rep.col("node")], "slave");
    EXPECT_EQ(rep.num(m, "sequence"), static_cast<double>(k + 1));
    EXPECT_EQ(rep.num(s, "sequence"), static_cast<double>(k + 1));
    EXPECT_EQ(rep.rows[m][rep.col("mode")], "ENGAGED");
    EXPECT_NEAR(rep.num(m, "time_s"), sim.num(k, "time_s") - 1.0 / rate, 1e-9) << k;
    EXPECT_NEAR(rep.num(s, "time_s"), sim.num(k, "time_s") - 1.0 / rate, 1e-9) << k;
    EXPECT_EQ(rep.num(m, "position_m"), sim.num(k, "master_sensed_m")) << k;
    EXPECT_EQ(rep.num(s, "position_m"), sim.num(k, "slave_sensed_m")) << k;
    // The master's actuator is driven by -F_am (docs/architecture.md §2.1); the slave's by F_as.
    EXPECT_EQ(rep.num(m, "command_N"), -sim.num(k, "master_force_N")) << k;
    EXPECT_EQ(rep.num(s, "command_N"), sim.num(k, "slave_force_N")) << k;
    EXPECT_EQ(rep.num(m, "peer_position_m"), sim.num(k, "slave_sensed_m")) << k;
    if (k >= 1) {
      EXPECT_EQ(rep.num(m, "force_N"), sim.num(k - 1, "human_force_N")) << k;
      EXPECT_EQ(rep.num(s, "force_N"), sim.num(k - 1, "environment_force_N")) << k;
      EXPECT_EQ(rep.num(s, "peer_position_m"), sim.num(k - 1, "master_sensed_m")) << k;
      EXPECT_EQ(rep.num(s, "peer_sequence"), static_cast<double>(k)) << k;
    }
    EXPECT_EQ(rep.num(m, "round_trip_ns"), 1e9 / rate) << k;
  }
}

TEST(Replay, PrintsTheStabilityReportTheAnalyserGives) {
  const TempDir dir;
  const std::string path = scene("paddles_slave_fixture_unstable.textproto");
  const std::string file = simulate_mcap(dir, path, "--duration 1", "u.mcap");
  const SplitResult sim = run(dir, "simulate " + path + " --duration 1 --json");
  const json predicted = json::parse(sim.out)["predicted"];

  const SplitResult r = run(dir, "replay " + file + " --print /supervisor/stability --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::vector<std::string> lines = lines_of(r.out);
  ASSERT_EQ(lines.size(), 1U) << r.out;
  const json j = json::parse(lines[0]);
  EXPECT_EQ(j["log_time_ns"].get<std::uint64_t>(), 0U);
  EXPECT_EQ(j["message"]["verdict"], predicted["verdict"]);
  EXPECT_EQ(j["message"]["verdict"], "unstable");
  EXPECT_NEAR(j["message"]["min_damping_ratio"].get<double>(),
              predicted["min_damping_ratio"].get<double>(), 1e-12);
  EXPECT_EQ(j["message"]["slave_fixture_stiffness_N_per_m"].get<double>(), 4000.0);

  const SplitResult text = run(dir, "replay " + file + " --print /supervisor/stability");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  ASSERT_EQ(lines_of(text.out).size(), 1U);
  EXPECT_EQ(text.out.rfind("0.000000000 { verdict: \"unstable\"", 0), 0U) << text.out;

  // Every telemetry message prints, one line each.
  const SplitResult tel = run(dir, "replay " + file + " --print /slave/telemetry --json");
  ASSERT_EQ(tel.exit_code, 0) << tel.err;
  EXPECT_EQ(lines_of(tel.out).size(), static_cast<std::size_t>(500 / 20));
}

TEST(Replay, ErrorsNameTheFileAndWhatIsWrong) {
  const TempDir dir;
  const std::string file =
      simulate_mcap(dir, scene("paddles_slave_fixture_stable.textproto"), "--duration 1", "s.mcap");
  SplitResult r = run(dir, "replay " + file + " --print /nope");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(file + ": no channel '/nope' (channels: /config,"), std::string::npos)
      << r.err;

  const std::string csv = dir.file("x.csv");
  std::ofstream(csv) << "time_s,x\n0,1\n";
  r = run(dir, "replay " + csv);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(csv + ": offset 0: not an MCAP file"), std::string::npos) << r.err;

  const std::string cut = dir.file("cut.mcap");
  fs::copy_file(file, cut);
  fs::resize_file(cut, fs::file_size(file) / 2);
  r = run(dir, "replay " + cut);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(cut + ": offset"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--recover"), std::string::npos) << r.err;

  r = run(dir, "replay " + dir.file("missing.mcap"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.mcap: no such file"), std::string::npos) << r.err;

  EXPECT_EQ(run(dir, "replay").exit_code, 2);
  EXPECT_EQ(run(dir, "replay " + file + " --speed 0").exit_code, 2);
  EXPECT_EQ(run(dir, "replay " + file + " --csv --resimulate").exit_code, 2);
  EXPECT_EQ(run(dir, "replay " + file + " --bogus").exit_code, 2);
  const SplitResult help = run(dir, "replay --help");
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_EQ(help.out.rfind("usage: teleopctl replay", 0), 0U) << help.out;
}

// --- recovery --------------------------------------------------------------------------------

TEST(Replay, RecoverKeepsExactlyTheCompleteChunks) {
  const TempDir dir;
  // 20 s at 1 kHz: several 256 KiB chunks.
  const std::string file =
      simulate_mcap(dir, scene("paddles_master_fixture.textproto"), "--duration 20", "long.mcap");
  const teleop::record::McapReader original = teleop::record::McapReader::open(file);
  const std::vector<teleop::record::ChunkIndex>& chunks = original.chunk_indexes();
  ASSERT_GE(chunks.size(), 4U);
  // Cut in the middle of the third chunk.
  const std::uint64_t cut_at = chunks[2].chunk_start_offset + chunks[2].chunk_length / 2;
  const std::string cut = dir.file("cut.mcap");
  fs::copy_file(file, cut);
  fs::resize_file(cut, cut_at);

  struct Kept {
    std::string topic;
    std::uint64_t log_time_ns;
    std::string data;
    bool operator==(const Kept&) const = default;
  };
  std::vector<Kept> expected;
  std::uint64_t expected_chunks = 0;
  for (const auto& c : chunks) {
    if (c.chunk_start_offset + c.chunk_length <= cut_at) ++expected_chunks;
  }
  original.for_each_message(teleop::record::Order::kFile, [&](const auto& m) {
    for (const auto& c : chunks) {
      if (m.record_offset == c.chunk_start_offset &&
          c.chunk_start_offset + c.chunk_length <= cut_at) {
        expected.push_back({m.channel->topic, m.log_time_ns, std::string(m.data)});
      }
    }
  });
  ASSERT_EQ(expected_chunks, 2U);
  ASSERT_FALSE(expected.empty());

  const std::string out = dir.file("recovered.mcap");
  const SplitResult r = run(dir, "replay " + cut + " --recover " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["chunks"].get<std::uint64_t>(), expected_chunks);
  EXPECT_EQ(j["messages"].get<std::uint64_t>(), expected.size());
  EXPECT_EQ(j["data_end"].get<std::uint64_t>(), chunks[2].chunk_start_offset);
  EXPECT_FALSE(j["complete"].get<bool>());

  const teleop::record::McapReader recovered = teleop::record::McapReader::open(out);
  EXPECT_TRUE(recovered.validate().empty());
  std::vector<Kept> got;
  recovered.for_each_message(teleop::record::Order::kFile, [&](const auto& m) {
    got.push_back({m.channel->topic, m.log_time_ns, std::string(m.data)});
  });
  EXPECT_TRUE(got == expected) << got.size() << " vs " << expected.size();

  // The recovered file replays: its summary counts the cycles of the kept telemetry.
  const SplitResult text = run(dir, "replay " + cut + " --recover " + dir.file("again.mcap"));
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(
      text.out.find("kept 2 complete chunks, " + std::to_string(expected.size()) + " messages"),
      std::string::npos)
      << text.out;
  EXPECT_EQ(run(dir, "replay " + out).exit_code, 0);
}

// --- live re-publication -----------------------------------------------------------------------

// A loopback endpoint on a port the kernel just gave out.
std::string free_endpoint() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  EXPECT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)), 0);
  socklen_t len = sizeof(a);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return "tcp://127.0.0.1:" + std::to_string(ntohs(a.sin_port));
}

// A child process with its stdout and stderr in files.
class Child {
 public:
  Child(const std::vector<std::string>& args, const std::string& out_file) {
    std::vector<char*> argv;
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 1, out_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, 1, 2);
    if (posix_spawn(&pid_, argv[0], &fa, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
  }
  ~Child() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      int status = 0;
      waitpid(pid_, &status, 0);
    }
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  [[nodiscard]] bool started() const { return pid_ > 0; }
  // Waits until the process exits or `timeout`; its exit code, or nothing.
  std::optional<int> wait(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
      }
      std::this_thread::sleep_for(5ms);  // polling the exit, bounded by the deadline
    }
    return std::nullopt;
  }

 private:
  pid_t pid_{-1};
  bool exited_{false};
};

struct Status {
  std::string state{};
  double position_s{-1.0};
  std::map<std::string, std::uint64_t> sent{};
  std::map<std::string, std::uint64_t> subscriptions{};
};

Status parse_status(const std::string& reply) {
  Status s;
  std::smatch m;
  static const std::regex re(
      R"(^(\w+) at ([0-9.]+) s of [0-9.]+ s; speed [0-9.e+]+; sent \d+ messages, the file has )"
      R"(\d+: master=(\d+) slave=(\d+) report=(\d+) alarm=(\d+); subscriptions: )"
      R"(master=(\d+) slave=(\d+) report=(\d+)$)");
  if (!std::regex_match(reply, m, re)) {
    ADD_FAILURE() << "unexpected reply: " << reply;
    return s;
  }
  s.state = m[1].str();
  s.position_s = std::stod(m[2].str());
  s.sent = {{"master", std::stoull(m[3].str())},
            {"slave", std::stoull(m[4].str())},
            {"report", std::stoull(m[5].str())},
            {"alarm", std::stoull(m[6].str())}};
  s.subscriptions = {{"master", std::stoull(m[7].str())},
                     {"slave", std::stoull(m[8].str())},
                     {"report", std::stoull(m[9].str())}};
  return s;
}

TEST(Replay, SpeedRepublishesInOrderAndObeysPauseAndSeek) {
  const TempDir dir;
  const std::string file =
      simulate_mcap(dir, scene("paddles_master_fixture.textproto"), "--duration 10", "live.mcap");
  // What was recorded on the master's channel, in log-time order (the reader, not the replay).
  std::vector<std::pair<std::uint64_t, std::string>> recorded;
  std::string report_bytes;
  {
    const auto reader = teleop::record::McapReader::open(file);
    reader.for_each_message(teleop::record::Order::kLogTime, [&](const auto& m) {
      if (m.channel->topic == "/master/telemetry") recorded.emplace_back(m.log_time_ns, m.data);
      if (m.channel->topic == "/supervisor/stability") report_bytes = m.data;
    });
  }
  ASSERT_EQ(recorded.size(), 500U);

  // Free ports of this run (teleopctl launch's defaults are 5560-5568).
  const std::string master_ep = free_endpoint();
  const std::string slave_ep = free_endpoint();
  const std::string report_ep = free_endpoint();
  const std::string control_ep = free_endpoint();
  Child child(
      {TELEOPCTL_PATH, "replay", file, "--speed", "10", "--paused", "--control", control_ep,
       "--master-telemetry", master_ep, "--slave-telemetry", slave_ep, "--report", report_ep},
      dir.file("replay.out"));
  ASSERT_TRUE(child.started());

  zmq::context_t ctx(1);
  zmq::socket_t req(ctx, zmq::socket_type::req);
  req.set(zmq::sockopt::linger, 0);
  req.set(zmq::sockopt::rcvtimeo, 10000);
  req.set(zmq::sockopt::sndtimeo, 10000);
  req.connect(control_ep);
  auto ask = [&](const std::string& text) {
    EXPECT_TRUE(req.send(zmq::buffer(text), zmq::send_flags::none));
    zmq::message_t reply;
    const auto got = req.recv(reply);
    EXPECT_TRUE(got.has_value()) << "no reply to '" << text << "'";
    return got ? reply.to_string() : std::string();
  };
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 100000);
  sub.set(zmq::sockopt::subscribe, "");
  sub.connect(master_ep);
  zmq::socket_t reports(ctx, zmq::socket_type::sub);
  reports.set(zmq::sockopt::linger, 0);
  reports.set(zmq::sockopt::subscribe, "report");
  reports.connect(report_ep);
  auto receive = [&](zmq::socket_t& s, std::chrono::milliseconds timeout) {
    std::array<zmq::pollitem_t, 1> item{{{s.handle(), 0, ZMQ_POLLIN, 0}}};
    zmq::poll(item.data(), 1, timeout);
    zmq::message_t msg;
    std::optional<std::string> out;
    if (s.recv(msg, zmq::recv_flags::dontwait)) out = msg.to_string();
    return out;
  };

  // Paused until both subscriptions have reached the replay (no message lost to a late join).
  Status st = parse_status(ask("status"));
  const auto deadline = std::chrono::steady_clock::now() + 10s;
  while ((st.subscriptions["master"] == 0 || st.subscriptions["report"] == 0) &&
         std::chrono::steady_clock::now() < deadline) {
    (void)receive(sub, 10ms);  // nothing is sent while paused: a bounded wait
    st = parse_status(ask("status"));
  }
  ASSERT_EQ(st.state, "paused");
  ASSERT_GE(st.subscriptions["master"], 1U);
  ASSERT_EQ(st.sent["master"], 0U);
  EXPECT_EQ(st.position_s, 0.0);

  st = parse_status(ask("resume"));
  EXPECT_EQ(st.state, "playing");
  // The stability report (log time 0) as supervisor_app publishes it: "report", then the bytes.
  {
    const auto tag = receive(reports, 5000ms);
    ASSERT_TRUE(tag.has_value());
    EXPECT_EQ(*tag, "report");
    const auto body = receive(reports, 5000ms);
    ASSERT_TRUE(body.has_value());
    EXPECT_EQ(*body, report_bytes);
  }
  std::size_t received = 0;
  auto expect_next = [&](const std::string& bytes, std::size_t index) {
    ASSERT_LT(index, recorded.size());
    EXPECT_EQ(bytes, recorded[index].second) << "message " << index;
  };
  while (received < 30) {
    const auto m = receive(sub, 5000ms);
    ASSERT_TRUE(m.has_value()) << "after " << received;
    expect_next(*m, received++);
  }
  Status paused = parse_status(ask("pause"));
  EXPECT_EQ(paused.state, "paused");
  EXPECT_GE(paused.sent["master"], received);
  EXPECT_GT(paused.position_s, 0.0);
  // Everything sent before the pause arrives; nothing after it.
  while (received < paused.sent["master"]) {
    const auto m = receive(sub, 5000ms);
    ASSERT_TRUE(m.has_value()) << "after " << received;
    expect_next(*m, received++);
  }
  EXPECT_EQ(received, paused.sent["master"]);
  Status still = parse_status(ask("status"));
  EXPECT_EQ(still.sent["master"], paused.sent["master"]);
  EXPECT_EQ(still.position_s, paused.position_s);
  EXPECT_FALSE(receive(sub, 0ms).has_value());
  EXPECT_EQ(ask("jump").rfind("error: unknown request 'jump'", 0), 0U);
  EXPECT_NE(ask("speed 20").find("speed 20;"), std::string::npos);
  // Relative requests (what the console's keys send): a factor on the speed in force, and a
  // seek from the position in force, clamped to the file's 0..10 s.
  EXPECT_NE(ask("speed x0.5").find("speed 10;"), std::string::npos);
  EXPECT_NE(ask("speed x0.5").find("speed 5;"), std::string::npos);
  EXPECT_NE(ask("speed x4").find("speed 20;"), std::string::npos);
  EXPECT_EQ(ask("speed x0").rfind("error: speed: must be positive", 0), 0U);
  EXPECT_EQ(parse_status(ask("seek 3")).position_s, 3.0);
  EXPECT_EQ(parse_status(ask("seek +2")).position_s, 5.0);
  EXPECT_EQ(parse_status(ask("seek -1.5")).position_s, 3.5);
  EXPECT_EQ(parse_status(ask("seek -30")).position_s, 0.0);
  EXPECT_EQ(parse_status(ask("seek +30")).position_s, 10.0);

  // Seek to 6 s: playback continues with the first message logged at or after 6 s.
  Status seek = parse_status(ask("seek 6"));
  EXPECT_EQ(seek.position_s, 6.0);
  EXPECT_EQ(seek.state, "paused");
  std::size_t index = 0;
  while (index < recorded.size() && recorded[index].first < 6'000'000'000ULL) ++index;
  ASSERT_LT(index, recorded.size());
  EXPECT_EQ(parse_status(ask("resume")).state, "playing");
  const std::size_t after_seek = recorded.size() - index;
  for (std::size_t i = 0; i < after_seek; ++i) {
    const auto m = receive(sub, 5000ms);
    ASSERT_TRUE(m.has_value()) << "after seek, message " << i;
    expect_next(*m, index + i);
    if (i == 0) {
      teleop::v1::Telemetry t;
      ASSERT_TRUE(t.ParseFromString(*m));
      // Logged at the end of its last cycle's period: cycles 5981..6000 at 1 kHz.
      EXPECT_EQ(t.cycles(0).sequence(), 5981U);
    }
  }
  // At the end the replay exits by itself and says so.
  const std::optional<int> code = child.wait(30s);
  ASSERT_TRUE(code.has_value());
  EXPECT_EQ(*code, 0);
  const std::string out = read_text(dir.file("replay.out"));
  EXPECT_NE(out.find("finished at 10.000000 s"), std::string::npos) << out;
}

// --- the summary stream of a replay
// ---------------------------------------------------------------

// A session file read with the MCAP reader (not through the replay): its log-time span, the
// telemetry of both nodes and its stability report.
struct RecordedSession {
  std::uint64_t first_ns{UINT64_MAX};
  std::uint64_t last_ns{0};
  std::vector<std::pair<std::uint64_t, teleop::v1::Telemetry>> master{};
  std::vector<std::pair<std::uint64_t, teleop::v1::Telemetry>> slave{};
  std::string report_bytes{};
  [[nodiscard]] double duration_s() const { return static_cast<double>(last_ns - first_ns) * 1e-9; }
};

RecordedSession read_session(const std::string& file) {
  RecordedSession r;
  const auto reader = teleop::record::McapReader::open(file);
  reader.for_each_message(teleop::record::Order::kLogTime, [&](const auto& m) {
    r.first_ns = std::min(r.first_ns, m.log_time_ns);
    r.last_ns = std::max(r.last_ns, m.log_time_ns);
    const std::string& topic = m.channel->topic;
    if (topic == "/master/telemetry" || topic == "/slave/telemetry") {
      teleop::v1::Telemetry t;
      EXPECT_TRUE(t.ParseFromArray(m.data.data(), static_cast<int>(m.data.size())));
      (topic == "/master/telemetry" ? r.master : r.slave).emplace_back(m.log_time_ns, t);
    }
    if (topic == "/supervisor/stability") r.report_bytes = m.data;
  });
  return r;
}

// The newest telemetry message logged at or before `log_time_ns`.
const teleop::v1::Telemetry* newest_at_or_before(
    const std::vector<std::pair<std::uint64_t, teleop::v1::Telemetry>>& messages,
    std::uint64_t log_time_ns) {
  const teleop::v1::Telemetry* newest = nullptr;
  for (const auto& [t, m] : messages) {
    if (t <= log_time_ns) newest = &m;
  }
  return newest;
}

// `teleopctl replay FILE --speed X --paused` on free ports, with a control client and a
// subscriber to the summary stream ("status" on the report endpoint).
class PausedReplay {
 public:
  PausedReplay(const TempDir& dir, const std::string& file, const std::string& speed)
      : control_ep_(free_endpoint()),
        report_ep_(free_endpoint()),
        child_({TELEOPCTL_PATH, "replay", file, "--speed", speed, "--paused", "--control",
                control_ep_, "--master-telemetry", free_endpoint(), "--slave-telemetry",
                free_endpoint(), "--report", report_ep_},
               dir.file("replay.out")) {
    req_.set(zmq::sockopt::linger, 0);
    req_.set(zmq::sockopt::rcvtimeo, 10000);
    req_.set(zmq::sockopt::sndtimeo, 10000);
    req_.connect(control_ep_);
    sub_.set(zmq::sockopt::linger, 0);
    sub_.set(zmq::sockopt::subscribe, "status");
    sub_.connect(report_ep_);
  }
  ~PausedReplay() {
    if (child_.started()) {
      (void)ask("stop");
      (void)child_.wait(10s);
    }
  }
  PausedReplay(const PausedReplay&) = delete;
  PausedReplay& operator=(const PausedReplay&) = delete;

  [[nodiscard]] bool started() const { return child_.started(); }
  [[nodiscard]] const std::string& control_endpoint() const { return control_ep_; }

  std::string ask(const std::string& text) {
    if (!req_.send(zmq::buffer(text), zmq::send_flags::none)) return {};
    zmq::message_t reply;
    return req_.recv(reply) ? reply.to_string() : std::string();
  }

  // The first summary that `accept` takes, within `timeout` (older ones are passed over).
  template <typename Accept>
  std::optional<teleop::v1::SupervisorStatus> status_where(Accept accept,
                                                           std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left.count() <= 0) return std::nullopt;
      std::array<zmq::pollitem_t, 1> item{{{sub_.handle(), 0, ZMQ_POLLIN, 0}}};
      zmq::poll(item.data(), 1, left);
      zmq::message_t tag;
      if (!sub_.recv(tag, zmq::recv_flags::dontwait)) continue;
      EXPECT_EQ(tag.to_string(), "status");
      EXPECT_TRUE(sub_.get(zmq::sockopt::rcvmore)) << "a status without its message";
      zmq::message_t body;
      if (!sub_.recv(body, zmq::recv_flags::none)) return std::nullopt;
      teleop::v1::SupervisorStatus st;
      EXPECT_TRUE(st.ParseFromArray(body.data(), static_cast<int>(body.size())));
      if (accept(st)) return st;
    }
  }

 private:
  std::string control_ep_;
  std::string report_ep_;
  Child child_;
  zmq::context_t ctx_{1};
  zmq::socket_t req_{ctx_, zmq::socket_type::req};
  zmq::socket_t sub_{ctx_, zmq::socket_type::sub};
};

TEST(ReplayStatusStream, PausedReplayPublishesItsPositionAndTheRecordedReport) {
  const TempDir dir;
  const std::string file = simulate_mcap(dir, scene("paddles_slave_fixture_unstable.textproto"),
                                         "--duration 4", "u.mcap");
  const RecordedSession rec = read_session(file);
  ASSERT_FALSE(rec.master.empty());
  ASSERT_FALSE(rec.report_bytes.empty());
  teleop::v1::StabilityReport report;
  ASSERT_TRUE(report.ParseFromString(rec.report_bytes));

  PausedReplay replay(dir, file, "2");
  ASSERT_TRUE(replay.started());
  const auto st = replay.status_where([](const auto&) { return true; }, 10s);
  ASSERT_TRUE(st.has_value()) << "no summary on the report endpoint within 10 s";
  EXPECT_EQ(st->source(), "replay");
  EXPECT_FALSE(st->client_may_command());
  ASSERT_TRUE(st->has_replay());
  EXPECT_EQ(st->replay().file(), file);
  EXPECT_EQ(st->replay().state(), "paused");
  EXPECT_NEAR(st->replay().position_s(), 0.0, 1e-9);
  EXPECT_NEAR(st->replay().duration_s(), rec.duration_s(), 1e-9);
  EXPECT_EQ(st->replay().speed(), 2.0);
  EXPECT_EQ(st->replay().control_endpoint(), replay.control_endpoint());
  EXPECT_EQ(st->time_ns(), static_cast<std::int64_t>(rec.first_ns));
  // The report logged at the start is in force from position 0; no alarm was recorded.
  ASSERT_TRUE(st->has_report());
  EXPECT_EQ(st->report().SerializeAsString(), rec.report_bytes);
  EXPECT_EQ(st->recent_alarms_size(), 0);
  // `simulate` records no supervisor status: no recording to speak of.
  EXPECT_EQ(st->recording_file(), "");

  // The stream goes on while paused, and the control reply text is unchanged.
  const auto again =
      replay.status_where([&](const auto& s) { return s.replay().state() == "paused"; }, 5s);
  ASSERT_TRUE(again.has_value());
  EXPECT_NEAR(again->replay().position_s(), 0.0, 1e-9);
  EXPECT_EQ(parse_status(replay.ask("status")).state, "paused");
}

TEST(ReplayStatusStream, SeekShowsTheNodesAsRecordedAtThatPosition) {
  const TempDir dir;
  // The unstable slave fixture: both paddles move, so each message's last cycle differs.
  const std::string file = simulate_mcap(dir, scene("paddles_slave_fixture_unstable.textproto"),
                                         "--duration 4", "u.mcap");
  const RecordedSession rec = read_session(file);
  PausedReplay replay(dir, file, "1");
  ASSERT_TRUE(replay.started());
  ASSERT_TRUE(replay.status_where([](const auto&) { return true; }, 10s).has_value());

  // Forward to between two messages, then back to exactly a message's log time.
  for (const double s : {2.51, 1.0}) {
    SCOPED_TRACE(s);
    const Status reply = parse_status(replay.ask("seek " + std::to_string(s)));
    EXPECT_EQ(reply.state, "paused");
    EXPECT_EQ(reply.position_s, s);
    const auto st = replay.status_where(
        [&](const auto& x) { return std::abs(x.replay().position_s() - s) < 1e-9; }, 5s);
    ASSERT_TRUE(st.has_value()) << "no summary at the new position within 5 s";
    EXPECT_EQ(st->replay().state(), "paused");
    const std::uint64_t at_ns = rec.first_ns + static_cast<std::uint64_t>(std::llround(s * 1e9));
    EXPECT_EQ(st->time_ns(), static_cast<std::int64_t>(at_ns));
    for (const bool master : {true, false}) {
      SCOPED_TRACE(master ? "master" : "slave");
      const teleop::v1::Telemetry* t = newest_at_or_before(master ? rec.master : rec.slave, at_ns);
      ASSERT_NE(t, nullptr);
      ASSERT_GT(t->cycles_size(), 0);
      const teleop::v1::NodeSummary& n = master ? st->master() : st->slave();
      EXPECT_EQ(n.position_m(), t->cycles(t->cycles_size() - 1).position_m());
      EXPECT_EQ(n.force_n(), t->cycles(t->cycles_size() - 1).force_n());
      EXPECT_EQ(n.mode(), t->mode());
      // Alive: its clock is the recorded one, so a paused replay does not look dead.
      EXPECT_TRUE(n.alive());
      EXPECT_EQ(master ? st->master_alive() : st->slave_alive(), true);
    }
    // Position 0's report is still in force after a seek back.
    EXPECT_EQ(st->report().SerializeAsString(), rec.report_bytes);
  }
}

// --- identification and resimulation ----------------------------------------------------------

// A band-limited random push (0.5-10 Hz), seeded.
std::vector<double> random_push(std::uint64_t seed, std::size_t n, double period_s, double rms) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> white(0.0, 1.0);
  const double a_hi = 1.0 - std::exp(-2.0 * std::numbers::pi * 10.0 * period_s);
  const double a_lo = 1.0 - std::exp(-2.0 * std::numbers::pi * 0.5 * period_s);
  double l1 = 0.0;
  double l2 = 0.0;
  double slow = 0.0;
  double sq = 0.0;
  std::vector<double> out(n);
  for (std::size_t k = 0; k < n; ++k) {
    l1 += a_hi * (white(rng) - l1);
    l2 += a_hi * (l1 - l2);
    slow += a_lo * (l2 - slow);
    out[k] = l2 - slow;
    sq += out[k] * out[k];
  }
  for (double& v : out) v *= rms / std::sqrt(sq / static_cast<double>(n));
  return out;
}

TEST(IdentifySession, BothPaddlesFromASimulatedSessionFile) {
  const TempDir dir;
  // The master gains all zero: the hand pushes the master paddle alone, the slave follows on
  // its own spring (tests/unit/stability/test_identify.cpp's scene).
  const std::size_t n = 15000;
  const std::vector<double> push = random_push(7, n, 1e-3, 1.0);
  std::ostringstream s;
  s << "sample_rate_hz: 1000\n"
       "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } }\n"
       "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } }\n"
       "gains { kps: 300 kds: 1 }\n"
       "velocity_filter { cutoff_hz: 200 }\n"
       "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n"
       "scene {\n  duration_s: 15\n  seed: 3\n  human_force { trace {\n";
  s.precision(17);
  for (std::size_t k = 0; k < n; k += 10) {
    s << "    time_s: " << static_cast<double>(k) * 1e-3 << " force_N: " << push[k] << "\n";
  }
  s << "  } }\n}\n";
  const std::string scene_path = dir.file("push.textproto");
  std::ofstream(scene_path) << s.str();
  const std::string file = simulate_mcap(dir, scene_path, "", "push.mcap");

  const struct {
    const char* device;
    double mass_kg;
    double damping_Ns_per_m;
  } cases[] = {{"master", 0.040, 0.41}, {"slave", 0.036, 0.49}};
  for (const auto& c : cases) {
    const SplitResult r = run(dir, "identify " + file + " --device " + c.device + " --json");
    ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
    const json j = json::parse(r.out);
    const double m = j["mass_kg"].get<double>();
    const double b = j["damping_Ns_per_m"].get<double>();
    EXPECT_LT(std::abs(m / c.mass_kg - 1.0), 0.05) << c.device << " mass " << m;
    EXPECT_LT(std::abs(b / c.damping_Ns_per_m - 1.0), 0.05) << c.device << " damping " << b;
    EXPECT_GT(j["r_squared"].get<double>(), 0.9) << c.device;
    ASSERT_EQ(j["runs"].size(), 1U);
    ASSERT_EQ(j["set"].size(), 2U);
    EXPECT_EQ(j["set"][0].get<std::string>().rfind(std::string(c.device) + ".device.mass_kg=", 0),
              0U);
    std::cout << c.device << ": m " << m << " kg, b " << b << " Ns/m, r^2 "
              << j["r_squared"].get<double>() << "\n";
  }
  // Column options are for CSV files.
  const SplitResult bad = run(dir, "identify " + file + " --position x --force f");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.err.find("are for CSV files"), std::string::npos) << bad.err;
}

TEST(Replay, ResimulationWithASofterFixtureOscillatesLess) {
  const TempDir dir;
  const std::string path = scene("paddles_slave_fixture_unstable.textproto");
  const std::string file = simulate_mcap(dir, path, "", "unstable.mcap");
  const json sim = json::parse(run(dir, "simulate " + path + " --json").out);
  ASSERT_TRUE(sim["oscillation"]["detected"].get<bool>());

  // As recorded: the resimulation plays the lockstep's loop again and finds what it recorded.
  SplitResult r = run(dir, "replay " + file + " --resimulate --json");
  EXPECT_EQ(r.exit_code, 3) << r.err;  // the resimulated slave oscillates
  json j = json::parse(r.out);
  const json rec = j["recorded"]["outcome"];
  EXPECT_TRUE(rec["oscillation"]["detected"].get<bool>());
  EXPECT_EQ(j["recorded"]["analysis"]["verdict"], sim["predicted"]["verdict"]);
  EXPECT_EQ(j["resimulated"]["outcome"], rec);
  const double recorded_amplitude = rec["oscillation"]["amplitude_m"].get<double>();
  // The recorded buzz is the one simulate reported (sensed here, true positions there).
  EXPECT_NEAR(recorded_amplitude, sim["oscillation"]["amplitude_m"].get<double>(), 2.5e-4);

  r = run(dir,
          "replay " + file + " --resimulate --set slave.fixture.stiffness_N_per_m=1000 --json");
  ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 3) << r.err;
  j = json::parse(r.out);
  EXPECT_EQ(j["resimulated"]["analysis"]["verdict"], "stable");
  EXPECT_EQ(j["resimulated"]["analysis"]["slave_fixture_stiffness_N_per_m"].get<double>(), 1000.0);
  EXPECT_EQ(j["recorded"]["analysis"]["slave_fixture_stiffness_N_per_m"].get<double>(), 4000.0);
  const double amplitude = j["resimulated"]["outcome"]["oscillation"]["amplitude_m"].get<double>();
  EXPECT_LT(amplitude, 0.6 * recorded_amplitude) << amplitude << " vs " << recorded_amplitude;
  EXPECT_EQ(j["resimulated"]["outcome"]["cycles"], rec["cycles"]);

  // A bad override names itself.
  r = run(dir, "replay " + file + " --resimulate --set slave.fixture.stiffness_N_per_m=-5");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("slave.fixture.stiffness_N_per_m"), std::string::npos) << r.err;
}

// --- several task-space axes (issue 18) ------------------------------------------------------

// A 3-axis session written here through the live session recorder: 2 s at 1 kHz, 100 cycles
// per telemetry message. Axis i of the master moves as a sine of amplitude (i + 1) mm at 1, 2
// and 5 Hz, its load cell reads 0.1 (i + 1) N times the same sine and its command is the
// force's negative; the slave follows at 0.9 of the master's position with the negated force.
// These sines reach their peaks at sample times (t = 1/(4f), 3/(4f): k = 250, 125, 50 and 750,
// 375, 150), so each axis's range is +-(i + 1) mm and its largest |force| 0.1 (i + 1) N (to
// rounding).
double axis_sine(int i, int k) {
  constexpr double kHz[] = {1.0, 2.0, 5.0};
  return std::sin(2.0 * std::numbers::pi * kHz[i] * k * 1e-3);
}

// `refused`: the master's cycle 1235 (k = 1234) has one force too few, a record the codec
// refuses.
std::string write_three_axis_session(const TempDir& dir, bool refused = false) {
  const std::string path = dir.file("axes.mcap");
  const std::unique_ptr<teleop::record::SessionSink> sink =
      teleop::record::make_session_recorder_at(path);
  for (int message = 0; message < 20; ++message) {
    for (const bool master : {true, false}) {
      teleop::v1::Telemetry t;
      t.set_session_id(master ? 1 : 2);
      t.mutable_loop()->set_period_s(1e-3);
      for (int j = 0; j < 100; ++j) {
        const int k = 100 * message + j;
        teleop::v1::CycleRecord* c = t.add_cycles();
        c->set_sequence(static_cast<std::uint64_t>(k + 1));
        c->set_sample_time_ns(1'000'000LL * k);
        c->set_mode(teleop::v1::ENGAGED);
        c->set_axes(3);
        for (int i = 0; i < 3; ++i) {
          const double x = 1e-3 * (i + 1) * axis_sine(i, k);
          const double f = 0.1 * (i + 1) * axis_sine(i, k);
          c->add_positions_m(master ? x : 0.9 * x);
          c->add_velocities_m_per_s(0.0);
          c->add_forces_n(master ? f : -f);
          c->add_commands_n(master ? -f : f);
          c->add_peer_positions_m(master ? 0.9 * x : x);
        }
        if (refused && master && k == 1234) c->mutable_forces_n()->RemoveLast();
      }
      sink->record(teleop::record::topic::telemetry(master), "teleop.v1.Telemetry",
                   1'000'000LL * (100 * message + 99), t.SerializeAsString());
    }
  }
  return path;
}

TEST(ReplayAxes, SummaryGivesEachAxisItsRangeAndPeaks) {
  const TempDir dir;
  const std::string file = write_three_axis_session(dir);
  const SplitResult r = run(dir, "replay " + file + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json j = json::parse(r.out);
  for (const char* side : {"master", "slave"}) {
    SCOPED_TRACE(side);
    const json& n = j["nodes"][side];
    EXPECT_EQ(n["cycles"].get<int>(), 2000);
    EXPECT_EQ(n["axes"].get<int>(), 3);
    EXPECT_EQ(n["refused_records"].get<int>(), 0);
    ASSERT_EQ(n["per_axis"].size(), 3U);
    const double scale = std::string(side) == "master" ? 1.0 : 0.9;
    for (int i = 0; i < 3; ++i) {
      const json& a = n["per_axis"][static_cast<std::size_t>(i)];
      EXPECT_NEAR(a["max_position_m"].get<double>(), scale * 1e-3 * (i + 1), 1e-12) << i;
      EXPECT_NEAR(a["min_position_m"].get<double>(), -scale * 1e-3 * (i + 1), 1e-12) << i;
      EXPECT_NEAR(a["max_abs_force_N"].get<double>(), 0.1 * (i + 1), 1e-12) << i;
      EXPECT_NEAR(a["max_abs_command_N"].get<double>(), 0.1 * (i + 1), 1e-12) << i;
    }
  }
  const SplitResult text = run(dir, "replay " + file);
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("3 task-space axes"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("axis 2: position -3.000 .. 3.000 mm, |force| up to 0.300 N"),
            std::string::npos)
      << text.out;
}

TEST(ReplayAxes, CsvHasEachAxisColumnsWithTheWrittenValues) {
  const TempDir dir;
  const std::string file = write_three_axis_session(dir);
  const SplitResult r = run(dir, "replay " + file + " --csv");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Csv csv = parse_csv(r.out);
  ASSERT_EQ(csv.rows.size(), 4000U);  // master rows first, then the slave's
  for (const std::size_t row : {std::size_t{0}, std::size_t{250}, std::size_t{1999}}) {
    const int k = static_cast<int>(row);
    EXPECT_EQ(csv.rows[row][csv.col("node")], "master");
    EXPECT_EQ(csv.num(row, "axes"), 3.0);
    EXPECT_NEAR(csv.num(row, "time_s"), k * 1e-3, 1e-12);
    for (int i = 0; i < 3; ++i) {
      const std::string n = std::to_string(i);
      // Written as the shortest round trip: the same double back.
      EXPECT_EQ(csv.num(row, "position_m_" + n), 1e-3 * (i + 1) * axis_sine(i, k)) << row;
      EXPECT_EQ(csv.num(row, "force_N_" + n), 0.1 * (i + 1) * axis_sine(i, k)) << row;
      EXPECT_EQ(csv.num(2000 + row, "position_m_" + n), 0.9 * (1e-3 * (i + 1) * axis_sine(i, k)));
      EXPECT_EQ(csv.num(2000 + row, "peer_position_m_" + n), 1e-3 * (i + 1) * axis_sine(i, k));
    }
  }
  EXPECT_EQ(csv.rows[2000][csv.col("node")], "slave");
}

// A record the codec refuses: the summary counts it and names its sequence; the CSV and the plot
// stop with an error naming the file, the topic and the cycle, exit 1.
TEST(ReplayAxes, ARefusedRecordIsCountedOrNamedNeverACrash) {
  const TempDir dir;
  const std::string file = write_three_axis_session(dir, true);
  const SplitResult r = run(dir, "replay " + file + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["nodes"]["master"]["refused_records"].get<int>(), 1);
  EXPECT_EQ(j["nodes"]["master"]["first_refused_sequence"].get<int>(), 1235);
  EXPECT_EQ(j["nodes"]["slave"]["refused_records"].get<int>(), 0);
  for (const std::string& action : {std::string("--csv"), "--plot " + dir.file("x.svg")}) {
    const SplitResult bad = run(dir, "replay " + file + " " + action);
    EXPECT_EQ(bad.exit_code, 1) << action << ": " << bad.out << bad.err;
    EXPECT_NE(bad.err.find(file + ": /master/telemetry cycle 1235 (log time 1299000000 ns): "),
              std::string::npos)
        << action << ": " << bad.err;
  }
}

// --resimulate needs the recorded configuration: a session without /config is refused by name,
// exit 1, before any work.
TEST(ReplayAxes, ResimulateWithoutTheRecordedConfigurationSaysSo) {
  const TempDir dir;
  const std::string file = write_three_axis_session(dir);
  const SplitResult r = run(dir, "replay " + file + " --resimulate");
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(
      r.err.find(file + ": no /config channel: --resimulate needs the recorded configuration"),
      std::string::npos)
      << r.err;
}

// The three-axis scene (examples/scenes/cartesian3_planes.textproto) as a session file.
std::string simulate_three_axis_mcap(const TempDir& dir, const std::string& extra = "") {
  return simulate_mcap(dir, scene("cartesian3_planes.textproto"), extra, "cartesian3.mcap");
}

// `src` copied to `dst` message by message (log times, topics and types kept), each Telemetry
// message of `topic` passed through `edit` first.
void rewrite_session(const std::string& src, const std::string& dst, std::string_view topic,
                     const std::function<void(teleop::v1::Telemetry&)>& edit) {
  const teleop::record::McapReader reader = teleop::record::McapReader::open(src);
  const std::unique_ptr<teleop::record::SessionSink> sink =
      teleop::record::make_session_recorder_at(dst);
  reader.for_each_message(teleop::record::Order::kLogTime,
                          [&](const teleop::record::MessageView& m) {
                            std::string bytes(m.data);
                            if (m.channel->topic == topic) {
                              teleop::v1::Telemetry t;
                              ASSERT_TRUE(t.ParseFromString(bytes));
                              edit(t);
                              bytes = t.SerializeAsString();
                            }
                            sink->record(m.channel->topic, m.schema->name,
                                         static_cast<std::int64_t>(m.log_time_ns), bytes);
                          });
}

// The nodes' own law on the same plant with the same inputs: resimulating what simulate wrote
// gives the recorded slave bit for bit on every axis (deviation exactly 0), and the same measures.
TEST(ReplayAxes, ResimulatingASimulatedSessionDeviatesByNothingOnAnyAxis) {
  const TempDir dir;
  const std::string file = simulate_three_axis_mcap(dir, "--duration 2");
  const SplitResult r = run(dir, "replay " + file + " --resimulate --json");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json j = json::parse(r.out);
  EXPECT_EQ(j["axes"].get<int>(), 3);
  EXPECT_EQ(j["master_cycles"].get<int>(), 2000);  // 2 s at 1 kHz
  const json& d = j["deviation"];
  EXPECT_EQ(d["cycles_compared"].get<int>(), 2000);
  ASSERT_EQ(d["per_axis"].size(), 3U);
  for (const json& axis : d["per_axis"]) {
    EXPECT_EQ(axis["max_abs_position_m"].get<double>(), 0.0) << axis;
    EXPECT_EQ(axis["rms_position_m"].get<double>(), 0.0) << axis;
    EXPECT_EQ(axis["max_abs_command_N"].get<double>(), 0.0) << axis;
  }
  EXPECT_EQ(j["recorded"]["outcome"], j["resimulated"]["outcome"]);
  EXPECT_EQ(j["resimulated"]["analysis"]["verdict"], "stable");
  // The slave was pushed into its planes: the measure is not of a slave at rest.
  EXPECT_GT(j["recorded"]["outcome"]["max_penetration_slave_m"].get<double>(), 5e-3);
  const SplitResult text = run(dir, "replay " + file + " --resimulate");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_NE(text.out.find("axis 2: position up to 0 mm"), std::string::npos) << text.out;
}

// The record's slave moved by d = 0.25 mm on axis 1 from cycle 1001 on: the resimulation, which
// reads only the master's motion, differs from the record by exactly d there and nowhere else
// (rms d sqrt(1000 / 2000)).
TEST(ReplayAxes, AShiftedAxisInTheRecordShowsExactlyThatShiftOnThatAxisOnly) {
  const TempDir dir;
  const std::string file = simulate_three_axis_mcap(dir, "--duration 2");
  const std::string shifted = dir.file("shifted.mcap");
  constexpr double kShift_m = 0.25e-3;
  rewrite_session(file, shifted, "/slave/telemetry", [](teleop::v1::Telemetry& t) {
    for (teleop::v1::CycleRecord& c : *t.mutable_cycles()) {
      if (c.sequence() > 1000) c.set_positions_m(1, c.positions_m(1) + kShift_m);
    }
  });
  const SplitResult r = run(dir, "replay " + shifted + " --resimulate --json");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json d = json::parse(r.out)["deviation"];
  EXPECT_EQ(d["cycles_compared"].get<int>(), 2000);
  for (int i : {0, 2}) {
    EXPECT_EQ(d["per_axis"][static_cast<std::size_t>(i)]["max_abs_position_m"].get<double>(), 0.0);
    EXPECT_EQ(d["per_axis"][static_cast<std::size_t>(i)]["rms_position_m"].get<double>(), 0.0);
  }
  const json& a1 = d["per_axis"][1];
  EXPECT_NEAR(a1["max_abs_position_m"].get<double>(), kShift_m, 1e-15);
  EXPECT_NEAR(a1["rms_position_m"].get<double>(), kShift_m * std::sqrt(0.5), 1e-15);
  EXPECT_GT(a1["at_sequence"].get<int>(), 1000);
  EXPECT_EQ(a1["max_abs_command_N"].get<double>(), 0.0);  // the slave's commands are untouched
  EXPECT_NEAR(d["max_abs_position_m"].get<double>(), kShift_m, 1e-15);
}

// The statics in the written session, solved by hand as test_teleopctl_axes.cpp does: the
// planes' normals (0, 0, -1) and (1, 1, 0)/sqrt 2 and the tangent (1, -1, 0)/sqrt 2 are
// orthogonal and every spring isotropic, so along a normal n (push F = 20 n.d,
// d = (1, 1, -1)/sqrt 3; hand k_h = 70, coupling k_c = 600, plane K at p):
//   (k_h + k_c) m - k_c s = F,   -k_c m + (k_c + K) s = K p.
// The master's load cell reads the hand's force F - k_h m, its command is minus that (F_am
// balances the hand at rest); the slave (no environment) reads 0 and commands 0. The summary
// and the CSV read every axis of both nodes.
TEST(ReplayAxes, TheWrittenSessionHoldsTheHandSolvedStatics) {
  const TempDir dir;
  const std::string file = simulate_three_axis_mcap(dir);  // the scene's 5 s
  const SplitResult summary = run(dir, "replay " + file + " --json");
  ASSERT_EQ(summary.exit_code, 0) << summary.err;
  const json js = json::parse(summary.out);
  for (const char* side : {"master", "slave"}) {
    EXPECT_EQ(js["nodes"][side]["axes"].get<int>(), 3) << side;
    EXPECT_EQ(js["nodes"][side]["cycles"].get<int>(), 5000) << side;
    EXPECT_EQ(js["nodes"][side]["refused_records"].get<int>(), 0) << side;
  }
  const SplitResult r = run(dir, "replay " + file + " --csv");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const Csv csv = parse_csv(r.out);
  ASSERT_EQ(csv.rows.size(), 10000U);
  const std::size_t m = 4999;  // the master's last cycle, then the slave's
  const std::size_t s = 9999;
  ASSERT_EQ(csv.rows[s][csv.col("node")], "slave");
  const auto v = [&](std::size_t row, const char* field) {
    std::array<double, 3> x{};
    for (int i = 0; i < 3; ++i)
      x[static_cast<std::size_t>(i)] = csv.num(row, std::string(field) + "_" + std::to_string(i));
    return x;
  };
  const auto along_floor = [](const std::array<double, 3>& x) { return -x[2]; };
  const auto along_wall = [](const std::array<double, 3>& x) {
    return (x[0] + x[1]) / std::sqrt(2.0);
  };
  const auto along_tangent = [](const std::array<double, 3>& x) {
    return (x[0] - x[1]) / std::sqrt(2.0);
  };
  const double kh = 70.0;
  const double kc = 600.0;
  const auto solve = [&](double f, double k, double p) {
    const double det = (kh + kc) * (kc + k) - kc * kc;
    return std::pair{(f * (kc + k) + kc * k * p) / det, ((kh + kc) * k * p + kc * f) / det};
  };
  const double f_floor = 20.0 / std::sqrt(3.0);
  const double f_wall = 20.0 * 2.0 / std::sqrt(6.0);
  const auto [m_floor, s_floor] = solve(f_floor, 1500.0, 0.01);
  const auto [m_wall, s_wall] = solve(f_wall, 1000.0, 0.02);
  const std::array<double, 3> xm = v(m, "position_m");
  const std::array<double, 3> xs = v(s, "position_m");
  EXPECT_NEAR(along_floor(xs) - 0.01, 6.2e-3, 0.05e-3);  // the scene's comment: 6.2 mm
  EXPECT_NEAR(along_wall(xs) - 0.02, 12.6e-3, 0.05e-3);  // and 12.6 mm
  EXPECT_NEAR(along_floor(xs), s_floor, 1e-6);
  EXPECT_NEAR(along_wall(xs), s_wall, 1e-6);
  EXPECT_NEAR(along_floor(xm), m_floor, 1e-6);
  EXPECT_NEAR(along_wall(xm), m_wall, 1e-6);
  EXPECT_NEAR(along_tangent(xs), 0.0, 1e-6);
  EXPECT_NEAR(along_tangent(xm), 0.0, 1e-6);
  const std::array<double, 3> fm = v(m, "force_N");
  EXPECT_NEAR(along_floor(fm), f_floor - kh * m_floor, 1e-3);
  EXPECT_NEAR(along_wall(fm), f_wall - kh * m_wall, 1e-3);
  const std::array<double, 3> um = v(m, "command_N");
  EXPECT_NEAR(along_floor(um), -(f_floor - kh * m_floor), 1e-3);
  EXPECT_NEAR(along_wall(um), -(f_wall - kh * m_wall), 1e-3);
  for (int i = 0; i < 3; ++i) {
    const std::string n = std::to_string(i);
    EXPECT_EQ(csv.num(s, "force_N_" + n), 0.0) << i;
    EXPECT_NEAR(csv.num(s, "command_N_" + n), 0.0, 1e-3) << i;
    // Each node's peer: the master's slave of the same sample, the slave's master a round trip
    // earlier (at rest: the same position).
    EXPECT_EQ(csv.num(m, "peer_position_m_" + n), xs[static_cast<std::size_t>(i)]) << i;
    EXPECT_NEAR(csv.num(s, "peer_position_m_" + n), xm[static_cast<std::size_t>(i)], 1e-9) << i;
  }
  // The slave law's deepest plane: the wall (12.6 mm in, the floor 6.2 mm).
  EXPECT_NEAR(csv.num(s, "fixture_penetration_m"), along_wall(xs) - 0.02, 1e-12);
}

// Hostile sessions, never a crash: a slave cycle of 2 axes in a 3-axis session, and a master
// cycle whose positions list is one short, are refused naming the file, topic and sequence.
TEST(ReplayAxes, ResimulateRefusesWrongAxisCountsAndTruncatedListsByName) {
  const TempDir dir;
  const std::string file = simulate_three_axis_mcap(dir, "--duration 2");
  const std::string two = dir.file("two_axes.mcap");
  rewrite_session(file, two, "/slave/telemetry", [](teleop::v1::Telemetry& t) {
    for (teleop::v1::CycleRecord& c : *t.mutable_cycles()) {
      if (c.sequence() != 777) continue;
      c.set_axes(2);
      for (auto* list :
           {c.mutable_positions_m(), c.mutable_velocities_m_per_s(), c.mutable_forces_n(),
            c.mutable_commands_n(), c.mutable_peer_positions_m()}) {
        list->RemoveLast();
      }
    }
  });
  SplitResult r = run(dir, "replay " + two + " --resimulate");
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.err.find(two + ": /slave/telemetry cycle 777: 2 task-space axes, the recorded "
                             "configuration 3"),
            std::string::npos)
      << r.err;
  const std::string cut = dir.file("cut.mcap");
  rewrite_session(file, cut, "/master/telemetry", [](teleop::v1::Telemetry& t) {
    for (teleop::v1::CycleRecord& c : *t.mutable_cycles()) {
      if (c.sequence() == 1235) c.mutable_positions_m()->RemoveLast();
    }
  });
  r = run(dir, "replay " + cut + " --resimulate --json");
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.err.find(cut + ": /master/telemetry cycle 1235 (log time "), std::string::npos)
      << r.err;
  // A session with no cycles at all on the master's channel.
  const std::string empty = dir.file("empty.mcap");
  rewrite_session(file, empty, "/master/telemetry",
                  [](teleop::v1::Telemetry& t) { t.clear_cycles(); });
  r = run(dir, "replay " + empty + " --resimulate");
  EXPECT_EQ(r.exit_code, 1) << r.out << r.err;
  EXPECT_NE(r.err.find(empty + ": no master cycles to replay"), std::string::npos) << r.err;
}

// The plot: one position and one force trace per axis and node (6 each), labelled by axis.
TEST(ReplayAxes, PlotDrawsEveryAxisOfBothNodes) {
  const TempDir dir;
  const std::string file = write_three_axis_session(dir);
  const std::string svg = dir.file("axes.svg");
  const SplitResult r = run(dir, "replay " + file + " --plot " + svg);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const std::string text = read_text(svg);
  for (const char* node : {"master", "slave"}) {
    for (int i = 0; i < 3; ++i) {
      const std::string label = std::string(node) + " axis " + std::to_string(i);
      EXPECT_NE(text.find(label), std::string::npos) << label;
    }
  }
  EXPECT_NE(text.find("positions and forces of 3 axes"), std::string::npos);
}

}  // namespace
