// Runs the real teleop-master / teleop-slave (and teleop-supervisor) processes on loopback and
// watches them through their own telemetry and command endpoints (the supervisor's through
// its request endpoint). Waits are for conditions seen in telemetry (with a
// generous bound against a hang), never for time to pass; deadlines are checked from the
// nodes' own timestamps.
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>
#include <zmq.hpp>

#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::test {

using namespace std::chrono_literals;

// A TCP port on 127.0.0.1 that is free now and that this process has not handed out before.
// Picked below the kernel's ephemeral range (32768-60999 on Debian), so that no outgoing
// connection of a node can take it between the pick and the node's bind, and never twice in
// one process: bind(port 0) may hand the same port out again once it has been closed, which
// once gave the relay and the master's command server the same port.
inline int free_port() {
  static std::mutex mutex;
  static std::set<int> handed_out;
  static unsigned next = 20000u + static_cast<unsigned>(::getpid()) * 7919u % 12000u;
  const std::lock_guard<std::mutex> lock{mutex};
  for (int tries = 0; tries < 12000; ++tries) {
    const int port = 20000 + static_cast<int>(next++ % 12000u);
    if (handed_out.count(port) != 0) continue;
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    const bool free = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
    ::close(fd);
    if (free) {
      handed_out.insert(port);
      return port;
    }
  }
  std::abort();
}

struct Ports {
  int master_state{free_port()};
  int slave_state{free_port()};
  int master_command{free_port()};
  int slave_command{free_port()};
  int master_telemetry{free_port()};
  int slave_telemetry{free_port()};
};

inline std::string tcp(int port) { return "tcp://127.0.0.1:" + std::to_string(port); }

// A node section for loopback on these ports, every cycle in telemetry at 100 Hz, no memory
// locking (the sanitizer build's shadow memory), no real-time scheduling unless asked for
// (`fifo_priority`: used where the kernel permits it, a warning otherwise).
inline std::string node_section(const Ports& p, bool master, const std::string& extra = "",
                                int fifo_priority = 0) {
  const int state = master ? p.master_state : p.slave_state;
  const int command = master ? p.master_command : p.slave_command;
  const int telemetry = master ? p.master_telemetry : p.slave_telemetry;
  return "node { state_endpoint: \"" + tcp(state) + "\" command_endpoint: \"" + tcp(command) +
         "\" telemetry_endpoint: \"" + tcp(telemetry) +
         "\" telemetry_rate_hz: 100 rt { fifo_priority: " + std::to_string(fifo_priority) +
         " lock_memory: false "
         "cpu_dma_latency_us: -1 } " +
         extra + " }";
}

// The paper's paddles at 1 kHz (the live tests' system): the two device sections with the
// given node sections and slave extras (a fixture), the paper's gains, a fixed human pushing
// `push_N` from engagement on, a 20 ms engage ramp. The caller appends the rest (supervisor).
inline std::string paddles_system(const std::string& master_node, const std::string& slave_node,
                                  const std::string& slave_extra, double push_N) {
  return "sample_rate_hz: 1000\n"
         "master { device { mass_kg: 0.040 damping_Ns_per_m: 0.41 } " +
         master_node +
         " }\n"
         "slave { device { mass_kg: 0.036 damping_Ns_per_m: 0.49 } " +
         slave_extra + " " + slave_node +
         " }\n"
         "gains { kpm: 600 kps: 600 kdm: 2 kds: 2 }\n"
         "velocity_filter { cutoff_hz: 200 }\n"
         "human { fixed { mass_kg: 0.012 damping_Ns_per_m: 0.76 stiffness_N_per_m: 70 } }\n"
         "scene { duration_s: 3 seed: 1 human_force { constant { force_N: " +
         std::to_string(push_N) +
         " } } }\n"
         "link { engage_ramp_ms: 20 }\n";
}

// A plaintext loopback system whose supervisor retunes the nodes must opt in by name: without
// CURVE keys a node refuses every RETUNE (common/runtime/command_authority.hpp). Appended to
// the configuration of the live tests that need it.
inline constexpr const char* kAllowUnauthenticatedRetune =
    "security { allow_unauthenticated_retune: true }\n";

