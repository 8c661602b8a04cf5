// A Foxglove WebSocket protocol server (subprotocol `foxglove.websocket.v1`, the public spec of
// github.com/foxglove/ws-protocol docs/spec.md): server info, channels advertised with their
// schemas, subscribe and unsubscribe, binary message data. Written for `teleopctl bridge`
// (docs/foxglove.md); it knows no teleop message type, only topics, schemas and bytes.
//
// The server runs on a thread of its own (websocketpp over standalone asio); publish() may be
// called from any thread, never blocks on a client and never throws. Nothing a client sends
// ends the process: a malformed frame closes that connection (websocketpp), a malformed or
// unsupported JSON request gets a `status` reply with level 2 (error) naming what was wrong,
// a client too slow to take its messages loses messages (counted), not memory.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>

namespace teleop::bridge {

inline constexpr std::string_view kSubprotocol = "foxglove.websocket.v1";

// One channel: a topic and how its messages are encoded (for protobuf: `schema_name` the
// message's full name, `schema_data` a serialized FileDescriptorSet, sent base64-encoded).
struct ChannelSpec {
  std::string topic{};
  std::string schema_name{};
  std::string schema_data{};
  std::string encoding{"protobuf"};
  std::string schema_encoding{"protobuf"};
  // The newest message is kept and sent to each new subscriber at once (for channels that
  // change rarely, such as the stability report).
  bool latched{false};
};

struct ServerOptions {
  std::string address{"127.0.0.1"};  // an IP address; loopback unless the caller decides
  std::uint16_t port{8765};          // 0: any free port (port() says which)
  std::string name{"teleop"};        // serverInfo.name
  std::map<std::string, std::string> metadata{};    // serverInfo.metadata
  std::size_t max_clients{16};                      // further connections are refused
  std::size_t max_request_bytes{64 * 1024};         // a larger client message closes it (1009)
  std::size_t max_buffered_bytes{8 * 1024 * 1024};  // per client; beyond it messages drop
  // Told each connection, subscription, unsubscription and disconnection as one line
  // ("127.0.0.1:41234 subscribed to /slave/cycle"), on the server's thread; must not throw.
  std::function<void(const std::string&)> on_event{};
};

struct ServerStats {
  std::uint64_t connections{0};       // accepted since start
  std::uint64_t clients{0};           // connected now
  std::uint64_t messages_sent{0};     // message data frames handed to clients
  std::uint64_t messages_dropped{0};  // not sent: the client's buffer was full
  std::uint64_t bad_requests{0};      // client messages answered with an error status
  std::uint64_t refused{0};           // handshakes refused (subprotocol, client limit)
};

class FoxgloveServer {
 public:
  // Listens on options.address:port and starts serving; throws std::runtime_error naming the
  // address and port when it cannot (in use, not an address of this host).
  explicit FoxgloveServer(ServerOptions options);
  ~FoxgloveServer();
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  // Adds a channel (advertised to connected clients at once, to later ones on connection) and
  // returns its id. Thread-safe.
  std::uint32_t add_channel(ChannelSpec spec);

  // Sends `payload` on `channel` to every client subscribed to it, with `receive_time_ns`
  // (ns since the Unix epoch) as the message's timestamp. Thread-safe; never blocks or throws.
  void publish(std::uint32_t channel, std::uint64_t receive_time_ns,
               std::string_view payload) noexcept;

  // Whether any client is subscribed to `channel` now (lets a caller skip encoding).
  [[nodiscard]] bool has_subscribers(std::uint32_t channel) const noexcept;

  [[nodiscard]] std::uint16_t port() const noexcept;
  [[nodiscard]] ServerStats stats() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// RFC 4648 base64 with padding (the Advertise message's `schema`).
[[nodiscard]] std::string base64_encode(std::string_view bytes);

// A Message Data frame: opcode 0x01, subscription id (uint32 LE), receive timestamp (uint64 LE),
// the payload.
[[nodiscard]] std::string message_data_frame(std::uint32_t subscription_id,
                                             std::uint64_t receive_time_ns,
                                             std::string_view payload);

}  // namespace teleop::bridge
