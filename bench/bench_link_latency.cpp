// One-way latency (half the round trip) of the node link against a raw UDP ping on loopback,
// both paced at 1 kHz by a PeriodicLoop (issue 4 "Benchmarks"; bench/run_rt_bench.sh runs it).
//
//   --mode udp    the floor: the loop thread sends a datagram (as many bytes as an encoded
//                 NodeState) straight from its step; an echo thread blocked in recv() sends it
//                 back at once; a receiver thread blocked in recv() timestamps it.
//   --mode zmq    our link as node_app wires it: the step hands a NodeStateRecord to a sender
//                 thread (LatestValue + atomic notify), which encodes and publishes it on
//                 make_state_publisher; the echo side is node_app's receiver (poll + drain +
//                 PeerStateFilter) that encodes and publishes a reply at once, its own
//                 sequence echoing the ping's; the pinger's receiver is node_app's receiver
//                 again. One zmq context per side, as two processes have.
//   --mode nodes  the real processes (teleop-master, teleop-slave, disarmed, simulated
//                 devices): the master's per-cycle round trip from its telemetry. Their round
//                 trip runs from the sending cycle's deadline, so it also holds both loops'
//                 wake-up latency and step; the peer's hold until its next cycle is subtracted
//                 (RoundTripEstimator).
//
// udp and zmq time from the step (after the wake-up, measured by bench_loop_latency) to the
// echo's arrival, so the two differ only in the path; in both, only the loop thread gets the
// real-time settings, as in a node. A warm-up second (link set-up, slow joiner) is not counted.
// Prints one `key=value` line: one-way = round trip / 2, in microseconds.
#include <arpa/inet.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

#include "common/rt/cpu_dma_latency.hpp"
#include "common/rt/latest_value.hpp"
#include "common/rt/periodic_loop.hpp"
#include "common/transport/node_state_codec.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "teleop/v1/telemetry.pb.h"

extern char** environ;

namespace {

using namespace std::chrono_literals;
using teleop::rt::PeriodicLoop;
using teleop::transport::NodeStateRecord;
using teleop::transport::Role;

constexpr auto kPeriod = 1ms;
constexpr std::uint64_t kWarmupCycles = 1000;

struct Options {
  std::string mode{};
  double duration_s{20.0};
  int priority{80};
  bool mlock{true};
  int dma_latency_us{-1};
  // --mode nodes
  std::string master_bin{};
  std::string slave_bin{};
  std::string config{};
  int port_base{25560};
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
    if (a == "--mode") {
      o.mode = value();
    } else if (a == "--duration") {
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
    } else if (a == "--master-bin") {
      o.master_bin = value();
    } else if (a == "--slave-bin") {
      o.slave_bin = value();
    } else if (a == "--config") {
      o.config = value();
    } else if (a == "--port-base") {
      o.port_base = std::stoi(value());
    } else {
      throw std::invalid_argument("unknown option " + a);
    }
  }
  if (!mlock_given) o.mlock = o.priority > 0;
  if (o.mode != "udp" && o.mode != "zmq" && o.mode != "nodes") {
    throw std::invalid_argument("--mode udp, zmq or nodes");
  }
  if (o.mode == "nodes" && (o.master_bin.empty() || o.slave_bin.empty() || o.config.empty())) {
    throw std::invalid_argument("--mode nodes needs --master-bin, --slave-bin and --config");
  }
  if (!(o.duration_s > 0.0)) throw std::invalid_argument("--duration must be > 0");
  return o;
}

std::size_t sample_count(const Options& o) {
  return static_cast<std::size_t>(std::llround(o.duration_s * 1000.0));
}

// Round trips in a preallocated array, written by one receiver thread.
struct RoundTrips {
  explicit RoundTrips(std::size_t n) : ns(n, 0) {}
  void add(std::int64_t rtt_ns) {
    if (count < ns.size()) ns[count++] = rtt_ns;
  }
  std::vector<std::int64_t> ns;
  std::size_t count{0};
};

