// Hostile bytes on the wire against the real processes (issue 14 findings 4 and 5, "No bytes
// can kill a process"): raw TCP clients speaking ZMTP/1.0 (unversioned, 13/ZMTP), 2.0
// (15/ZMTP), 3.0 (23/ZMTP) and 3.1 (37/ZMTP) badly, written here from those specs, against every
// endpoint of a running master, slave and supervisor: multi-part and 2-frame requests,
// truncated, oversized and zero-length frames, unknown mechanisms and commands, subscription
// floods, connection floods and clients that never read. After each attack every process is
// still running and answering, and both nodes were ENGAGED on every cycle of their telemetry
// (CycleRecord.mode) from before the attack to after it. One system for the whole file (each
// test starts from where the previous left it, engaged), so the file runs in well under a
// minute. TELEOP_{MASTER,SLAVE,SUPERVISOR}_BIN override the binaries (to run the attacks
// against an older build).
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <iostream>

#include "tests/integration/node_harness.hpp"
#include "tests/support/sanitizer.hpp"

namespace teleop::test {
namespace {

using Bytes = std::string;

std::string bin(const char* env, const char* built) {
  const char* v = std::getenv(env);
  return v != nullptr && *v != '\0' ? std::string(v) : std::string(built);
}

// --- ZMTP, from the specs ---------------------------------------------------------------------

// 23/ZMTP and 37/ZMTP: signature (0xFF, 8 octets of padding, 0x7F), version major 3 and
// minor, the mechanism name padded with zeros to 20 octets, as-server, 31 octets of filler.
Bytes greeting3(const std::string& mechanism = "NULL", char minor = 0) {
  Bytes g;
  g += '\xff';
  g += Bytes(8, '\0');
  g += '\x7f';
  g += '\x03';
  g += minor;
  Bytes m = mechanism;
  m.resize(20, '\0');
  g += m;
  g += '\0';  // as-server: we are the client
  g += Bytes(31, '\0');
  return g;
}

constexpr unsigned char kMore = 0x01;
constexpr unsigned char kLong = 0x02;
constexpr unsigned char kCommand = 0x04;

// A ZMTP 2.0/3.x frame: flags, size (one octet, or 8 in network order with the LONG flag),
// body.
Bytes frame(const Bytes& body, unsigned char flags = 0, bool force_long = false) {
  Bytes f;
  if (body.size() > 255 || force_long) {
    f += static_cast<char>(flags | kLong);
    for (int i = 7; i >= 0; --i) {
      f += static_cast<char>((static_cast<std::uint64_t>(body.size()) >> (8 * i)) & 0xff);
    }
  } else {
    f += static_cast<char>(flags);
    f += static_cast<char>(body.size());
  }
  return f + body;
}

// A long frame header announcing `size` octets (the body is the caller's, or never comes).
Bytes long_header(std::uint64_t size, unsigned char flags = 0) {
  Bytes f(1, static_cast<char>(flags | kLong));
  for (int i = 7; i >= 0; --i) f += static_cast<char>((size >> (8 * i)) & 0xff);
  return f;
}

Bytes command(const std::string& name, const Bytes& data = {}) {
  return frame(Bytes(1, static_cast<char>(name.size())) + name + data, kCommand);
}

// A READY command with one property, Socket-Type (name length, name, 4-octet value length,
// value).
Bytes ready(const std::string& socket_type) {
  Bytes p(1, static_cast<char>(std::strlen("Socket-Type")));
  p += "Socket-Type";
  const auto n = static_cast<std::uint32_t>(socket_type.size());
  p += static_cast<char>(n >> 24);
  p += static_cast<char>((n >> 16) & 0xff);
  p += static_cast<char>((n >> 8) & 0xff);
  p += static_cast<char>(n & 0xff);
  p += socket_type;
  return command("READY", p);
}

// 15/ZMTP (ZMTP/2.0): the signature, revision 0x01, the socket type (REQ 3, SUB 2), an empty
// identity frame.
Bytes greeting2(char socket_type) {
  Bytes g;
  g += '\xff';
  g += Bytes(8, '\0');
  g += '\x7f';
  g += '\x01';
  g += socket_type;
  g += Bytes("\x00\x00", 2);
  return g;
}

// 13/ZMTP (ZMTP/1.0, unversioned): frames of a length octet (counting the flags octet), the
// flags (bit 0: MORE) and the body; the greeting is an anonymous identity frame (01 00).
Bytes frame1(const Bytes& body, bool more) {
  return Bytes(1, static_cast<char>(body.size() + 1)) + (more ? '\x01' : '\x00') + body;
}

// A raw TCP client on loopback.
class Raw {
 public:
  explicit Raw(int port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(static_cast<std::uint16_t>(port));
    connected_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
  }
  ~Raw() {
    if (fd_ >= 0) ::close(fd_);
  }
  Raw(const Raw&) = delete;
  Raw& operator=(const Raw&) = delete;
  Raw(Raw&& o) noexcept : fd_(o.fd_), connected_(o.connected_), in_(std::move(o.in_)) {
    o.fd_ = -1;
  }
  [[nodiscard]] bool connected() const { return connected_; }
  // Everything written, unless the peer closed (false then).
  bool send(const Bytes& b) {
    std::size_t off = 0;
    while (off < b.size()) {
      const ssize_t n = ::send(fd_, b.data() + off, b.size() - off, MSG_NOSIGNAL);
      if (n <= 0) return false;
      off += static_cast<std::size_t>(n);
    }
    return true;
  }
  // Reads until `n` octets are buffered or `timeout` passes.
  bool fill(std::size_t n, std::chrono::milliseconds timeout = 2s) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (in_.size() < n) {
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          until - std::chrono::steady_clock::now());
      if (left.count() <= 0) return false;
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) return false;
      char buf[65536];
      const ssize_t got = ::recv(fd_, buf, sizeof(buf), 0);
      if (got <= 0) return false;
      in_.append(buf, static_cast<std::size_t>(got));
    }
    return true;
  }
  // One ZMTP 3.x frame (flags, body); nullopt on timeout or close.
  std::optional<std::pair<unsigned char, Bytes>> read_frame(std::chrono::milliseconds t = 2s) {
    if (!fill(2, t)) return std::nullopt;
    const auto flags = static_cast<unsigned char>(in_[0]);
    std::size_t header = 2;
    std::uint64_t size = static_cast<unsigned char>(in_[1]);
    if ((flags & kLong) != 0) {
      if (!fill(9, t)) return std::nullopt;
      header = 9;
      size = 0;
      for (std::size_t i = 1; i <= 8; ++i) size = (size << 8) | static_cast<unsigned char>(in_[i]);
    }
    if (!fill(header + size, t)) return std::nullopt;
    Bytes body = in_.substr(header, size);
    in_.erase(0, header + size);
    return std::make_pair(flags, body);
  }
  // The server's greeting and its READY: the handshake is complete (messages sent before
  // that count as handshake commands, and fail it).
  bool handshake3(const std::string& socket_type, char minor = 0) {
    if (!send(greeting3("NULL", minor) + ready(socket_type))) return false;
    if (!fill(64)) return false;
    in_.erase(0, 64);
    for (int i = 0; i < 10; ++i) {
      const auto f = read_frame();
      if (!f) return false;
      if ((f->first & kCommand) != 0 && f->second.substr(1, 5) == "READY") return true;
    }
    return false;
  }
  // The parts of the next message (commands such as PING skipped).
  std::optional<std::vector<Bytes>> read_message(std::chrono::milliseconds t = 2s) {
    std::vector<Bytes> parts;
    while (true) {
      const auto f = read_frame(t);
      if (!f) return std::nullopt;
      if ((f->first & kCommand) != 0) continue;
      parts.push_back(f->second);
      if ((f->first & kMore) == 0) return parts;
    }
  }
  // Closes with a TCP reset (SO_LINGER 0) instead of a FIN.
  void reset() {
    linger l{1, 0};
    (void)::setsockopt(fd_, SOL_SOCKET, SO_LINGER, &l, sizeof(l));
    ::close(fd_);
    fd_ = -1;
  }
  // Writes what the socket takes now, without waiting (false when nothing could be written).
  bool send_some(const Bytes& b) {
    return ::send(fd_, b.data(), b.size(), MSG_NOSIGNAL | MSG_DONTWAIT) > 0;
  }
  // Whether the server closed the connection within `timeout` (reading and discarding).
  bool closed_within(std::chrono::milliseconds timeout) {
    const auto until = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < until) {
      pollfd p{fd_, POLLIN, 0};
      if (::poll(&p, 1, 20) <= 0) continue;
      char buf[65536];
      const ssize_t got = ::recv(fd_, buf, sizeof(buf), 0);
      if (got <= 0) return true;
    }
    return false;
  }

 private:
  int fd_{-1};
  bool connected_{false};
  Bytes in_;
};

