// Counts what happens to a node's ZeroMQ connections (issue 7 "from the network ... all are
// counted"): connections accepted on its bound endpoints, connections that closed (a peer
// gone, or a frame over the socket's size limit, which libzmq drops with the connection before
// allocating it) and handshakes that failed (a client with an unlisted CURVE key, a peer that
// does not speak ZMTP). libzmq's socket monitor reports each event on an inproc pair; one
// thread of its own (never the real-time loop) reads them. Counters are atomics read by the
// telemetry thread.
#pragma once

#include <sys/socket.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <map>
#include <string>
#include <thread>
#include <vector>
#include <zmq.hpp>

namespace teleop::transport {

struct ConnectionCounts {
  std::uint64_t accepted{0};           // TCP connections a bound socket took
  std::uint64_t closed{0};             // connections that went away after their handshake
  std::uint64_t handshakes_failed{0};  // ZMTP or CURVE handshakes that failed (any reason)
  std::uint64_t auth_failed{0};        // of those: refused by authentication (ZAP)
  std::uint64_t cut_over_budget{0};    // connections cut for sending more than their budget
};

// How much a connection accepted by a bound socket may send: `burst` bytes plus
// `bytes_per_s` for every second it has been open (TCP payload as the kernel counts it,
// TCP_INFO tcpi_bytes_received). A connection over its budget is cut (shutdown(2) on its
// descriptor, which libzmq sees as the peer closing, and drops the connection and everything
// it holds for it). Zero burst: no budget.
//
// Why (issue 14 finding 5): a publisher keeps every distinct subscription a subscriber sends
// (a trie node per byte) until that subscriber disconnects, and no libzmq option bounds their
// number (ZMQ_XPUB_MANUAL keeps them too, in xpub.cpp's _manual_subscriptions); a subscriber
// of ours sends one subscription and its heartbeats, a few hundred bytes a second at most.
struct InboundBudget {
  std::uint64_t burst_bytes{0};
  std::uint64_t bytes_per_s{0};
};

// The budget of a publisher's subscriber: the handshake (CURVE: ~600 B), a few subscriptions
// and ZMTP heartbeats both ways every 100 ms (CURVE: ~45 B each, ~900 B/s), with 2x margin
// and more.
inline constexpr InboundBudget kSubscriberBudget{16 * 1024, 2 * 1024};
// The budget of a command client (a request is < 1 KiB; a console asks a few times a second,
// the CLI connects anew for each command): 256 KiB plus 64 KiB/s.
inline constexpr InboundBudget kCommandClientBudget{256 * 1024, 64 * 1024};

class SocketMonitor {
 public:
  // Monitors every socket given (kept by the caller; they must outlive stop()). The inproc
  // names are made unique per monitor from `tag`.
  // `budgets`, when given, has one entry per socket (see InboundBudget).
  SocketMonitor(zmq::context_t& ctx, const std::vector<zmq::socket_t*>& sockets,
                const std::string& tag, std::vector<InboundBudget> budgets = {});
  ~SocketMonitor();
  SocketMonitor(const SocketMonitor&) = delete;
  SocketMonitor& operator=(const SocketMonitor&) = delete;

  // Joins the thread and detaches the monitors; idempotent. Call before closing the sockets.
  void stop();
  [[nodiscard]] ConnectionCounts counts() const;

  // A connection a budgeted socket accepted, as the kernel names it (checked again before it
  // is cut: a descriptor libzmq has closed meanwhile may already be another connection's).
  struct Tracked {
    std::chrono::steady_clock::time_point since{};
    sockaddr_storage local{};
    sockaddr_storage peer{};
    std::uint64_t received{0};
  };

 private:
  void run();
  void check_budgets(std::vector<std::map<int, Tracked>>& tracked, bool& trim);

  std::vector<zmq::socket_t*> sockets_;
  std::vector<InboundBudget> budgets_;
  std::vector<zmq::socket_t> pairs_;
  std::atomic<bool> running_{true};
  std::array<std::atomic<std::uint64_t>, 5> counts_{};
  std::chrono::steady_clock::time_point trim_until_{};
  std::chrono::steady_clock::time_point next_trim_{};
  std::thread thread_;
};

}  // namespace teleop::transport