void print(const Options& o, RoundTrips& r, std::size_t expected, const std::string& note) {
  if (r.count == 0) throw std::runtime_error("no round trip measured");
  std::vector<std::int64_t> v(r.ns.begin(), r.ns.begin() + static_cast<std::ptrdiff_t>(r.count));
  std::sort(v.begin(), v.end());
  auto one_way_us = [&](double q) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
    return static_cast<double>(v[std::max<std::size_t>(rank, 1) - 1]) * 0.5e-3;
  };
  std::cout << fmt::format(
      "link mode={} samples={} lost={} p50_us={:.1f} p99_us={:.1f} p999_us={:.1f} "
      "max_us={:.1f}\n# one-way = round trip / 2; SCHED_{} {} on the loop thread, mlockall {}, "
      "cpu_dma_latency {}{}\n",
      o.mode, v.size(), expected > v.size() ? expected - v.size() : 0, one_way_us(0.5),
      one_way_us(0.99), one_way_us(0.999), static_cast<double>(v.back()) * 0.5e-3,
      o.priority > 0 ? "FIFO" : "OTHER", o.priority, o.mlock ? "on" : "off",
      o.dma_latency_us >= 0 ? std::to_string(o.dma_latency_us) + " us" : "untouched", note);
}

// When each ping left, by sequence (the loop thread writes, the receiver reads).
class SendTimes {
 public:
  void sent(std::uint64_t seq, std::int64_t t_ns) noexcept {
    Slot& s = slots_[seq % slots_.size()];
    s.t_ns.store(t_ns, std::memory_order_relaxed);
    s.seq.store(seq, std::memory_order_release);
  }
  [[nodiscard]] std::optional<std::int64_t> at(std::uint64_t seq) const noexcept {
    const Slot& s = slots_[seq % slots_.size()];
    if (s.seq.load(std::memory_order_acquire) != seq) return std::nullopt;
    return s.t_ns.load(std::memory_order_relaxed);
  }

 private:
  struct Slot {
    std::atomic<std::uint64_t> seq{0};
    std::atomic<std::int64_t> t_ns{0};
  };
  std::array<Slot, 4096> slots_{};
};

// The pinger's loop: one ping per cycle, kWarmupCycles uncounted, then `samples` counted.
// `send(seq, t_ns)` runs on the RT thread.
void run_pinger(const Options& o, std::size_t samples, SendTimes& times,
                const std::function<void(std::uint64_t, std::int64_t)>& send) {
  std::optional<teleop::rt::CpuDmaLatency> dma;
  if (o.dma_latency_us >= 0) {
    dma.emplace(o.dma_latency_us);
    if (dma->refusal()) throw std::runtime_error(*dma->refusal());
  }
  const std::uint64_t last = kWarmupCycles + samples;
  std::uint64_t seq = 0;
  PeriodicLoop loop(kPeriod, teleop::rt::RtSettings{o.priority, o.mlock, -1, true},
                    [&](std::chrono::nanoseconds) {
                      if (seq >= last) return;
                      const std::int64_t t0 = PeriodicLoop::monotonic_now().count();
                      ++seq;
                      times.sent(seq, t0);
                      send(seq, t0);
                    });
  loop.start();
  // The last echo gets 200 ms after the last ping.
  std::this_thread::sleep_for(kPeriod * static_cast<std::int64_t>(last) + 200ms);
  loop.stop();
}

// ---- raw UDP ----

int udp_socket() {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
    throw std::runtime_error(std::string("bind: ") + std::strerror(errno));
  }
  const timeval timeout{0, 50'000};  // so the threads notice the end
  (void)::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof(timeout));
  return fd;
}