class TempDir {
 public:
  TempDir() {
    std::string tmpl = (std::filesystem::temp_directory_path() / "teleop-nodes-XXXXXX").string();
    path_ = ::mkdtemp(tmpl.data());
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  [[nodiscard]] const std::filesystem::path& path() const { return path_; }
  std::filesystem::path write(const std::string& name, const std::string& text) const {
    const auto p = path_ / name;
    std::ofstream(p) << text;
    return p;
  }

 private:
  std::filesystem::path path_;
};

// `binary` with `args` started in a child process, its stdout+stderr in `log`: the child's pid.
// Everything the child needs is made before the fork: this process has threads (ZeroMQ's, the
// telemetry taps'), so the child may call only async-signal-safe functions until its exec. An
// allocation there can wait forever on a lock another thread held at the fork (clang 14's ASan
// takes no allocator lock around fork): a supervisor that never started, its log empty.
inline pid_t spawn_logged(const std::string& binary, const std::vector<std::string>& args,
                          const std::filesystem::path& log) {
  std::vector<char*> argv;
  argv.reserve(args.size() + 2);
  argv.push_back(const_cast<char*>(binary.c_str()));
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const std::string log_path = log.string();
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int fd = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(fd, 1);
    ::dup2(fd, 2);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return pid;
}

// A child process with its stdout+stderr in a file.
class Process {
 public:
  Process(const std::string& binary, const std::vector<std::string>& args,
          const std::filesystem::path& log)
      : log_(log), pid_(spawn_logged(binary, args, log)) {}
  ~Process() {
    if (pid_ > 0 && !waited_) {
      ::kill(pid_, SIGKILL);
      (void)wait();
    }
  }
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  void signal(int sig) const { ::kill(pid_, sig); }
  [[nodiscard]] pid_t pid() const { return pid_; }
  // The exit status (or 128 + signal) if the process has ended, without waiting.
  [[nodiscard]] std::optional<int> exited() {
    if (waited_) return exit_status_;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) != pid_) return std::nullopt;
    waited_ = true;
    exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    return exit_status_;
  }
  // Exit status (or 128 + signal).
  int wait() {
    if (waited_) return exit_status_;
    int status = 0;
    ::waitpid(pid_, &status, 0);
    waited_ = true;
    exit_status_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    return exit_status_;
  }
  [[nodiscard]] std::string log() const {
    std::ifstream in(log_);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }

 private:
  std::filesystem::path log_;
  pid_t pid_{-1};
  bool waited_{false};
  int exit_status_{0};
};

