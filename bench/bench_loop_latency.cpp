// Wake-up latency of PeriodicLoop measured as cyclictest measures its own (issue 4
// "Benchmarks"; bench/run_rt_bench.sh runs both): sleep to an absolute deadline on
// CLOCK_MONOTONIC, read the clock on waking, latency = now - deadline. Every cycle's latency is
// kept in a preallocated array (the loop's own LatencyHistogram has bins 2^(1/3) apart, too
// coarse for a 1.2x comparison), then binned like cyclictest's histogram (whole microseconds,
// truncated) so that both tools' quantiles come out of one function.
//
//   bench_loop_latency --duration 20 --priority 80 --mlock --dma-latency-us 10 [--step node]
//   bench_loop_latency --quantiles CYCLICTEST_HISTFILE
//
// Prints one `key=value` line for the script; --priority 0 leaves the scheduler alone
// (SCHED_OTHER), as cyclictest's --policy=other does.
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/device/sim_device.hpp"
#include "common/node/node_core.hpp"
#include "common/rt/cpu_dma_latency.hpp"
#include "common/rt/periodic_loop.hpp"

namespace {

using namespace std::chrono_literals;
using teleop::rt::PeriodicLoop;

// cyclictest's histogram: one bin per whole microsecond (the latency truncated), the rest
// counted as overflows.
struct UsHistogram {
  std::vector<std::uint64_t> bins{};
  std::uint64_t overflows{0};
  std::uint64_t total{0};
  std::int64_t max_us{0};
};

// Nearest rank: the smallest bin holding at least ceil(q * total) samples; -1 in the overflow.
std::int64_t quantile_us(const UsHistogram& h, double q) {
  const auto rank = std::max<std::uint64_t>(
      1, static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(h.total))));
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < h.bins.size(); ++i) {
    seen += h.bins[i];
    if (seen >= rank) return static_cast<std::int64_t>(i);
  }
  return -1;
}

std::string format_quantiles(const UsHistogram& h) {
  auto text = [&](double q) {
    const std::int64_t v = quantile_us(h, q);
    return v < 0 ? std::string("overflow") : std::to_string(v);
  };
  return fmt::format("samples={} p50_us={} p99_us={} p999_us={} max_us={} overflows={}", h.total,
                     text(0.5), text(0.99), text(0.999), h.max_us, h.overflows);
}

// The file `cyclictest -h N --histfile PATH` writes: "# ..." comments (Max Latencies,
// Histogram Overflows) and "%06d %06d" lines, bin and count, for one thread.
UsHistogram read_cyclictest_histfile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot read cyclictest histogram " + path);
  UsHistogram h;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty()) continue;
    std::istringstream fields(line);
    if (line[0] == '#') {
      const auto colon = line.find(':');
      if (colon == std::string::npos) continue;
      const std::string key = line.substr(0, colon);
      std::istringstream value(line.substr(colon + 1));
      if (key == "# Max Latencies") value >> h.max_us;
      if (key == "# Histogram Overflows") value >> h.overflows;
      continue;
    }
    std::size_t bin = 0;
    std::uint64_t count = 0;
    if (!(fields >> bin >> count)) continue;
    if (h.bins.size() <= bin) h.bins.resize(bin + 1, 0);
    h.bins[bin] += count;
    h.total += count;
  }
  h.total += h.overflows;
  if (h.total == 0) throw std::runtime_error("empty cyclictest histogram " + path);
  return h;
}

struct Options {
  double duration_s{20.0};
  int priority{80};
  bool mlock{true};
  int dma_latency_us{-1};  // -1: leave /dev/cpu_dma_latency alone
  bool node_step{false};
  std::string quantiles_of{};
};

Options parse(int argc, char** argv) {
  Options o;
  bool mlock_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--duration") {
      o.duration_s = std::stod(value());
    } else if (a == "--priority") {
      o.priority = std::stoi(value());
    } else if (a == "--mlock") {
      o.mlock = mlock_given = true;
    } else if (a == "--no-mlock") {
      o.mlock = false;
      mlock_given = true;
    } else if (a == "--dma-latency-us") {
      o.dma_latency_us = std::stoi(value());
    } else if (a == "--step") {
      const std::string s = value();
      if (s != "empty" && s != "node") throw std::invalid_argument("--step: empty or node");
      o.node_step = s == "node";
    } else if (a == "--quantiles") {
      o.quantiles_of = value();
    } else {
      throw std::invalid_argument("unknown option " + a);
    }
  }
  if (!mlock_given) o.mlock = o.priority > 0;
  if (!(o.duration_s > 0.0)) throw std::invalid_argument("--duration must be > 0");
  if (o.priority < 0 || o.priority > 99) throw std::invalid_argument("--priority in [0, 99]");
  return o;
}