// --- the system ---------------------------------------------------------------------------------

struct HostilePorts {
  Ports nodes{};
  int report{free_port()};
  int request{free_port()};
};

std::string system_config(const HostilePorts& p) {
  // SCHED_FIFO 80 where the kernel permits it (as deployed; the link threads and libzmq's I/O
  // threads run at 70): the attacks' CPU must not be what takes a node off its deadlines.
  return paddles_system(node_section(p.nodes, true, "", 80), node_section(p.nodes, false, "", 80),
                        "", 0.0) +
         "supervisor { report_endpoint: \"" + tcp(p.report) + "\" request_endpoint: \"" +
         tcp(p.request) + "\" record: false }\n";
}

struct Endpoint {
  std::string name;
  int port;
  std::string kind;  // "state", "command", "telemetry", "report", "request"
};

long status_kb(pid_t pid, const std::string& field) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(field + ":", 0) == 0) return std::stol(line.substr(field.size() + 1));
  }
  return -1;
}

class HostileWire : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { sys_ = new System(); }
  static void TearDownTestSuite() {
    delete sys_;
    sys_ = nullptr;
  }

  struct System {
    TempDir dir;
    HostilePorts ports;
    std::filesystem::path config{dir.write("system.textproto", system_config(ports))};
    Process master{bin("TELEOP_MASTER_BIN", MASTER_BIN), {config.string()}, dir.path() / "m.log"};
    Process slave{bin("TELEOP_SLAVE_BIN", SLAVE_BIN), {config.string()}, dir.path() / "s.log"};
    Process supervisor{
        bin("TELEOP_SUPERVISOR_BIN", SUPERVISOR_BIN), {config.string()}, dir.path() / "sup.log"};
    zmq::context_t ctx{1};
    TelemetryTap mt{ctx, tcp(ports.nodes.master_telemetry)};
    TelemetryTap st{ctx, tcp(ports.nodes.slave_telemetry)};
    bool engaged{false};
    std::string logs() {
      return "--- master\n" + master.log() + "--- slave\n" + slave.log() + "--- supervisor\n" +
             supervisor.log();
    }
  };

  void SetUp() override {
    System& s = *sys_;
    if (!s.engaged) {
      ASSERT_TRUE(s.mt.wait_for([](const v1::Telemetry& t) { return t.link().accepted() > 0; }))
          << s.logs();
      ASSERT_TRUE(s.st.wait_for([](const v1::Telemetry& t) { return t.link().accepted() > 0; }))
          << s.logs();
      for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
        for (const int port : {s.ports.nodes.master_command, s.ports.nodes.slave_command}) {
          const auto r = send_command(s.ctx, tcp(port), kind);
          ASSERT_TRUE(r && r->ok()) << (r ? r->message() : "no reply") << s.logs();
        }
      }
      ASSERT_TRUE(s.mt.wait_for_mode(v1::ENGAGED)) << s.logs();
      ASSERT_TRUE(s.st.wait_for_mode(v1::ENGAGED)) << s.logs();
      s.engaged = true;
    }
    ASSERT_FALSE(s.master.exited() || s.slave.exited() || s.supervisor.exited())
        << "a process ended before this test";
    // Each test from both engaged, whatever the one before it left.
    if (s.mt.mode() != v1::ENGAGED || s.st.mode() != v1::ENGAGED) {
      re_engage();
      if (HasFatalFailure()) return;
    }
    from_master_ = s.mt.cycles().size();
    from_slave_ = s.st.cycles().size();
    ASSERT_EQ(s.mt.mode(), v1::ENGAGED);
    ASSERT_EQ(s.st.mode(), v1::ENGAGED);
  }

  [[nodiscard]] std::vector<Endpoint> endpoints() const {
    const Ports& n = sys_->ports.nodes;
    return {{"master state", n.master_state, "state"},
            {"slave state", n.slave_state, "state"},
            {"master command", n.master_command, "command"},
            {"slave command", n.slave_command, "command"},
            {"master telemetry", n.master_telemetry, "telemetry"},
            {"slave telemetry", n.slave_telemetry, "telemetry"},
            {"supervisor report", sys_->ports.report, "report"},
            {"supervisor request", sys_->ports.request, "request"}};
  }

  // Both nodes left ENGAGED because their own SCHED_FIFO loops were not run for longer than
  // the peer timeout, within 0.1 s of each other: the wake-up latency of the first cycle that
  // left says so. Nothing this test sends runs above those loops (the wire is served by
  // SCHED_OTHER threads), so that is the host (this VM stops both cores for 30 ms and more at
  // times); "" otherwise, and then every other departure fails the test as before.
  std::string host_stall() const {
    System& s = *sys_;
    std::string evidence;
    std::int64_t at[2] = {0, 0};
    int i = 0;
    for (const auto& [tap, from, name] :
         {std::tuple{&s.mt, from_master_, "master"}, std::tuple{&s.st, from_slave_, "slave"}}) {
      const std::vector<v1::CycleRecord> c = tap->cycles();
      const auto left =
          std::find_if(c.begin() + static_cast<std::ptrdiff_t>(from), c.end(),
                       [](const v1::CycleRecord& r) { return r.mode() != v1::ENGAGED; });
      if (left == c.end() || left->wakeup_latency_ns() < 29'000'000) return "";
      at[i++] = left->sample_time_ns() + left->wakeup_latency_ns();
      evidence += std::string(evidence.empty() ? "" : ", ") + name + " woke " +
                  std::to_string(left->wakeup_latency_ns() / 1'000'000) + " ms late";
    }
    return std::abs(at[0] - at[1]) < 100'000'000 ? evidence : "";
  }

  // Where the attacks stood on the nodes' clock (CLOCK_MONOTONIC, as their sample times), so
  // that a departure from ENGAGED names the attack in flight.
  void mark(const std::string& attack) {
    marks_.emplace_back(std::chrono::duration_cast<std::chrono::nanoseconds>(
                            std::chrono::steady_clock::now().time_since_epoch())
                            .count(),
                        attack);
  }
  std::string attack_at(std::int64_t t_ns) const {
    std::string in_flight = "before the first attack";
    for (const auto& [at, what] : marks_) {
      if (at <= t_ns) in_flight = what;
    }
    return in_flight;
  }

  // Every process still running and answering; the supervisor answering; 100 more cycles from
  // both nodes. Then every departure from ENGAGED since the test began ("" for none), and
  // whether each was the link's timeout (a node that heard nothing from its peer for the peer
  // timeout, and the peer that followed it safe).
  // A reason to leave ENGAGED that is the node's own timing or the link's, not something the
  // node decided from what it received: the loop (SCHED_FIFO, above every thread the attacks
  // reach) overran or stalled, or the peer's states stopped arriving (and the peer followed).
  static bool host_or_link_timing(const std::string& reason) {
    return reason == "peer timeout" || reason == "peer safe, faulted or restarted" ||
           reason == "own loop overran in a burst" ||
           reason == "own loop stalled past the peer timeout";
  }
  struct Departures {
    std::string text{};
    bool timing_only{true};
  };
  void expect_all_running(const std::string& what) {
    System& s = *sys_;
    for (auto* p : {&s.master, &s.slave, &s.supervisor}) {
      const std::optional<int> rc = p->exited();
      EXPECT_FALSE(rc.has_value()) << what << ": a process exited with " << *rc << "\n" << s.logs();
    }
  }
  Departures departures(const std::string& what) {
    System& s = *sys_;
    Departures d;
    const bool answered =
        eventually([&] { return supervisor_status(s.ctx, s.ports.request).has_value(); }, 15s);
    // The supervisor answers requests one at a time: after a request flood it answers once
    // it has worked through what was queued (a few seconds for thousands; see the report).
    EXPECT_TRUE(answered) << what << ": the supervisor does not answer\n" << s.logs();
    if (!answered) return {"the supervisor does not answer", false};
    const std::size_t m_now = s.mt.cycles().size();
    const std::size_t s_now = s.st.cycles().size();
    EXPECT_TRUE(eventually([&] {
      return s.mt.cycles().size() > m_now + 100 && s.st.cycles().size() > s_now + 100;
    })) << what;
    for (const auto& [tap, from, name] :
         {std::tuple{&s.mt, from_master_, "master"}, std::tuple{&s.st, from_slave_, "slave"}}) {
      const std::vector<v1::CycleRecord> c = tap->cycles();
      EXPECT_EQ(tap->last()->cycles_dropped(), 0u) << name;
      std::size_t bad = 0;
      const v1::CycleRecord* first = nullptr;
      for (std::size_t i = from; i < c.size(); ++i) {
        if (c[i].mode() != v1::ENGAGED && bad++ == 0) first = &c[i];
      }
      if (bad == 0) continue;
      const std::string reason = tap->last()->mode_reason();
      d.timing_only = d.timing_only && host_or_link_timing(reason);
      d.text += std::string(name) + " left ENGAGED at cycle " + std::to_string(first->sequence()) +
                " (" + reason + "), " + std::to_string(bad) + " of " +
                std::to_string(c.size() - from) + " cycles, during " +
                attack_at(first->sample_time_ns()) + "\n";
    }
    return d;
  }

  // Every process still running and answering, and both nodes ENGAGED on every cycle since
  // the test began, through at least 100 cycles after now.
  void expect_all_alive_and_engaged(const std::string& what) {
    expect_all_running(what);
    if (HasFailure()) return;
    if (const std::string stall = host_stall(); !stall.empty()) {
      // Not a skip: a failure with host-timing evidence, run again by scripts/run-ctest.sh
      // (docs/testing.md "Host stalls"), so the attack is judged on a run the host let happen.
      HostTiming::instance().note("both loops stalled: " + stall);
      FAIL() << what << ": inconclusive, the host stalled both nodes' loops: " << stall;
    }
    System& s = *sys_;
    for (const int port : {s.ports.nodes.master_command, s.ports.nodes.slave_command}) {
      const auto r = send_command(s.ctx, tcp(port), v1::NodeCommand::STATUS);
      ASSERT_TRUE(r.has_value()) << what << ": no STATUS reply from " << port << "\n" << s.logs();
      EXPECT_EQ(r->mode(), v1::ENGAGED) << what << ": " << r->mode_reason();
    }
    const Departures d = departures(what);
    EXPECT_EQ(d.text, "") << what;
  }

  // As expect_all_alive_and_engaged() for an attack run twice when its first run ended only in
  // the nodes' own timing or the link's (host_or_link_timing): on this 2-core VM a host stall
  // of the link's threads past the 30 ms peer timeout happens without any attack (CI saw one in
  // the sanitizer build, master and slave loops on time), and so do bursts of overruns of an
  // ASan-built loop beside another test's nodes. An attack that breaks the link does so on both
  // runs and fails; a process that ends, any other reason to leave ENGAGED, or a supervisor that
  // stops answering fails on the first.
  void attack_twice_if_the_link_timed_out(const std::string& what,
                                          const std::function<void()>& attack) {
    std::string first;
    for (int run = 0; run < 2; ++run) {
      if (run > 0) {
        re_engage();
        if (HasFatalFailure()) return;
      }
      attack();
      if (HasFatalFailure()) return;
      expect_all_running(what);
      if (HasFailure()) return;
      if (const std::string stall = host_stall(); !stall.empty()) {
        HostTiming::instance().note("both loops stalled: " + stall);  // rerun, as above
        FAIL() << what << ": inconclusive, the host stalled both nodes' loops: " << stall;
      }
      const Departures d = departures(what);
      if (d.text.empty()) {
        if (!first.empty()) std::cout << "[ note ] " << what << ", first run: " << first;
        return;
      }
      if (run == 0 && d.timing_only) {
        first = d.text;
        continue;
      }
      ADD_FAILURE() << what << (first.empty() ? "" : ", first run: " + first + "second run: ")
                    << d.text;
      return;
    }
  }

  // Both nodes ENGAGED again, as SetUp() leaves them, counting from now.
  void re_engage() {
    System& s = *sys_;
    for (const auto kind :
         {v1::NodeCommand::CLEAR, v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
      for (const int port : {s.ports.nodes.master_command, s.ports.nodes.slave_command}) {
        (void)send_command(s.ctx, tcp(port), kind);
      }
    }
    ASSERT_TRUE(s.mt.wait_for_mode(v1::ENGAGED, 5s)) << s.logs();
    ASSERT_TRUE(s.st.wait_for_mode(v1::ENGAGED, 5s)) << s.logs();
    from_master_ = s.mt.cycles().size();
    from_slave_ = s.st.cycles().size();
    marks_.clear();
  }

  void bad_greetings();

  static System* sys_;
  std::size_t from_master_{0};
  std::size_t from_slave_{0};
  std::vector<std::pair<std::int64_t, std::string>> marks_{};
};

