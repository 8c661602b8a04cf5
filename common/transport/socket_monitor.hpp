// Counts what happens to a node's ZeroMQ connections (issue 7 "from the network ... all are
// counted"): connections accepted on its bound endpoints, connections that closed (a peer
// gone, or a frame over the socket's size limit, which libzmq drops with the connection before
// allocating it) and handshakes that failed (a client with an unlisted CURVE key, a peer that
// does not speak ZMTP). libzmq's socket monitor reports each event on an inproc pair; one
// thread of its own (never the real-time loop) reads them. Counters are atomics read by the
// telemetry thread.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
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
};

class SocketMonitor {
 public:
  // Monitors every socket given (kept by the caller; they must outlive stop()). The inproc
  // names are made unique per monitor from `tag`.
  SocketMonitor(zmq::context_t& ctx, const std::vector<zmq::socket_t*>& sockets,
                const std::string& tag);
  ~SocketMonitor();
  SocketMonitor(const SocketMonitor&) = delete;
  SocketMonitor& operator=(const SocketMonitor&) = delete;

  // Joins the thread and detaches the monitors; idempotent. Call before closing the sockets.
  void stop();
  [[nodiscard]] ConnectionCounts counts() const;

 private:
  void run();

  std::vector<zmq::socket_t*> sockets_;
  std::vector<zmq::socket_t> pairs_;
  std::atomic<bool> running_{true};
  std::array<std::atomic<std::uint64_t>, 4> counts_{};
  std::thread thread_;
};

}  // namespace teleop::transport