// The master node's RT step as the nodes run it (disarmed, no peer): a SimDevice with the
// paper's paddle and a human, so each cycle also simulates the plant.
struct NodeStep {
  NodeStep()
      : device([] {
          teleop::sim::HumanParams h;
          h.impedance = teleop::HumanImpedance{0.012, 0.76, 70.0};
          return teleop::device::SimDeviceConfig::paddle_master(h);
        }()) {
    if (!device.configure().ok() || !device.activate().ok()) {
      throw std::runtime_error("simulated device did not start");
    }
    teleop::node::NodeSettings s;
    s.role = teleop::transport::Role::kMaster;
    s.period = 1ms;
    s.law.period_s = 1e-3;
    s.law.gains = teleop::Gains{600, 600, 2, 2, 0, 0, 0};
    core = std::make_unique<teleop::node::NodeCore>(s, device);
  }
  teleop::device::SimDevice device;
  std::unique_ptr<teleop::node::NodeCore> core{};
};

int run(const Options& o) {
  constexpr auto kPeriod = 1ms;
  const auto samples = static_cast<std::size_t>(std::llround(o.duration_s * 1000.0));
  // Written before the loop starts, so every page is resident before mlockall and the RT
  // thread never faults one in.
  std::vector<std::int64_t> latency_ns(samples, 0);
  std::optional<NodeStep> node;
  if (o.node_step) node.emplace();
  std::optional<teleop::rt::CpuDmaLatency> dma;
  if (o.dma_latency_us >= 0) {
    dma.emplace(o.dma_latency_us);
    if (dma->refusal()) throw std::runtime_error(*dma->refusal());
  }

  std::size_t taken = 0;
  std::atomic<bool> done{false};
  std::unique_ptr<PeriodicLoop> loop;
  const teleop::rt::RtSettings settings{o.priority, o.mlock, -1, true};
  loop = std::make_unique<PeriodicLoop>(kPeriod, settings, [&](std::chrono::nanoseconds deadline) {
    // The latency the loop itself measured for this cycle, on this (the RT) thread.
    if (taken < samples) latency_ns[taken++] = loop->timing().last_wakeup_latency().count();
    if (node) node->core->step(deadline, &loop->timing());
    if (taken == samples && !done.load(std::memory_order_relaxed)) {
      done.store(true, std::memory_order_release);
      done.notify_one();
    }
  });
  loop->start();
  done.wait(false, std::memory_order_acquire);
  loop->stop();

  UsHistogram h;
  for (const std::int64_t ns : latency_ns) {
    const std::int64_t us = ns / 1000;
    const auto bin = static_cast<std::size_t>(std::max<std::int64_t>(us, 0));
    if (h.bins.size() <= bin) h.bins.resize(bin + 1, 0);
    ++h.bins[bin];
    ++h.total;
    h.max_us = std::max(h.max_us, us);
  }
  std::sort(latency_ns.begin(), latency_ns.end());
  auto exact = [&](double q) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(samples)));
    return static_cast<double>(latency_ns[std::max<std::size_t>(rank, 1) - 1]) * 1e-3;
  };
  const teleop::rt::LatencyHistogram& own = loop->timing().wakeup_latency();
  auto edge = [&](double q) { return static_cast<double>(own.quantile(q).count()) * 1e-3; };
  std::cout << "loop " << format_quantiles(h)
            << fmt::format(" overruns={}", loop->timing().overruns()) << "\n"
            << fmt::format(
                   "# exact: p50 {:.1f} us, p99 {:.1f} us, p99.9 {:.1f} us; the loop's "
                   "LatencyHistogram (upper bin edges, 2^(1/3) apart): p50 {:.1f}, p99 {:.1f}, "
                   "p99.9 {:.1f} us; step {}, SCHED_{} {}, mlockall {}, cpu_dma_latency {}\n",
                   exact(0.5), exact(0.99), exact(0.999), edge(0.5), edge(0.99), edge(0.999),
                   o.node_step ? "NodeCore (master, SimDevice)" : "empty",
                   o.priority > 0 ? "FIFO" : "OTHER", o.priority, o.mlock ? "on" : "off",
                   o.dma_latency_us >= 0 ? std::to_string(o.dma_latency_us) + " us" : "untouched");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    if (!o.quantiles_of.empty()) {
      std::cout << "cyclictest " << format_quantiles(read_cyclictest_histfile(o.quantiles_of))
                << "\n";
      return 0;
    }
    return run(o);
  } catch (const std::exception& e) {
    std::cerr << "bench_loop_latency: " << e.what() << "\n";
    return 1;
  }
}