HostileWire::System* HostileWire::sys_ = nullptr;

bool is_node(const Endpoint& e) { return e.kind == "command"; }

// Finding 4: a request of two parts (libzmq REQ with SNDMORE, and the same written raw in
// ZMTP/1.0, 2.0, 3.0 and 3.1) to each command endpoint. Before: the node's REP read the first
// part only and its reply threw EFSM on the command thread (std::terminate, exit 134); the
// supervisor's reply threw out of its main loop (exit 1). Now: answered "malformed", and the
// endpoint answers the next request.
TEST_F(HostileWire, TwoPartRequestsGetAMalformedReplyAndNoProcessDies) {
  System& s = *sys_;
  for (const Endpoint& e : endpoints()) {
    if (e.kind != "command" && e.kind != "request") continue;
    SCOPED_TRACE(e.name);
    {
      zmq::socket_t req(s.ctx, zmq::socket_type::req);
      req.set(zmq::sockopt::linger, 0);
      req.set(zmq::sockopt::rcvtimeo, 3000);
      req.connect(tcp(e.port));
      req.send(zmq::str_buffer("\x08\x08"), zmq::send_flags::sndmore);
      req.send(zmq::str_buffer("\x08\x08"), zmq::send_flags::none);
      zmq::message_t reply;
      ASSERT_TRUE(req.recv(reply).has_value()) << "no reply to a 2-part request\n" << s.logs();
      if (is_node(e)) {
        v1::NodeCommandReply r;
        ASSERT_TRUE(r.ParseFromArray(reply.data(), static_cast<int>(reply.size())));
        EXPECT_FALSE(r.ok());
        EXPECT_NE(r.message().find("malformed command: 2 parts"), std::string::npos) << r.message();
      } else {
        v1::SupervisorReply r;
        ASSERT_TRUE(r.ParseFromArray(reply.data(), static_cast<int>(reply.size())));
        EXPECT_NE(r.error().find("malformed request: 2 parts"), std::string::npos) << r.error();
      }
    }
    // ZMTP/1.0, 13 octets: anonymous identity, the empty delimiter (MORE), then "a" (MORE),
    // "b" (MORE), "c": a 3-part request. And the 2-part one.
    for (const Bytes& b :
         {Bytes("\x01\x00", 2) + frame1("", true) + frame1("a", true) + frame1("b", true) +
              frame1("c", false),
          Bytes("\x01\x00", 2) + frame1("", true) + frame1("a", true) + frame1("b", false)}) {
      Raw raw(e.port);
      ASSERT_TRUE(raw.connected());
      EXPECT_TRUE(raw.send(b));
      (void)raw.closed_within(100ms);
    }
    // ZMTP/2.0: greeting (REQ), then the delimiter and two parts.
    {
      Raw raw(e.port);
      ASSERT_TRUE(raw.connected());
      EXPECT_TRUE(raw.send(greeting2('\x03') + frame("", kMore) + frame("\x08\x08", kMore) +
                           frame("\x08\x08")));
      (void)raw.closed_within(100ms);
    }
    // ZMTP/3.0 and 3.1: the reply to the 2-part request is read and parsed.
    for (const char minor : {'\x00', '\x01'}) {
      Raw raw(e.port);
      ASSERT_TRUE(raw.handshake3("REQ", minor)) << "no handshake";
      ASSERT_TRUE(raw.send(frame("", kMore) + frame("\x08\x08", kMore) + frame("\x08\x08")));
      const auto reply = raw.read_message();
      ASSERT_TRUE(reply.has_value()) << "no reply to a raw 2-part request\n" << s.logs();
      ASSERT_EQ(reply->size(), 2u);  // the delimiter and the reply
      if (is_node(e)) {
        v1::NodeCommandReply r;
        ASSERT_TRUE(r.ParseFromString(reply->back()));
        EXPECT_NE(r.message().find("malformed"), std::string::npos) << r.message();
      } else {
        v1::SupervisorReply r;
        ASSERT_TRUE(r.ParseFromString(reply->back()));
        EXPECT_NE(r.error().find("malformed"), std::string::npos) << r.error();
      }
    }
  }
  expect_all_alive_and_engaged("2-part requests");
}

