// The node link's sockets, configured once here so every process gets the same behaviour. Used on
// the link thread only: ZeroMQ allocates for messages over 33 bytes, so none of this runs on the RT
// thread (docs/architecture.md §4.2).
//
// Why the options differ from ZeroMQ's defaults:
//  - State (PUB/SUB) is a latest-value stream: a control law wants the newest peer state,
//    and every queued older one is pure delay. The publisher sets ZMQ_CONFLATE (one slot per
//    subscriber, the newest replaces the older), so a slow or stalled link never builds a
//    backlog of stale states at the sender (the default SNDHWM of 1000 would be a second of
//    them at 1 kHz). A small SNDHWM is not a substitute: a full PUB queue drops the *newest*
//    messages (measured: a burst of 1000 with SNDHWM 2 delivers message 0 and nothing after).
//    CONFLATE supports single-part messages only, which is what NodeState is, and it also
//    conflates the PUB's inbound subscriptions: fine, our subscribers subscribe once.
//    ZMQ_XPUB_NODROP stays off so a slow subscriber can never block the sender.
//  - The subscriber does NOT set ZMQ_CONFLATE, although that looks natural: in libzmq 4.3.4 a
//    conflated SUB strands the last message of a burst (its double buffer, src/dbuffer.hpp,
//    skips a write that meets the reader holding the lock, and the reader is then never
//    woken) and, under AddressSanitizer, leaks a pipe pair at close in a few percent of runs.
//    Instead its queue is sized for what can arrive between two drains (a TCP backlog after
//    a stall included; a full queue would drop the newest) and recv_latest() drains it,
//    returning the newest and discarding the rest.
//    Known limit of the publisher's conflated slot (same double buffer): the newest message
//    can be held back until the next send replaces it. A node publishes every period, which
//    bounds this to one period (visible as peer age); a stream that stops cannot count on
//    its last message arriving.
//  - ZMQ_LINGER 0 everywhere: the default (infinite) makes closing the context wait for
//    unsent messages to a peer that may never come back, hanging process exit; a stale state
//    or command is worthless after exit anyway.
//  - Subscribers and clients reconnect after 10 ms, backing off to 100 ms (default: every 100 ms,
//    no back-off), so a restarted peer is picked up within a few control periods.
//  - ZMTP heartbeats (100 ms interval, 300 ms timeout) detect a dead TCP peer (cable pulled,
//    machine powered off) that would otherwise look connected until the kernel gives up,
//    minutes later; the connecting side then reconnects.
//  - We never use PAIR: it neither reconnects reliably nor tolerates a second peer.
//  - The command client is REQ with ZMQ_REQ_RELAXED and ZMQ_REQ_CORRELATE: a plain REQ whose
//    reply never arrives refuses to send again (EFSM) forever; relaxed lets it send the next
//    request, correlate discards the late reply to the abandoned one.
#pragma once

#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <zmq.hpp>

#include "common/transport/zmq_security.hpp"

namespace teleop::transport {

// How long ZMTP heartbeats take to declare a silent peer dead.
inline constexpr std::chrono::milliseconds kHeartbeatInterval{100};
inline constexpr std::chrono::milliseconds kHeartbeatTimeout{300};
inline constexpr std::chrono::milliseconds kReconnectInterval{10};
inline constexpr std::chrono::milliseconds kReconnectIntervalMax{100};
// The subscriber's queue: far more than arrives between two drains of a link thread.
inline constexpr int kStateReceiveHwm = 1000;
// The largest message a node state subscriber or a command server accepts, bytes: every
// message of ours is far smaller (a NodeState ~100 B, a command or supervisor request < 1 KiB).
// libzmq drops the connection of a peer that sends a larger one before allocating it, so an
// oversized frame never costs the receiver its memory nor reaches a parser.
inline constexpr std::int64_t kMaxInboundMessageBytes = 64 * 1024;
// The largest frame a publisher (PUB, XPUB) accepts: a publisher's only inbound traffic is the
// handshake (a CURVE INITIATE with its metadata is ~300 B) and subscriptions (ours: one, empty).
// libzmq keeps every subscription in a trie, one node per byte, built on the thread that sends:
// without a limit one 1 MB subscription is a million allocations on the node's sender thread
// (measured: the link stalls past its peer timeout and both nodes go safe, issue 14 finding 5).
inline constexpr std::int64_t kMaxPublisherInboundBytes = 1024;

// A failed bind: the zmq::error_t (num() is the errno, EADDRINUSE for a port in use) whose
// what() names the endpoint, e.g. "cannot bind tcp://127.0.0.1:5562: Address already in use".
class BindError : public zmq::error_t {
 public:
  BindError(int err, std::string_view endpoint);
  [[nodiscard]] const char* what() const noexcept override { return message_.c_str(); }
  [[nodiscard]] const std::string& endpoint() const noexcept { return endpoint_; }

