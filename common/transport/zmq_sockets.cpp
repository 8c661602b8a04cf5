#include "common/transport/zmq_sockets.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <limits>
#include <stdexcept>

namespace teleop::transport {

namespace {

// A bound socket's inbound queue (ZMQ_RCVHWM) is unlimited: in libzmq 4.3.4 a connection
// whose queue is full stops reading; if the peer then resets it, the connection is marked
// _io_error but not closed, and when the queue drains the rest of its input is decoded: a
// PING there is answered through out_event(), which asserts !_io_error
// (src/stream_engine_base.cpp:331) and aborts the process (measured: a subscription flood to a
// node's telemetry endpoint, then a reset: exit 134). A queue that is never full never stops
// reading. What a peer may send is bounded instead by the frame limit and by its connection's
// budget (socket_monitor.hpp), and the socket's thread drains it.
constexpr int kNoInboundHwm = 0;

// ZMTP heartbeats go on the connecting side only: in libzmq 4.3.4 (and its master as of this
// writing) a connection whose input is stopped (its queue to the socket full) and that then errors
// (a peer's RST: EPOLLERR) is marked _io_error without being closed, and the next heartbeat timer
// calls out_event(), which asserts !_io_error (src/stream_engine_base.cpp:331) and aborts the
// process. A peer could do that to any bound socket with heartbeats (measured: a subscription flood
// to a node's telemetry endpoint, then RST: exit 134; issue 14). A bound socket sends no
// heartbeats; its clients' heartbeats are still answered (and see kNoInboundHwm for the other path
// to that assertion).

int to_option_ms(std::chrono::milliseconds d) {
  return static_cast<int>(
      std::min<std::chrono::milliseconds::rep>(d.count(), std::numeric_limits<int>::max()));
}

void set_common(zmq::socket_t& socket) { socket.set(zmq::sockopt::linger, 0); }

// Connecting sockets only (see above: on a bound socket a peer could abort the process).
void set_heartbeats(zmq::socket_t& socket) {
  socket.set(zmq::sockopt::heartbeat_ivl, to_option_ms(kHeartbeatInterval));
  socket.set(zmq::sockopt::heartbeat_timeout, to_option_ms(kHeartbeatTimeout));
}

void set_reconnect(zmq::socket_t& socket) {
  socket.set(zmq::sockopt::reconnect_ivl, to_option_ms(kReconnectInterval));
  socket.set(zmq::sockopt::reconnect_ivl_max, to_option_ms(kReconnectIntervalMax));
}

}  // namespace

BindError::BindError(int err, std::string_view endpoint)
    : zmq::error_t(err),
      endpoint_(endpoint),
      message_(fmt::format("cannot bind {}: {}", endpoint, zmq_strerror(err))) {}

void bind_or_throw(zmq::socket_t& socket, std::string_view endpoint) {
  try {
    socket.bind(std::string(endpoint));
  } catch (const zmq::error_t& e) {
    throw BindError(e.num(), endpoint);
  }
}

namespace {

// Every socket of the link is made alike around its own `options`: the common settings first,
// then (connecting sockets) heartbeats and reconnection, then the options, the security, and
// the bind or the connect last.
template <typename Options>
zmq::socket_t bound_socket(zmq::context_t& ctx, zmq::socket_type type, std::string_view endpoint,
                           const LinkSecurity& security, IoLane lane, const Options& options) {
  zmq::socket_t socket(ctx, type);
  set_common(socket);
  socket.set(zmq::sockopt::affinity, static_cast<std::uint64_t>(lane));
  options(socket);
  (void)apply_link_security(ctx, socket, endpoint, LinkRole::kServer, security);
  bind_or_throw(socket, endpoint);
  return socket;
}

template <typename Options>
zmq::socket_t connected_socket(zmq::context_t& ctx, zmq::socket_type type,
                               std::string_view endpoint, const LinkSecurity& security, IoLane lane,
                               const Options& options) {
  zmq::socket_t socket(ctx, type);
  set_common(socket);
  socket.set(zmq::sockopt::affinity, static_cast<std::uint64_t>(lane));
  set_heartbeats(socket);
  set_reconnect(socket);
  options(socket);
  (void)apply_link_security(ctx, socket, endpoint, LinkRole::kClient, security);
  socket.connect(std::string(endpoint));
  return socket;
}

// A publisher (PUB) around its own `options`: its only inbound traffic (handshakes and
// subscriptions) capped at kMaxPublisherInboundBytes, and a full subscriber's queue drops for
// that subscriber rather than blocking the sender (ZMQ_XPUB_NODROP off).
template <typename Options>
zmq::socket_t publisher_socket(zmq::context_t& ctx, std::string_view endpoint,
                               const LinkSecurity& security, IoLane lane, const Options& options) {
  return bound_socket(ctx, zmq::socket_type::pub, endpoint, security, lane,
                      [&options](zmq::socket_t& socket) {
                        socket.set(zmq::sockopt::maxmsgsize, kMaxPublisherInboundBytes);
                        options(socket);
                        socket.set(zmq::sockopt::xpub_nodrop, false);
                      });
}

}  // namespace

zmq::socket_t make_state_publisher(zmq::context_t& ctx, std::string_view endpoint,
                                   const LinkSecurity& security, IoLane lane) {
  return publisher_socket(ctx, endpoint, security, lane, [](zmq::socket_t& socket) {
    socket.set(zmq::sockopt::conflate, true);
    // No SNDHWM: a conflated pipe has one slot and ignores it (and a small HWM without
    // conflation would drop the newest; see the header).
  });
}

zmq::socket_t make_telemetry_publisher(zmq::context_t& ctx, std::string_view endpoint,
                                       const LinkSecurity& security, IoLane lane) {
  return publisher_socket(ctx, endpoint, security, lane, [](zmq::socket_t& socket) {
    // No inbound limit: see kNoInboundHwm (the budget bounds what a subscriber may send).
    socket.set(zmq::sockopt::rcvhwm, kNoInboundHwm);
    socket.set(zmq::sockopt::sndhwm, 1000);
  });
}

zmq::socket_t make_state_subscriber(zmq::context_t& ctx, std::string_view endpoint,
                                    const LinkSecurity& security, IoLane lane) {
  return connected_socket(ctx, zmq::socket_type::sub, endpoint, security, lane,
                          [](zmq::socket_t& socket) {
                            // Not ZMQ_CONFLATE (see the header: libzmq 4.3.4 strands and leaks
                            // with it on a SUB).
                            socket.set(zmq::sockopt::rcvhwm, kStateReceiveHwm);
                            socket.set(zmq::sockopt::maxmsgsize, kMaxInboundMessageBytes);
                            socket.set(zmq::sockopt::subscribe, "");
                          });
}

zmq::socket_t make_command_server(zmq::context_t& ctx, std::string_view endpoint,
                                  const LinkSecurity& security, IoLane lane) {
  return bound_socket(ctx, zmq::socket_type::rep, endpoint, security, lane,
                      [](zmq::socket_t& socket) {
                        socket.set(zmq::sockopt::maxmsgsize, kMaxInboundMessageBytes);
                        socket.set(zmq::sockopt::rcvhwm, kNoInboundHwm);
                      });
}

zmq::socket_t make_command_client(zmq::context_t& ctx, std::string_view endpoint,
                                  const LinkSecurity& security, std::chrono::milliseconds timeout) {
  // Zero or negative would mean "never wait" or "wait forever" to ZeroMQ; neither is a
  // command timeout.
  if (timeout <= std::chrono::milliseconds::zero()) {
    throw std::invalid_argument(
        fmt::format("{}: command timeout must be positive, got {} ms", endpoint, timeout.count()));
  }
  return connected_socket(ctx, zmq::socket_type::req, endpoint, security, IoLane::kAny,
                          [timeout](zmq::socket_t& socket) {
                            socket.set(zmq::sockopt::req_relaxed, true);
                            socket.set(zmq::sockopt::req_correlate, true);
                            socket.set(zmq::sockopt::sndtimeo, to_option_ms(timeout));
                            socket.set(zmq::sockopt::rcvtimeo, to_option_ms(timeout));
                          });
}

std::string bound_endpoint(const zmq::socket_t& socket) {
  return socket.get(zmq::sockopt::last_endpoint);
}

std::optional<std::string> recv_latest(zmq::socket_t& socket, std::chrono::milliseconds timeout) {
  zmq::pollitem_t item{socket.handle(), 0, ZMQ_POLLIN, 0};
  try {
    if (zmq::poll(&item, 1, timeout) == 0) return std::nullopt;
  } catch (const zmq::error_t& e) {
    if (e.num() == EINTR) return std::nullopt;
    throw;
  }
  std::optional<std::string> latest;
  zmq::message_t message;
  while (true) {
    zmq::recv_result_t got;
    try {
      got = socket.recv(message, zmq::recv_flags::dontwait);
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) break;
      throw;
    }
    if (!got) break;
    latest = message.to_string();
    // Discard the rest of a multipart message (not expected on this link).
    while (message.more()) {
      if (!socket.recv(message, zmq::recv_flags::dontwait)) break;
    }
  }
  return latest;
}