// Finding 5: one 1 MB subscription to each publisher, and 200 000 subscriptions to the
// master's state and telemetry publishers, at once and spread out. Before: the 1 MB
// subscription became a million trie nodes built on the master's sender thread, the link
// stalled past its peer timeout and both nodes went safe; spread-out subscriptions grew the
// master for good (23 MB measured for 200 000). Now: a frame over 1 KiB drops its
// connection before it is allocated, a subscriber over its budget is cut and its memory given
// back; the nodes stay engaged and the master's resident memory ends within 16 MB of where it
// was (before: +160 MB).
TEST_F(HostileWire, SubscriptionFloodsKeepBothNodesEngagedWithBoundedMemory) {
  System& s = *sys_;
  const long rss_before = status_kb(s.master.pid(), "VmRSS");
  const v1::LinkStats link_before = s.mt.last()->link();
  for (const Endpoint& e : endpoints()) {
    if (e.kind != "state" && e.kind != "telemetry" && e.kind != "report") continue;
    SCOPED_TRACE(e.name);
    Raw raw(e.port);
    ASSERT_TRUE(raw.handshake3("SUB"));
    (void)raw.send(frame("\x01" + Bytes(1'000'000, 'x')));
    EXPECT_TRUE(raw.closed_within(2s)) << "a 1 MB subscription was taken";
  }
  // 200 000 distinct 4-octet subscriptions in one write, to the master's state and telemetry.
  Bytes flood;
  for (std::uint32_t i = 0; i < 200'000; ++i) {
    Bytes topic("\x01", 1);
    for (int k = 3; k >= 0; --k) topic += static_cast<char>((i * 2654435761u >> (8 * k)) & 0xff);
    flood += frame(topic);
  }
  for (const int port : {s.ports.nodes.master_state, s.ports.nodes.master_telemetry}) {
    Raw raw(port);
    ASSERT_TRUE(raw.handshake3("SUB"));
    (void)raw.send(flood);
    EXPECT_TRUE(raw.closed_within(3s)) << "200 000 subscriptions were taken on " << port;
  }
  // Spread out: 20 a millisecond for 1 s (what the conflated state publisher takes one by one).
  {
    Raw raw(s.ports.nodes.master_state);
    ASSERT_TRUE(raw.handshake3("SUB"));
    bool open = true;
    for (std::size_t at = 0; open && at + 140 <= flood.size() && at < 20'000 * 7; at += 140) {
      open = raw.send(flood.substr(at, 140));
      std::this_thread::sleep_for(1ms);
    }
    EXPECT_FALSE(open && !raw.closed_within(2s)) << "a subscription stream was never cut";
  }
  expect_all_alive_and_engaged("subscription floods");
  std::optional<v1::LinkStats> link;
  EXPECT_TRUE(s.mt.wait_for([&](const v1::Telemetry& t) {
    link = t.link();
    return link->connections_cut_over_budget() >= link_before.connections_cut_over_budget() + 3;
  })) << "subscribers cut: "
      << (link ? link->connections_cut_over_budget() : 0) -
             link_before.connections_cut_over_budget();
  // The memory the floods took is given back (the cut connections' tries, malloc_trim).
  long rss_after = 0;
  (void)eventually(
      [&] {
        rss_after = status_kb(s.master.pid(), "VmRSS");
        return rss_after - rss_before < 16 * 1024;
      },
      3s);
  std::cout << "master VmRSS " << rss_before << " kB before, " << rss_after
            << " kB after the floods; VmLck " << status_kb(s.master.pid(), "VmLck")
            << " kB; subscribers cut "
            << (link ? link->connections_cut_over_budget() -
                           link_before.connections_cut_over_budget()
                     : 0)
            << "\n";
  // Measured: 0.5-9 MB here (what was queued before the cut, as far as malloc_trim can give it
  // back); before: 160 MB and both nodes safe.
  // ASan's allocator keeps freed memory in quarantine and ignores malloc_trim: the bound is the
  // normal build's (the sanitizer build still checks every node ENGAGED on every cycle).
  if (!kAddressSanitizer) {
    EXPECT_LT(rss_after - rss_before, 16 * 1024) << "kB";
  }
}