void udp_connect(int fd, int to) {
  sockaddr_in a{};
  socklen_t len = sizeof(a);
  if (::getsockname(to, reinterpret_cast<sockaddr*>(&a), &len) != 0 ||
      ::connect(fd, reinterpret_cast<sockaddr*>(&a), len) != 0) {
    throw std::runtime_error(std::string("connect: ") + std::strerror(errno));
  }
}

void run_udp(const Options& o) {
  // The same bytes on the wire as a NodeState.
  NodeStateRecord typical;
  typical.session_id = 0x0123456789abcdefULL;
  typical.sequence = 1'000'000;
  typical.sample_time_ns = PeriodicLoop::monotonic_now().count();
  typical.last_peer_sequence = 999'999;
  typical.peer_age_ns = 250'000;
  typical.role = Role::kMaster;
  typical.mode = 3;
  typical.position_m = 0.0123;
  typical.velocity_m_per_s = -0.045;
  const std::size_t size = std::max<std::size_t>(teleop::transport::encode(typical).size(), 8);

  const int pinger = udp_socket();
  const int echo = udp_socket();
  udp_connect(pinger, echo);
  udp_connect(echo, pinger);
  const std::size_t samples = sample_count(o);
  RoundTrips rtts(samples);
  SendTimes times;
  std::atomic<bool> running{true};
  std::thread echoer([&] {
    std::array<char, 2048> buf{};
    while (running.load()) {
      const ssize_t n = ::recv(echo, buf.data(), buf.size(), 0);
      if (n > 0) (void)::send(echo, buf.data(), static_cast<std::size_t>(n), 0);
    }
  });
  std::thread receiver([&] {
    std::array<char, 2048> buf{};
    while (running.load()) {
      const ssize_t n = ::recv(pinger, buf.data(), buf.size(), 0);
      const std::int64_t arrival = PeriodicLoop::monotonic_now().count();
      if (n < 8) continue;
      std::uint64_t seq = 0;
      std::memcpy(&seq, buf.data(), sizeof(seq));
      const auto sent = times.at(seq);
      if (seq > kWarmupCycles && sent) rtts.add(arrival - *sent);
    }
  });
  std::vector<char> payload(size, 0x5a);
  run_pinger(o, samples, times, [&](std::uint64_t seq, std::int64_t) {
    std::memcpy(payload.data(), &seq, sizeof(seq));
    (void)::send(pinger, payload.data(), payload.size(), MSG_DONTWAIT);
  });
  running = false;
  echoer.join();
  receiver.join();
  ::close(pinger);
  ::close(echo);
  print(o, rtts, samples, fmt::format("; {}-byte datagrams on 127.0.0.1", size));
}

// ---- our link ----

// node_app's receiver: wait up to 20 ms for a frame, drain everything queued through the
// filter, stamp each frame's arrival; `on_newest` gets the newest accepted one of the drain.
void receive_like_node_app(zmq::socket_t& sub, teleop::transport::PeerStateFilter& filter,
                           const std::atomic<bool>& running,
                           const std::function<void(const NodeStateRecord&, std::int64_t)>& on) {
  zmq::message_t frame;
  while (running.load()) {
    zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
    try {
      if (zmq::poll(&item, 1, 20ms) <= 0) continue;
    } catch (const zmq::error_t&) {
      continue;
    }
    std::optional<std::pair<NodeStateRecord, std::int64_t>> newest;
    while (sub.recv(frame, zmq::recv_flags::dontwait)) {
      const std::int64_t arrival = PeriodicLoop::monotonic_now().count();
      const auto accepted =
          filter.accept(std::string_view(static_cast<const char*>(frame.data()), frame.size()));
      if (accepted) newest.emplace(accepted->record, arrival);
    }
    if (newest) on(newest->first, newest->second);
  }
}

