// The project's ZAP handler (ZeroMQ RFC 27): decides which CURVE clients a server socket
// accepts. CURVE alone only proves that a client knows the server's public key, which is not
// a secret; the allowlist of client public keys is what keeps an unknown machine from
// commanding a robot. Every refusal is counted and logged with the key and the peer address
// so an operator can tell a misconfigured peer from an intruder.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "common/transport/zmq_fwd.hpp"

namespace teleop::transport {

struct ZapRefusal {
  std::string client_key_z85{};  // empty when the mechanism was not CURVE
  std::string peer_address{};    // IP address as libzmq reports it
  std::string domain_label{};    // what the socket serves, e.g. its endpoint
  std::string reason{};
};

// Serves ZAP requests for one zmq::context_t on a thread of its own.
//
// Lifetime: construct it after the context and before the server sockets, so it is destroyed
// after them: libzmq consults a handler only while one is bound to inproc://zeromq.zap.01,
// and with none it accepts every CURVE client key. apply_link_security() therefore refuses to
// set up a CURVE server on a context no ZapHandler serves.
class ZapHandler {
 public:
  // Binds inproc://zeromq.zap.01 on `ctx` (throws std::runtime_error if another handler
  // already serves it) and starts the thread. Requests that arrive before the thread runs
  // wait in the socket, so the handler is in force when the constructor returns.
  explicit ZapHandler(zmq::context_t& ctx);
  ~ZapHandler();
  ZapHandler(const ZapHandler&) = delete;
  ZapHandler& operator=(const ZapHandler&) = delete;
  ZapHandler(ZapHandler&&) = delete;
  ZapHandler& operator=(ZapHandler&&) = delete;

  // Registers the allowed client keys (Z85) of one server socket and returns the ZAP domain
  // to set on it. Requests with an unregistered domain are refused: fail closed. Throws
  // std::invalid_argument for a malformed key. Thread-safe.
  [[nodiscard]] std::string add_domain(const std::string& label,
                                       const std::vector<std::string>& allowed_client_keys);

  // Counters and recent refusals (the last kRecentRefusals), readable from any thread.
  [[nodiscard]] std::uint64_t accepted_count() const noexcept { return accepted_.load(); }
  [[nodiscard]] std::uint64_t refused_count() const noexcept { return refused_.load(); }
  [[nodiscard]] std::vector<ZapRefusal> recent_refusals() const;
  static constexpr std::size_t kRecentRefusals = 32;

  // The handler serving `ctx`, or nullptr.
  [[nodiscard]] static ZapHandler* serving(zmq::context_t& ctx);

 private:
  struct Domain {
    std::string label{};
    std::unordered_set<std::string> allowed_keys{};  // 32-byte binary keys: one spelling each
  };

  void run() noexcept;
  void serve_one();
  void refuse(ZapRefusal refusal);

  void* context_handle_{nullptr};
  std::unique_ptr<zmq::socket_t> zap_socket_;
  std::unique_ptr<zmq::socket_t> control_send_;  // the destructor's stop signal
  std::unique_ptr<zmq::socket_t> control_recv_;
  std::atomic<std::uint64_t> accepted_{0};
  std::atomic<std::uint64_t> refused_{0};
  mutable std::mutex mutex_;  // guards domains_, next_domain_, refusals_
  std::unordered_map<std::string, Domain> domains_;
  std::uint64_t next_domain_{0};
  std::vector<ZapRefusal> refusals_;
  std::thread thread_;
};

}  // namespace teleop::transport
