// Session recording throughput (issue 5): McapWriter and the Recorder against plain fwrite of
// the same message bytes in the same run (goal: >= 0.5x), and McapReader's replay scan.
//   bench_record [DIR] [MiB per run]   (default: the temp directory, 64 MiB)
// Best of 3 runs per row; files are written to the page cache (no fdatasync), as a recording
// normally is between chunk flushes.
#include <fmt/core.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "common/record/mcap_reader.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/recorder.hpp"

namespace {

using Clock = std::chrono::steady_clock;
namespace rec = teleop::record;

double best_of_3(const std::function<void()>& run) {
  double best = 1e300;
  for (int i = 0; i < 3; ++i) {
    const auto t0 = Clock::now();
    run();
    best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
  }
  return best;
}

struct Row {
  std::string what;
  std::size_t size;
  double seconds;
  std::uint64_t messages;
  std::uint64_t bytes;  // message bytes (write rows) or file bytes (replay rows)
  double baseline;      // seconds of fwrite for the same bytes; 0: none
};

void print(const Row& r) {
  const double mps = static_cast<double>(r.messages) / r.seconds;
  const double mbs = static_cast<double>(r.bytes) / r.seconds / 1e6;
  std::string ratio = "";
  if (r.baseline > 0) ratio = fmt::format("{:.2f}x", r.baseline / r.seconds);
  fmt::print("| {:<28} | {:>6} | {:>12.0f} | {:>9.0f} | {:>10} |\n", r.what, r.size, mps, mbs,
             ratio);
}

}  // namespace

int main(int argc, char** argv) {
  const std::filesystem::path dir =
      argc > 1 ? std::filesystem::path(argv[1]) : std::filesystem::temp_directory_path();
  const std::size_t mib = argc > 2 ? std::stoul(argv[2]) : 64;
  const auto path = dir / "bench_record.mcap";
  const auto plain = dir / "bench_record.bin";

  fmt::print("| {:<28} | {:>6} | {:>12} | {:>9} | {:>10} |\n", "case", "bytes", "messages/s",
             "MB/s", "vs fwrite");
  fmt::print("|{:-<30}|{:-<8}|{:->14}|{:->11}|{:->12}|\n", "", "", "", "", "");
  for (const std::size_t size : {std::size_t{100}, std::size_t{2000}}) {
    const std::uint64_t count = (mib << 20) / size;
    // 64 distinct random payloads, cycled: the bytes are not trivially compressible by anyone.
    std::mt19937_64 rng(size);
    std::vector<std::string> payloads(64, std::string(size, '\0'));
    for (auto& p : payloads) {
      for (char& c : p) c = static_cast<char>(rng());
    }
    const std::uint64_t bytes = count * size;

    const double fwrite_s = best_of_3([&] {
      std::FILE* f = std::fopen(plain.c_str(), "wb");
      if (f == nullptr) throw std::runtime_error("cannot create " + plain.string());
      for (std::uint64_t i = 0; i < count; ++i) std::fwrite(payloads[i & 63].data(), 1, size, f);
      std::fclose(f);
    });
    print({"fwrite (baseline)", size, fwrite_s, count, bytes, fwrite_s});

    const double writer_s = best_of_3([&] {
      rec::McapWriter w(path);
      const auto ch = w.add_channel({0, "/bench", "protobuf", {}});
      for (std::uint64_t i = 0; i < count; ++i) {
        if (!w.write(ch, i, payloads[i & 63])) throw std::runtime_error(w.error());
      }
      if (!w.close()) throw std::runtime_error(w.error());
    });
    print({"McapWriter", size, writer_s, count, bytes, fwrite_s});

    std::uint64_t full = 0;
    const double recorder_s = best_of_3([&] {
      rec::Recorder r(path);
      const auto ch = r.add_channel({0, "/bench", "protobuf", {}});
      for (std::uint64_t i = 0; i < count; ++i) {
        // A producer that outruns the writer is told so (false) and retries: this measures
        // the sustained rate, with the queue-full events counted.
        while (!r.record(ch, i, payloads[i & 63])) {
          ++full;
          std::this_thread::yield();
        }
      }
      if (!r.close()) throw std::runtime_error(r.error());
    });
    print({"Recorder (1 producer)", size, recorder_s, count, bytes, fwrite_s});

    const std::uint64_t file_bytes = std::filesystem::file_size(path);
    std::uint64_t seen = 0;
    const rec::McapReader reader = rec::McapReader::open(path);
    const double scan_s = best_of_3([&] {
      reader.for_each_message(rec::Order::kFile,
                              [&](const rec::MessageView& m) { seen += m.data.size(); });
    });
    print({"replay scan, file order", size, scan_s, count, file_bytes, 0});
    const double time_s = best_of_3([&] {
      reader.for_each_message(rec::Order::kLogTime,
                              [&](const rec::MessageView& m) { seen += m.data.size(); });
    });
    print({"replay scan, log-time order", size, time_s, count, file_bytes, 0});
    if (seen != 6 * bytes) throw std::runtime_error("replay saw the wrong byte count");
    fmt::print("|   (file {:.1f} MB for {:.1f} MB of messages; {} queue-full retries)\n",
               static_cast<double>(file_bytes) / 1e6, static_cast<double>(bytes) / 1e6, full);
  }
  std::filesystem::remove(path);
  std::filesystem::remove(plain);
  return 0;
}