 private:
  std::string endpoint_;
  std::string message_;
};

// socket.bind(endpoint), a failure thrown as BindError.
void bind_or_throw(zmq::socket_t& socket, std::string_view endpoint);

// Which of a context's libzmq I/O threads serves a socket's connections (ZMQ_AFFINITY, a bit
// per I/O thread). A node's context has kNodeIoThreads: the peer link (state publisher and
// subscriber) on one, everything a console or a stranger can reach (commands, telemetry) on the
// other, so that whatever arrives on those endpoints -- a flood, a bad handshake, a greedy
// client -- is never worked through on the thread that carries the link's states (issue 14
// finding 5's sibling: the link shares nothing with the service endpoints but the process).
// kAny: libzmq's choice (a context with one I/O thread).
enum class IoLane : std::uint64_t { kAny = 0, kPeerLink = 1, kService = 2 };
inline constexpr int kNodeIoThreads = 2;

// A PUB bound to `endpoint` (server side of the security policy); "tcp://127.0.0.1:*" picks a
// free port, read back with bound_endpoint(). Throws std::invalid_argument when the policy
// forbids the setup, BindError (a zmq::error_t naming the endpoint) when binding fails.
[[nodiscard]] zmq::socket_t make_state_publisher(zmq::context_t& ctx, std::string_view endpoint,
                                                 const LinkSecurity& security,
                                                 IoLane lane = IoLane::kAny);

// A PUB for telemetry (server side): unlike the state link, every message counts (each
// carries a batch of cycles), so no conflation; SNDHWM 1000 (20 s at 50 Hz) absorbs a slow
// subscriber, past which ZeroMQ drops for that subscriber only and the node never blocks.
[[nodiscard]] zmq::socket_t make_telemetry_publisher(zmq::context_t& ctx, std::string_view endpoint,
                                                     const LinkSecurity& security,
                                                     IoLane lane = IoLane::kAny);

// A SUB connected to `endpoint` (client side), subscribed to everything; read it with
// recv_latest().
[[nodiscard]] zmq::socket_t make_state_subscriber(zmq::context_t& ctx, std::string_view endpoint,
                                                  const LinkSecurity& security,
                                                  IoLane lane = IoLane::kAny);

// A REP bound to `endpoint` (server side) for operator and supervisor commands: one reply per
// request, in order, which is all a command channel needs.
[[nodiscard]] zmq::socket_t make_command_server(zmq::context_t& ctx, std::string_view endpoint,
                                                const LinkSecurity& security,
                                                IoLane lane = IoLane::kAny);

// A REQ connected to `endpoint` (client side); a request waits at most `timeout` to be sent
// and as long again for its reply.
[[nodiscard]] zmq::socket_t make_command_client(zmq::context_t& ctx, std::string_view endpoint,
                                                const LinkSecurity& security,
                                                std::chrono::milliseconds timeout);

// The endpoint a socket actually bound (ZMQ_LAST_ENDPOINT), with the real port for a '*'.
[[nodiscard]] std::string bound_endpoint(const zmq::socket_t& socket);

// The newest message pending on `socket`, waiting up to `timeout` for the first; everything
// older that is already queued is drained and discarded. Empty when nothing arrived in time
// (or the wait was interrupted by a signal). Single-part messages: any further parts of a
// multipart message are discarded with it.
[[nodiscard]] std::optional<std::string> recv_latest(zmq::socket_t& socket,
                                                     std::chrono::milliseconds timeout);

// The outcome of receive_whole(): how many parts the message had (0: nothing was pending or
// libzmq refused; `error` then says why, empty when there was simply nothing).
struct Received {
  std::size_t parts{0};
  std::string error{};
};

// Takes one whole message from `socket` without waiting: its first part into `first`, every
// further part received and discarded, so that a server socket (REP) is always ready to
// reply and never left in the middle of a request. A multi-part request is the caller's to
// refuse (parts > 1): ZeroMQ delivers a message atomically, so the rest never has to be waited
// for. Never throws: a REP found in its reply state (a reply that could not go out) is put
// back to receiving with an empty reply, and the error reported.
[[nodiscard]] Received receive_whole(zmq::socket_t& socket, zmq::message_t& first) noexcept;

// Sends one single-part message without waiting and without throwing: false (the reason in
// `error` when given) when libzmq refused it or the queue was full.
bool send_noexcept(zmq::socket_t& socket, std::string_view bytes,
                   zmq::send_flags flags = zmq::send_flags::dontwait,
                   std::string* error = nullptr) noexcept;

// Waits up to `timeout` for `socket` to be readable; false on timeout, signal or error (never
// throws).
[[nodiscard]] bool wait_readable(zmq::socket_t& socket, std::chrono::milliseconds timeout) noexcept;

// Sends `request` on a command client and waits for the reply within the socket's timeouts;
// empty on timeout, after which the socket can send the next request at once.
[[nodiscard]] std::optional<std::string> request_reply(zmq::socket_t& client,
                                                       std::string_view request);

}  // namespace teleop::transport