void run_zmq(const Options& o) {
  using namespace teleop::transport;
  const LinkSecurity plaintext{};  // loopback: what the examples run
  zmq::context_t master_ctx(1);
  zmq::context_t slave_ctx(1);
  zmq::socket_t master_pub = make_state_publisher(master_ctx, "tcp://127.0.0.1:*", plaintext);
  zmq::socket_t slave_pub = make_state_publisher(slave_ctx, "tcp://127.0.0.1:*", plaintext);
  zmq::socket_t slave_sub = make_state_subscriber(slave_ctx, bound_endpoint(master_pub), plaintext);
  zmq::socket_t master_sub =
      make_state_subscriber(master_ctx, bound_endpoint(slave_pub), plaintext);

  const std::size_t samples = sample_count(o);
  RoundTrips rtts(samples);
  SendTimes times;
  std::atomic<bool> running{true};
  teleop::rt::LatestValue<NodeStateRecord> state_out;
  std::atomic<std::uint32_t> published{0};

  // node_app's sender.
  std::thread sender([&] {
    std::uint32_t seen = published.load(std::memory_order_acquire);
    NodeStateRecord state;
    while (running.load()) {
      published.wait(seen, std::memory_order_acquire);
      seen = published.load(std::memory_order_acquire);
      if (!running.load()) break;
      if (!state_out.read(state)) continue;
      const std::string bytes = encode(state);
      (void)master_pub.send(zmq::buffer(bytes), zmq::send_flags::dontwait);
    }
  });
  // The slave side: the echo leaves as soon as the ping is through the filter; its hold time
  // (peer_age) is 0, so everything from arrival to send counts in the round trip.
  std::thread echoer([&] {
    PeerStateFilter filter(Role::kMaster);
    std::uint64_t seq = 0;
    receive_like_node_app(slave_sub, filter, running,
                          [&](const NodeStateRecord& ping, std::int64_t) {
                            NodeStateRecord reply;
                            reply.session_id = 2;
                            reply.sequence = ++seq;
                            reply.sample_time_ns = PeriodicLoop::monotonic_now().count();
                            reply.last_peer_sequence = ping.sequence;
                            reply.peer_age_ns = 0;
                            reply.role = Role::kSlave;
                            reply.mode = 1;
                            const std::string bytes = encode(reply);
                            (void)slave_pub.send(zmq::buffer(bytes), zmq::send_flags::dontwait);
                          });
  });
  std::thread receiver([&] {
    PeerStateFilter filter(Role::kSlave);
    receive_like_node_app(master_sub, filter, running,
                          [&](const NodeStateRecord& echo, std::int64_t arrival) {
                            const auto sent = times.at(echo.last_peer_sequence);
                            if (echo.last_peer_sequence > kWarmupCycles && sent) {
                              rtts.add(arrival - *sent - echo.peer_age_ns);
                            }
                          });
  });
  run_pinger(o, samples, times, [&](std::uint64_t seq, std::int64_t t0) {
    // What NodeCore::step hands over (a master state, disarmed).
    NodeStateRecord state;
    state.session_id = 1;
    state.sequence = seq;
    state.sample_time_ns = t0;
    state.role = Role::kMaster;
    state.mode = 1;
    state.position_m = 0.0123;
    state.velocity_m_per_s = -0.045;
    state_out.write(state);
    published.fetch_add(1, std::memory_order_release);
    published.notify_one();
  });
  running = false;
  published.fetch_add(1);
  published.notify_all();
  sender.join();
  echoer.join();
  receiver.join();
  print(o, rtts, samples, "; ZeroMQ PUB/SUB over tcp://127.0.0.1, plaintext");
}

// ---- the real processes ----

pid_t spawn(const std::string& binary, const std::vector<std::string>& args) {
  std::vector<std::string> all{binary};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  // Their log lines would interleave with the results: stdout to /dev/null, stderr kept.
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, "/dev/null", O_WRONLY, 0);
  pid_t pid = 0;
  const int rc = ::posix_spawn(&pid, binary.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) throw std::runtime_error("cannot start " + binary + ": " + std::strerror(rc));
  return pid;
}