// A flood of messages that fills a connection's queue to the socket (its input stopped), then
// a TCP reset: the libzmq 4.3.4 path that marks the connection _io_error without closing it,
// after which a heartbeat timer asserted (stream_engine_base.cpp:331, exit 134; measured on the
// master's telemetry endpoint before). Every endpoint, twice.
TEST_F(HostileWire, AFloodThenAResetOnEveryEndpointAbortsNothing) {
  Bytes subscriptions;
  Bytes requests;
  // Enough to fill a queue of libzmq's default high-water mark (1000) several times over.
  for (std::uint32_t i = 0; i < 3'000; ++i) {
    Bytes topic("\x01", 1);
    for (int k = 3; k >= 0; --k) topic += static_cast<char>((i >> (8 * k)) & 0xff);
    subscriptions += frame(topic);
  }
  for (int i = 0; i < 1'500; ++i) requests += frame("", kMore) + frame("\x08\x08");
  for (int round = 0; round < 2; ++round) {
    for (const Endpoint& e : endpoints()) {
      SCOPED_TRACE(e.name);
      const bool server = e.kind == "command" || e.kind == "request";
      Raw raw(e.port);
      ASSERT_TRUE(raw.handshake3(server ? "REQ" : "SUB"));
      // The flood, then a PING: answered when the stopped input is decoded after the reset.
      (void)raw.send_some((server ? requests : subscriptions) + command("PING", Bytes(2, '\0')));
      std::this_thread::sleep_for(20ms);
      raw.reset();
    }
    // Past a heartbeat interval (100 ms): the timer that asserted has fired by now.
    std::this_thread::sleep_for(150ms);
  }
  expect_all_alive_and_engaged("floods then resets");
}

// Greetings of every ZMTP version done wrong, truncated, oversized and zero-length frames,
// unknown mechanisms and commands, a CURVE handshake of garbage, ZMTP 3.1 SUBSCRIBE/CANCEL
// and PING commands, on every endpoint.
TEST_F(HostileWire, BadGreetingsAndFramesOnEveryEndpointLeaveEveryProcessServing) {
  attack_twice_if_the_link_timed_out("bad greetings and frames", [this] { bad_greetings(); });
}

void HostileWire::bad_greetings() {
  for (const Endpoint& e : endpoints()) {
    SCOPED_TRACE(e.name);
    const std::string type = e.kind == "command" || e.kind == "request" ? "REQ" : "SUB";
    const std::vector<Bytes> before_handshake = {
        "GET / HTTP/1.1\r\nHost: x\r\n\r\n",
        Bytes("\xff\x00\x00", 3),                 // truncated signature
        greeting3().substr(0, 11),                // truncated greeting
        greeting3("FOO"),                         // unknown mechanism
        greeting3("CURVE") + Bytes(300, '\x5a'),  // CURVE, garbage HELLO
        greeting3("PLAIN") + command("HELLO", Bytes(4, '\xff')),
        greeting3() + frame("not a command"),               // a message before READY
        greeting3() + command("READY", Bytes(40, '\xff')),  // READY, garbage properties
        greeting3() + long_header(1ull << 62, kCommand),    // an endless command
        Bytes("\x01\x00", 2) + Bytes("\xff\xff\xff\xff\xff\xff\xff\xff\xff\x00", 10),
        Bytes("\x00\x00\x00\x00", 4),    // ZMTP/1.0 zero-length frames
        greeting2('\x0b') + frame("x"),  // ZMTP/2.0, no such socket type
        greeting2(type == "REQ" ? '\x03' : '\x02') + long_header(1ull << 40),
    };
    mark(e.name + ", before the handshake");
    for (const Bytes& b : before_handshake) {
      Raw raw(e.port);
      ASSERT_TRUE(raw.connected());
      (void)raw.send(b);
      (void)raw.closed_within(30ms);
    }
    const std::vector<Bytes> after_handshake = {
        Bytes(200, '\0'),                                        // 100 zero-length frames
        frame("", kMore) + frame("") + frame("", kMore),         // empty parts, truncated
        long_header(10'000'000) + Bytes(100'000, 'x'),           // oversized, cut short
        frame(Bytes(70'000, 'y')),                               // over every limit
        long_header(1ull << 63),                                 // a size no one can have
        command("SUBSCRIBE", "abc") + command("CANCEL", "abc"),  // ZMTP 3.1
        command("PING", Bytes("\x00\x01", 2) + Bytes(16, 'c')) +
            command("PING", Bytes("\xff\xff", 2) + Bytes(200, 'c')),
        command("NO-SUCH-COMMAND", "x") + command("ERROR", "\x03why"),
        frame("\x08\x08", 0x80),  // reserved flag bits set
    };
    mark(e.name + ", after the handshake");
    for (const Bytes& b : after_handshake) {
      Raw raw(e.port);
      ASSERT_TRUE(raw.handshake3(type)) << "no handshake";
      (void)raw.send(b);
      (void)raw.closed_within(30ms);
    }
  }
}

// Connections that never finish their handshake, 50 held open on every endpoint at once, and
// a client that sends 2000 requests without reading a reply (its replies pile up against the
// socket's high-water mark): every endpoint goes on serving others.
TEST_F(HostileWire, ConnectionFloodsAndClientsThatNeverReadLeaveEveryEndpointServing) {
  System& s = *sys_;
  std::vector<Raw> held;
  for (const Endpoint& e : endpoints()) {
    for (int i = 0; i < 50; ++i) {
      held.emplace_back(e.port);
      ASSERT_TRUE(held.back().connected()) << e.name << " " << i;
      if (i % 2 == 0) (void)held.back().send(greeting3().substr(0, 20));
    }
  }
  std::vector<Raw> greedy;
  for (const int port :
       {s.ports.nodes.master_command, s.ports.nodes.slave_command, s.ports.request}) {
    greedy.emplace_back(port);
    ASSERT_TRUE(greedy.back().handshake3("REQ"));
    Bytes many;
    v1::NodeCommand status;
    status.set_kind(v1::NodeCommand::STATUS);
    for (int i = 0; i < 2000; ++i) many += frame("", kMore) + frame(status.SerializeAsString());
    (void)greedy.back().send(many);
  }
  expect_all_alive_and_engaged("held and greedy connections");
  held.clear();
  greedy.clear();
  expect_all_alive_and_engaged("after the connections closed");
}

// The replay's control endpoint (a REP, like the nodes') and its publishers: a 2-part request,
// the same in raw ZMTP/1.0, an empty request, verbs without their argument ("seek ": its
// first character was read from an empty string), oversized requests and subscriptions. Before:
// the 2-part request ended the replay. Now: each answered or dropped, the replay goes on
// answering and stops when asked, exit 0.
TEST(HostileWireReplay, ControlAnswersMultipartEmptyAndOddRequestsAndStopsWhenAsked) {
  const TempDir dir;
  const std::string file = (dir.path() / "s.mcap").string();
  const std::string scene =
      std::string(TELEOP_SOURCE_DIR) + "/examples/scenes/paddles_master_fixture.textproto";
  const std::string teleopctl = bin("TELEOP_TELEOPCTL_BIN", TELEOPCTL_PATH);
  const std::string simulate =
      teleopctl + " simulate " + scene + " --duration 1 --out " + file + " > /dev/null 2>&1";
  ASSERT_EQ(std::system(simulate.c_str()), 0);
  const int control = free_port();
  const int telemetry = free_port();
  Process replay(teleopctl,
                 {"replay", file, "--speed", "1", "--paused", "--hold", "--control", tcp(control),
                  "--master-telemetry", tcp(telemetry), "--slave-telemetry", tcp(free_port()),
                  "--report", tcp(free_port())},
                 dir.path() / "replay.log");
  zmq::context_t ctx(1);
  auto ask = [&](const std::vector<std::string>& parts) -> std::optional<std::string> {
    zmq::socket_t req(ctx, zmq::socket_type::req);
    req.set(zmq::sockopt::linger, 0);
    req.set(zmq::sockopt::rcvtimeo, 3000);
    req.connect(tcp(control));
    for (std::size_t i = 0; i < parts.size(); ++i) {
      req.send(zmq::buffer(parts[i]),
               i + 1 < parts.size() ? zmq::send_flags::sndmore : zmq::send_flags::none);
    }
    zmq::message_t reply;
    if (!req.recv(reply)) return std::nullopt;
    return reply.to_string();
  };
  ASSERT_TRUE(eventually([&] { return ask({"status"}).has_value(); }, 10s)) << replay.log();
  const std::optional<std::string> two = ask({"status", "status"});
  ASSERT_TRUE(two.has_value()) << replay.log();
  EXPECT_EQ(two->rfind("error: malformed request: 2 parts", 0), 0u) << *two;
  for (const std::string& odd : {std::string(), std::string("seek "), std::string("speed "),
                                 std::string("seek"), std::string(300, '\xff')}) {
    const std::optional<std::string> r = ask({odd});
    ASSERT_TRUE(r.has_value()) << "no reply to '" << odd << "'\n" << replay.log();
    EXPECT_EQ(r->rfind("error:", 0), 0u) << *r;
  }
  {
    Raw raw(control);
    ASSERT_TRUE(raw.send(Bytes("\x01\x00", 2) + frame1("", true) + frame1("a", true) +
                         frame1("b", true) + frame1("c", false)));
    (void)raw.closed_within(100ms);
  }
  {
    Raw raw(control);
    ASSERT_TRUE(raw.handshake3("REQ"));
    (void)raw.send(frame("", kMore) + frame(Bytes(70'000, 'x')));
    EXPECT_TRUE(raw.closed_within(2s)) << "a 70 kB request was taken";
  }
  {
    Raw raw(telemetry);
    ASSERT_TRUE(raw.handshake3("SUB"));
    (void)raw.send(frame("\x01" + Bytes(1'000'000, 'x')));
    EXPECT_TRUE(raw.closed_within(2s)) << "a 1 MB subscription was taken";
  }
  EXPECT_FALSE(replay.exited().has_value()) << replay.log();
  const std::optional<std::string> status = ask({"status"});
  ASSERT_TRUE(status.has_value()) << replay.log();
  EXPECT_EQ(status->rfind("paused", 0), 0u) << *status;
  const std::optional<std::string> stop = ask({"stop"});
  ASSERT_TRUE(stop.has_value());
  EXPECT_EQ(replay.wait(), 0) << replay.log();
}

}  // namespace
}  // namespace teleop::test