// Bounded wait (against a hang) for a condition polled every few ms; true once it holds.
inline bool eventually(const std::function<bool()>& pred, std::chrono::milliseconds bound = 20s) {
  const auto until = std::chrono::steady_clock::now() + bound;
  while (std::chrono::steady_clock::now() < until) {
    if (pred()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return pred();
}

// Host-timing evidence (docs/testing.md "Host stalls"): a node's own telemetry showing that the
// host, not the node, broke the test's premise of an engaged pair on a real-time loop: a cycle
// that woke 10 ms or more after its deadline (ten periods at 1 kHz; the nodes wake well within
// 1 ms here), or a node that went safe because its own loop stalled or overran in a burst.
// Every TelemetryTap reports what it sees; when a test fails with such evidence, the listener
// below says so and leaves a file named after the test in $TELEOP_HOST_TIMING_DIR, and
// scripts/test.sh runs that test again (at most twice). A failure without evidence is final.
class HostTiming {
 public:
  static HostTiming& instance() {
    static HostTiming h;
    return h;
  }
  void note(const std::string& what) {
    std::lock_guard lock(mutex_);
    if (std::find(evidence_.begin(), evidence_.end(), what) != evidence_.end()) return;
    if (evidence_.size() < 8) evidence_.push_back(what);
    ++count_;
  }
  void note_cycle(const v1::CycleRecord& c, const std::string& node) {
    if (c.wakeup_latency_ns() >= 10'000'000) {
      note(node + " woke " + std::to_string(c.wakeup_latency_ns() / 1'000'000) + " ms late at " +
           std::to_string(c.sample_time_ns()) + " ns");
    }
  }
  void note_reason(const std::string& reason, const std::string& node) {
    if (reason.find("own loop") != std::string::npos) note(node + " went safe: " + reason);
  }
  // A test that stalls a node on purpose (SIGSTOP) says so: evidence within it is the test's.
  void injecting(bool on) {
    std::lock_guard lock(mutex_);
    injecting_ = on;
  }
  [[nodiscard]] bool injecting() const {
    std::lock_guard lock(mutex_);
    return injecting_;
  }
  void clear() {
    std::lock_guard lock(mutex_);
    evidence_.clear();
    count_ = 0;
    injecting_ = false;
  }
  [[nodiscard]] std::string evidence() const {
    std::lock_guard lock(mutex_);
    std::string out;
    for (const std::string& e : evidence_) out += (out.empty() ? "" : "; ") + e;
    if (count_ > evidence_.size())
      out += "; " + std::to_string(count_ - evidence_.size()) + " more";
    return out;
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> evidence_;
  std::size_t count_{0};
  bool injecting_{false};
};

// The file scripts/test.sh looks for: `dir`/SUITE.NAME ('/' of a parameterized name as '_'),
// holding the evidence; returns its path.
inline std::filesystem::path write_host_timing_evidence(const std::filesystem::path& dir,
                                                        std::string name,
                                                        const std::string& evidence) {
  for (char& ch : name) {
    if (ch == '/') ch = '_';
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  const std::filesystem::path file = dir / name;
  std::ofstream(file) << evidence << "\n";
  return file;
}

class HostTimingListener : public ::testing::EmptyTestEventListener {
  void OnTestStart(const ::testing::TestInfo&) override { HostTiming::instance().clear(); }
  void OnTestEnd(const ::testing::TestInfo& info) override {
    const std::string evidence = HostTiming::instance().evidence();
    if (!info.result()->Failed() || evidence.empty()) return;
    const std::string name = std::string(info.test_suite_name()) + "." + info.name();
    std::cout << "[host timing] " << name << " failed with the host's stalls in the nodes' "
              << "telemetry: " << evidence << "\n";
    const char* dir = std::getenv("TELEOP_HOST_TIMING_DIR");
    if (dir == nullptr || *dir == '\0') return;
    write_host_timing_evidence(dir, name, evidence);
  }
};

inline const bool kHostTimingListening = [] {
  ::testing::UnitTest::GetInstance()->listeners().Append(new HostTimingListener);
  return true;
}();

// Collects every telemetry message of one node on a thread of its own.
class TelemetryTap {
 public:
  TelemetryTap(zmq::context_t& ctx, const std::string& endpoint,
               std::function<void(zmq::socket_t&)> secure = {})
      : socket_(ctx, zmq::socket_type::sub), endpoint_(endpoint) {
    socket_.set(zmq::sockopt::linger, 0);
    socket_.set(zmq::sockopt::rcvhwm, 100000);
    if (secure) secure(socket_);
    socket_.set(zmq::sockopt::subscribe, "");
    socket_.connect(endpoint);
    thread_ = std::thread([this] {
      while (running_) {
        zmq::pollitem_t item{socket_.handle(), 0, ZMQ_POLLIN, 0};
        if (zmq::poll(&item, 1, 20ms) <= 0) continue;
        zmq::message_t msg;
        while (socket_.recv(msg, zmq::recv_flags::dontwait)) {
          v1::Telemetry t;
          if (!t.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) continue;
          note_host_timing(t);
          std::lock_guard lock(mutex_);
          for (const auto& c : t.cycles()) cycles_.push_back(c);
          last_ = t;
          ++messages_;
        }
      }
    });
  }
  ~TelemetryTap() {
    running_ = false;
    thread_.join();
  }
  [[nodiscard]] std::vector<v1::CycleRecord> cycles() const {
    std::lock_guard lock(mutex_);
    return cycles_;
  }
  [[nodiscard]] std::optional<v1::Telemetry> last() const {
    std::lock_guard lock(mutex_);
    return last_;
  }
  [[nodiscard]] std::size_t messages() const {
    std::lock_guard lock(mutex_);
    return messages_;
  }
  [[nodiscard]] std::optional<v1::NodeMode> mode() const {
    std::lock_guard lock(mutex_);
    if (!last_) return std::nullopt;
    return last_->mode();
  }
  // Waits (bounded, against a hang) until pred holds on the latest telemetry.
  bool wait_for(const std::function<bool(const v1::Telemetry&)>& pred,
                std::chrono::milliseconds bound = 20s) const {
    const auto until = std::chrono::steady_clock::now() + bound;
    while (std::chrono::steady_clock::now() < until) {
      // The predicate may read the tap itself: call it without the lock.
      if (const std::optional<v1::Telemetry> t = last(); t && pred(*t)) return true;
      std::this_thread::sleep_for(5ms);
    }
    return false;
  }
  bool wait_for_mode(v1::NodeMode mode, std::chrono::milliseconds bound = 20s) const {
    return wait_for([mode](const v1::Telemetry& t) { return t.mode() == mode; }, bound);
  }

 private:
  // The host's stalls as this node saw them (HostTiming): its RT loop late, or its telemetry
  // thread (an ordinary thread, like the ones that carry the peer link) silent for 40 ms and
  // four of its own periods (shortest intervals of 5 ms or more), on the node's own clock.
  void note_host_timing(const v1::Telemetry& t) {
    HostTiming& h = HostTiming::instance();
    const std::int64_t sent = t.sent_time_ns();
    if (last_sent_ns_ > 0 && sent > last_sent_ns_) {
      const std::int64_t gap = sent - last_sent_ns_;
      if (min_interval_ns_ > 0 && gap >= 40'000'000 && gap >= 4 * min_interval_ns_ &&
          !h.injecting()) {
        h.note(endpoint_ + " telemetry silent " + std::to_string(gap / 1'000'000) + " ms");
      }
      // Its period: messages sent out of turn (a mode change, a flight record) come sooner.
      if (gap >= 5'000'000 && (min_interval_ns_ == 0 || gap < min_interval_ns_)) {
        min_interval_ns_ = gap;
      }
    }
    last_sent_ns_ = sent;
    if (h.injecting()) return;
    for (const auto& c : t.cycles()) h.note_cycle(c, endpoint_);
    if (t.mode_reason() != last_reason_) h.note_reason(t.mode_reason(), endpoint_);
    last_reason_ = t.mode_reason();
  }

  std::string last_reason_;
  std::int64_t last_sent_ns_{0};
  std::int64_t min_interval_ns_{0};
  zmq::socket_t socket_;
  std::string endpoint_;
  std::atomic<bool> running_{true};
  mutable std::mutex mutex_;
  std::vector<v1::CycleRecord> cycles_;
  std::optional<v1::Telemetry> last_;
  std::size_t messages_{0};
  std::thread thread_;
};

// One command, one reply (nullopt on timeout).
inline std::optional<v1::NodeCommandReply> send_command(
    zmq::context_t& ctx, const std::string& endpoint, const v1::NodeCommand& c,
    std::function<void(zmq::socket_t&)> secure = {}) {
  zmq::socket_t s(ctx, zmq::socket_type::req);
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::rcvtimeo, 5000);
  if (secure) secure(s);
  s.connect(endpoint);
  const std::string bytes = c.SerializeAsString();
  s.send(zmq::buffer(bytes), zmq::send_flags::none);
  zmq::message_t reply;
  if (!s.recv(reply)) return std::nullopt;
  v1::NodeCommandReply r;
  if (!r.ParseFromArray(reply.data(), static_cast<int>(reply.size()))) return std::nullopt;
  return r;
}

// One command of `kind` (no update), one reply.
inline std::optional<v1::NodeCommandReply> send_command(
    zmq::context_t& ctx, const std::string& endpoint, v1::NodeCommand::Kind kind,
    std::function<void(zmq::socket_t&)> secure = {}) {
  v1::NodeCommand c;
  c.set_kind(kind);
  return send_command(ctx, endpoint, c, std::move(secure));
}

// The supervisor's status from its request endpoint on this port (nullopt on timeout or a
// reply without one).
inline std::optional<v1::SupervisorStatus> supervisor_status(zmq::context_t& ctx, int port) {
  zmq::socket_t s(ctx, zmq::socket_type::req);
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::rcvtimeo, 2000);
  s.connect(tcp(port));
  v1::SupervisorRequest req;
  req.mutable_status();
  const std::string bytes = req.SerializeAsString();
  s.send(zmq::buffer(bytes), zmq::send_flags::none);
  zmq::message_t reply;
  if (!s.recv(reply)) return std::nullopt;
  v1::SupervisorReply r;
  if (!r.ParseFromArray(reply.data(), static_cast<int>(reply.size())) || !r.has_status()) {
    return std::nullopt;
  }
  return r.status();
}

}  // namespace teleop::test