void run_nodes(const Options& o) {
  auto endpoint = [&](int offset) {
    return fmt::format("tcp://127.0.0.1:{}", o.port_base + offset);
  };
  std::vector<std::string> args{o.config, "--set=sample_rate_hz=1000"};
  int offset = 0;
  for (const std::string side : {"master", "slave"}) {
    const std::string n = "--set=" + side + ".node.";
    args.push_back("--set=" + side + ".device.kind=SIM");
    args.push_back(n + "state_endpoint=" + endpoint(offset));
    args.push_back(n + "command_endpoint=" + endpoint(offset + 2));
    args.push_back(n + "telemetry_endpoint=" + endpoint(offset + 4));
    args.push_back(n + "rt.fifo_priority=" + std::to_string(o.priority));
    args.push_back(n + "rt.lock_memory=" + (o.mlock ? "true" : "false"));
    args.push_back(n + "rt.cpu_dma_latency_us=" + std::to_string(o.dma_latency_us));
    ++offset;
  }
  zmq::context_t ctx(1);
  zmq::socket_t telemetry(ctx, zmq::socket_type::sub);
  telemetry.set(zmq::sockopt::linger, 0);
  telemetry.set(zmq::sockopt::rcvhwm, 100'000);  // every batch counts
  telemetry.set(zmq::sockopt::subscribe, "");
  telemetry.connect(endpoint(4));

  const pid_t master = spawn(o.master_bin, args);
  const pid_t slave = spawn(o.slave_bin, args);
  const std::size_t samples = sample_count(o);
  RoundTrips rtts(samples);
  std::optional<std::uint64_t> first_cycle;
  std::uint64_t last_peer_sequence = 0;
  teleop::v1::Telemetry last;
  const auto give_up =
      std::chrono::steady_clock::now() + 10s + std::chrono::duration<double>(o.duration_s * 2);
  while (rtts.count < samples && std::chrono::steady_clock::now() < give_up) {
    zmq::message_t msg;
    zmq::pollitem_t item{telemetry.handle(), 0, ZMQ_POLLIN, 0};
    if (zmq::poll(&item, 1, 100ms) <= 0 || !telemetry.recv(msg, zmq::recv_flags::dontwait)) {
      continue;
    }
    teleop::v1::Telemetry t;
    if (!t.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) continue;
    for (const teleop::v1::CycleRecord& c : t.cycles()) {
      if (c.round_trip_ns() <= 0) continue;
      if (!first_cycle) first_cycle = c.sequence();
      // A new round trip is measured in the cycles that took a new slave state.
      if (c.sequence() > *first_cycle + kWarmupCycles && c.peer_sequence() != last_peer_sequence) {
        rtts.add(c.round_trip_ns());
      }
      last_peer_sequence = c.peer_sequence();
    }
    last = t;
  }
  ::kill(master, SIGINT);
  ::kill(slave, SIGINT);
  int status = 0;
  ::waitpid(master, &status, 0);
  ::waitpid(slave, &status, 0);
  print(o, rtts, samples,
        fmt::format("; the master's telemetry, its own histogram (bin upper edges): p50 {:.1f}, "
                    "p99 {:.1f} us one-way; wake-up p99 {:.1f} us; refused RT settings: {}",
                    static_cast<double>(last.link().round_trip_p50_ns()) * 0.5e-3,
                    static_cast<double>(last.link().round_trip_p99_ns()) * 0.5e-3,
                    static_cast<double>(last.loop().wakeup_p99_ns()) * 1e-3,
                    last.rt().refused_size()));
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Options o = parse(argc, argv);
    if (o.mode == "udp") run_udp(o);
    if (o.mode == "zmq") run_zmq(o);
    if (o.mode == "nodes") run_nodes(o);
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "bench_link_latency: " << e.what() << "\n";
    return 1;
  }
}
