// Session recording soak (issue 5): three 1 kHz streams of Telemetry messages (the nodes' own
// protobuf, built and serialized per message as the supervisor's subscriber threads would hand
// them over) into one record::Recorder, paced at real time on absolute deadlines, for a long
// run. Reports drops (goal: zero), messages written, file size, the deepest backlog between
// the producers and the disk, and the process's RSS growth after warm-up.
//   bench_record_soak [--duration S] [--dir DIR] [--cycles N] [--keep]
// Defaults: 600 s, the temp directory, 1 cycle per message (a 1 kHz stream carries each
// cycle once); --keep leaves the file for inspection.
#include <fmt/core.h>
#include <time.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "common/record/proto_schema.hpp"
#include "common/record/recorder.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace {

namespace rec = teleop::record;
namespace v1 = teleop::v1;

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

void sleep_until_ns(std::int64_t t) {
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(t / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(t % 1'000'000'000);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) != 0) {
  }
}

// Resident set size, bytes (/proc/self/statm: pages).
std::uint64_t rss_bytes() {
  std::ifstream in("/proc/self/statm");
  std::uint64_t size = 0;
  std::uint64_t resident = 0;
  in >> size >> resident;
  return resident * static_cast<std::uint64_t>(sysconf(_SC_PAGESIZE));
}

// A telemetry message as a node sends it: stats, link, RT status, active parameters and
// `cycles` cycle records with values that change every message (so the bytes vary like a
// live stream's).
void fill(v1::Telemetry& t, int stream, std::uint64_t n, int cycles) {
  const double x = 1e-3 * std::sin(static_cast<double>(n) * 0.01 + stream);
  t.set_session_id(0x9e3779b97f4a7c15ULL + static_cast<std::uint64_t>(stream));
  t.set_role(stream == 0 ? v1::MASTER : v1::SLAVE);
  t.set_mode(v1::ENGAGED);
  t.set_mode_reason("engaged: within alignment tolerance");
  t.set_sent_time_ns(monotonic_ns());
  v1::LoopStats* l = t.mutable_loop();
  l->set_period_s(1e-3);
  l->set_cycles(n);
  l->set_overruns(n / 100000);
  l->set_wakeup_p50_ns(32000 + static_cast<std::int64_t>(n % 7));
  l->set_wakeup_p99_ns(201000);
  l->set_wakeup_p999_ns(1497000);
  l->set_wakeup_max_ns(13866000);
  l->set_compute_p50_ns(2100);
  l->set_compute_p99_ns(5300);
  l->set_compute_max_ns(40000);
  v1::LinkStats* k = t.mutable_link();
  k->set_accepted(n);
  k->set_lost(n / 5000);
  k->set_loss_fraction(2e-4);
  k->set_round_trip_ns(1'100'000 + static_cast<std::int64_t>(n % 300) * 1000);
  k->set_round_trip_p50_ns(1'050'000);
  k->set_round_trip_p99_ns(1'900'000);
  k->set_round_trip_samples(2);
  k->set_one_way_latency_ns(550'000);
  k->set_peer_session_id(0x1234567812345678ULL);
  k->set_peer_age_ns(400'000);
  v1::RtStatus* r = t.mutable_rt();
  r->set_fifo_priority(80);
  r->set_memory_locked(true);
  r->set_cpu(-1);
  r->set_cpu_dma_latency_us(10);
  t.set_device("sim");
  v1::ActiveParameters* a = t.mutable_active();
  a->mutable_gains()->set_kpm(600);
  a->mutable_gains()->set_kps(600);
  a->mutable_gains()->set_kdm(2);
  a->mutable_gains()->set_kds(2);
  a->set_slave_fixture_stiffness_n_per_m(1500);
  a->set_ramp_progress(1.0);
  t.clear_cycles();
  for (int i = 0; i < cycles; ++i) {
    v1::CycleRecord* c = t.add_cycles();
    const std::uint64_t seq =
        n * static_cast<std::uint64_t>(cycles) + static_cast<std::uint64_t>(i);
    c->set_sequence(seq);
    c->set_sample_time_ns(static_cast<std::int64_t>(seq) * 1'000'000);
    c->set_mode(v1::ENGAGED);
    c->set_position_m(x);
    c->set_velocity_m_per_s(x * 31.4);
    c->set_force_n(0.5 + x * 100);
    c->set_command_n(-0.5 - x * 90);
    c->set_peer_sequence(seq - 1);
    c->set_peer_position_m(x * 0.98);
    c->set_peer_age_ns(400'000 + static_cast<std::int64_t>(seq % 97) * 1000);
    c->set_coupling_weight(1.0);
    c->set_flags(static_cast<std::uint32_t>(seq % 3));
    c->set_wakeup_latency_ns(30'000 + static_cast<std::int64_t>(seq % 1000) * 10);
    c->set_round_trip_ns(1'100'000);
    c->set_master_sequence(seq);
  }
}

struct Args {
  double duration_s{600.0};
  std::filesystem::path dir{std::filesystem::temp_directory_path()};
  int cycles{1};
  bool keep{false};
};

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string s = argv[i];
    if (s == "--duration" && i + 1 < argc) {
      a.duration_s = std::stod(argv[++i]);
    } else if (s == "--dir" && i + 1 < argc) {
      a.dir = argv[++i];
    } else if (s == "--cycles" && i + 1 < argc) {
      a.cycles = std::stoi(argv[++i]);
    } else if (s == "--keep") {
      a.keep = true;
    } else {
      fmt::print(stderr,
                 "usage: bench_record_soak [--duration S] [--dir DIR] [--cycles N] [--keep]\n");
      std::exit(2);
    }
  }
  return a;
}

}  // namespace

int main(int argc, char** argv) {
  const Args args = parse(argc, argv);
  const auto path = args.dir / "bench_record_soak.mcap";
  constexpr int kStreams = 3;
  constexpr std::int64_t kPeriodNs = 1'000'000;
  const char* topics[kStreams] = {"/master/telemetry", "/slave/telemetry", "/third/telemetry"};

  rec::Recorder recorder(path);
  const std::uint16_t schema =
      recorder.add_schema(rec::protobuf_schema(v1::Telemetry::descriptor()));
  std::uint16_t channels[kStreams];
  for (int s = 0; s < kStreams; ++s) {
    channels[s] = recorder.add_channel(rec::protobuf_channel(schema, topics[s]));
  }

  std::atomic<std::uint64_t> enqueued{0};
  std::atomic<std::uint64_t> refused{0};
  std::atomic<std::uint64_t> late{0};  // deadlines already past on wake-up by over a period
  std::atomic<std::uint64_t> message_bytes{0};
  std::atomic<bool> done{false};
  const std::int64_t start = monotonic_ns() + 100'000'000;
  const auto total = static_cast<std::uint64_t>(std::llround(args.duration_s * 1000.0));

  std::vector<std::thread> producers;
  for (int s = 0; s < kStreams; ++s) {
    producers.emplace_back([&, s] {
      v1::Telemetry t;
      std::string bytes;
      for (std::uint64_t n = 0; n < total; ++n) {
        const std::int64_t deadline = start + static_cast<std::int64_t>(n) * kPeriodNs;
        sleep_until_ns(deadline);
        if (monotonic_ns() - deadline > kPeriodNs) late.fetch_add(1, std::memory_order_relaxed);
        fill(t, s, n, args.cycles);
        t.SerializeToString(&bytes);
        message_bytes.fetch_add(bytes.size(), std::memory_order_relaxed);
        if (recorder.record(channels[s], static_cast<std::uint64_t>(monotonic_ns()), bytes)) {
          enqueued.fetch_add(1, std::memory_order_relaxed);
        } else {
          refused.fetch_add(1, std::memory_order_relaxed);
        }
      }
    });
  }

  // The monitor: backlog (accepted by record() but not yet in a chunk handed to the OS; it
  // includes the open chunk, so it bounds the queue depth from above) every 10 ms, RSS and a
  // progress line every 60 s. RSS is taken as a baseline after 10 s of warm-up.
  std::uint64_t max_backlog = 0;
  std::uint64_t rss_start = rss_bytes();
  std::uint64_t rss_warm = 0;
  std::uint64_t rss_max = rss_start;
  std::thread monitor([&] {
    std::int64_t next = start;
    std::int64_t next_line = start + 60'000'000'000;
    const std::int64_t warm_at = start + 10'000'000'000;
    while (!done.load()) {
      next += 10'000'000;
      sleep_until_ns(next);
      const std::uint64_t w = recorder.written();
      const std::uint64_t e = enqueued.load();
      if (e > w) max_backlog = std::max(max_backlog, e - w);
      const std::int64_t now = monotonic_ns();
      if (rss_warm == 0 && now >= warm_at) rss_warm = rss_bytes();
      if (now >= next_line) {
        next_line += 60'000'000'000;
        const std::uint64_t rss = rss_bytes();
        rss_max = std::max(rss_max, rss);
        fmt::print("[{:5.0f} s] written {} drops {} file {:.1f} MB backlog max {} RSS {:.1f} MB\n",
                   static_cast<double>(now - start) * 1e-9, w, recorder.drops(),
                   static_cast<double>(recorder.file_size()) / 1e6, max_backlog,
                   static_cast<double>(rss) / 1e6);
        std::fflush(stdout);
      }
    }
  });
  for (auto& p : producers) p.join();
  const std::uint64_t rss_end = rss_bytes();
  rss_max = std::max(rss_max, rss_end);
  const double produce_s = static_cast<double>(monotonic_ns() - start) * 1e-9;
  done = true;
  monitor.join();
  if (rss_warm == 0) rss_warm = rss_start;  // a run shorter than the warm-up
  const bool closed_ok = recorder.close();

  // The file as a reader sees it.
  std::uint64_t read_messages = 0;
  std::uint64_t chunks = 0;
  std::string read_error;
  try {
    const rec::McapReader reader = rec::McapReader::open(path);
    chunks = reader.chunk_indexes().size();
    if (reader.statistics()) read_messages = reader.statistics()->message_count;
  } catch (const std::exception& e) {
    read_error = e.what();
  }
  const std::uint64_t file_size = std::filesystem::file_size(path);

  const std::uint64_t produced = static_cast<std::uint64_t>(kStreams) * total;
  fmt::print(
      "\nbench_record_soak: {} streams x 1 kHz, {:.0f} s ({:.1f} s wall), {} cycle(s) per "
      "message\n",
      kStreams, args.duration_s, produce_s, args.cycles);
  fmt::print("  messages produced     {}\n", produced);
  fmt::print("  mean message size     {:.0f} B\n",
             static_cast<double>(message_bytes.load()) / static_cast<double>(produced));
  fmt::print("  drops                 {} (record() refused {}){}\n", recorder.drops(),
             refused.load(), recorder.drops() == 0 ? "" : "  <-- goal is zero");
  fmt::print("  messages written      {} (reader's statistics: {}, {} chunks)\n",
             recorder.written(), read_messages, chunks);
  fmt::print("  file size             {:.1f} MB ({:.2f} MB/min)\n",
             static_cast<double>(file_size) / 1e6,
             static_cast<double>(file_size) / 1e6 / (args.duration_s / 60.0));
  fmt::print("  max backlog           {} messages (accepted, not yet in a written chunk)\n",
             max_backlog);
  fmt::print("  late producer wakes   {} (> 1 period behind)\n", late.load());
  fmt::print(
      "  RSS                   start {:.1f} MB, after 10 s {:.1f} MB, end {:.1f} MB, max "
      "{:.1f} MB; growth after warm-up {:+.2f} MB\n",
      static_cast<double>(rss_start) / 1e6, static_cast<double>(rss_warm) / 1e6,
      static_cast<double>(rss_end) / 1e6, static_cast<double>(rss_max) / 1e6,
      (static_cast<double>(rss_end) - static_cast<double>(rss_warm)) / 1e6);
  if (!closed_ok) fmt::print("  recorder error: {}\n", recorder.error());
  if (!read_error.empty()) fmt::print("  reader error: {}\n", read_error);
  if (!args.keep) std::filesystem::remove(path);
  const bool ok = closed_ok && read_error.empty() && recorder.drops() == 0 &&
                  recorder.written() == produced && read_messages == produced;
  return ok ? 0 : 1;
}