Received receive_whole(zmq::socket_t& socket, zmq::message_t& first) noexcept {
  Received out;
  try {
    if (!socket.recv(first, zmq::recv_flags::dontwait)) return out;
    out.parts = 1;
    zmq::message_t rest;
    // The rest of a message is there already (ZeroMQ delivers whole messages only).
    bool more = first.more();
    while (more) {
      if (!socket.recv(rest, zmq::recv_flags::dontwait)) break;
      ++out.parts;
      more = rest.more();
    }
  } catch (const zmq::error_t& e) {
    out.error = e.what();
    if (e.num() == EFSM) {
      // A REP still owing a reply: an empty one puts it back to receiving.
      try {
        (void)socket.send(zmq::const_buffer(), zmq::send_flags::dontwait);
      } catch (const zmq::error_t&) {
      }
    }
  }
  return out;
}

bool send_noexcept(zmq::socket_t& socket, std::string_view bytes, zmq::send_flags flags,
                   std::string* error) noexcept {
  try {
    if (socket.send(zmq::buffer(bytes.data(), bytes.size()), flags)) return true;
    if (error != nullptr) *error = "queue full";
  } catch (const zmq::error_t& e) {
    if (error != nullptr) *error = e.what();
  }
  return false;
}

bool wait_readable(zmq::socket_t& socket, std::chrono::milliseconds timeout) noexcept {
  zmq::pollitem_t item{socket.handle(), 0, ZMQ_POLLIN, 0};
  try {
    return zmq::poll(&item, 1, timeout) > 0 && (item.revents & ZMQ_POLLIN) != 0;
  } catch (const zmq::error_t&) {
    return false;
  }
}

std::optional<std::string> request_reply(zmq::socket_t& client, std::string_view request) {
  if (!client.send(zmq::buffer(request), zmq::send_flags::none)) return std::nullopt;
  zmq::message_t reply;
  if (!client.recv(reply, zmq::recv_flags::none)) return std::nullopt;
  std::string text = reply.to_string();
  while (reply.more()) {
    if (!client.recv(reply, zmq::recv_flags::none)) break;
  }
  return text;
}

}  // namespace teleop::transport
