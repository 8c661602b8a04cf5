// The Foxglove WebSocket protocol server (common/bridge/foxglove_server.hpp) against a client
// written here from RFC 6455 and the foxglove.websocket.v1 spec (raw sockets, so the tests can
// also send what no proper client would): the handshake (RFC 6455 §1.3's accept key), server
// info and advertise, subscribe, message data frames byte by byte, unsubscribe, and hostile
// input — malformed JSON ops, malformed or oversized frames, garbage instead of a handshake —
// after which the server still serves a new client. Base64 against RFC 4648 §10.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <functional>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "common/bridge/foxglove_server.hpp"

namespace teleop::bridge {
namespace {

using namespace std::chrono_literals;
using Json = nlohmann::json;

// RFC 6455 §1.3: this key's accept value.
constexpr const char* kRfcKey = "dGhlIHNhbXBsZSBub25jZQ==";
constexpr const char* kRfcAccept = "s3pPLMBiTxaQ9kYGzzhZRbK+xOo=";

struct Frame {
  int opcode{-1};
  std::string payload{};
};

// A WebSocket client on a raw TCP socket.
class RawClient {
 public:
  explicit RawClient(std::uint16_t port) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0) {
      throw std::runtime_error("connect failed");
    }
  }
  ~RawClient() {
    if (fd_ >= 0) ::close(fd_);
  }
  RawClient(const RawClient&) = delete;
  RawClient& operator=(const RawClient&) = delete;

  void send_raw(const std::string& bytes) const {
    (void)::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL);
  }

  // The opening handshake; returns the server's response head (status line and headers).
  std::string handshake(const std::string& protocols = std::string(kSubprotocol)) {
    std::string req =
        "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
        "Connection: Upgrade\r\nSec-WebSocket-Key: " +
        std::string(kRfcKey) + "\r\nSec-WebSocket-Version: 13\r\n";
    if (!protocols.empty()) req += "Sec-WebSocket-Protocol: " + protocols + "\r\n";
    send_raw(req + "\r\n");
    std::string head;
    while (head.find("\r\n\r\n") == std::string::npos) {
      if (!fill(2s)) break;
      head += buffer_;
      buffer_.clear();
    }
    const auto end = head.find("\r\n\r\n");
    if (end != std::string::npos) {
      buffer_ = head.substr(end + 4);
      head.resize(end);
    }
    return head;
  }

  // One client frame: masked (as RFC 6455 §5.3 requires of clients) unless `masked` is false.
  static std::string frame(int opcode, const std::string& payload, bool masked = true,
                           std::uint8_t first_byte_extra = 0x80) {
    std::string f;
    f += static_cast<char>(first_byte_extra | (opcode & 0x0F));
    const std::uint8_t mask_bit = masked ? 0x80 : 0x00;
    if (payload.size() < 126) {
      f += static_cast<char>(mask_bit | payload.size());
    } else if (payload.size() < 65536) {
      f += static_cast<char>(mask_bit | 126);
      f += static_cast<char>((payload.size() >> 8) & 0xFF);
      f += static_cast<char>(payload.size() & 0xFF);
    } else {
      f += static_cast<char>(mask_bit | 127);
      for (int b = 7; b >= 0; --b) f += static_cast<char>((payload.size() >> (8 * b)) & 0xFF);
    }
    const char mask[4] = {0x12, 0x34, 0x56, 0x78};
    if (masked) f.append(mask, 4);
    for (std::size_t i = 0; i < payload.size(); ++i) {
      f += masked ? static_cast<char>(payload[i] ^ mask[i % 4]) : payload[i];
    }
    return f;
  }

  void send_text(const std::string& text) const { send_raw(frame(0x1, text)); }

  // The next complete server frame within `timeout`, or nullopt (nothing, or the connection
  // ended: closed() then says so).
  std::optional<Frame> read(std::chrono::milliseconds timeout = 2000ms) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    for (;;) {
      if (auto f = parse()) return f;
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      if (left <= 0ms || !fill(left)) return std::nullopt;
    }
  }

  // The next text frame parsed as JSON, skipping nothing.
  std::optional<Json> read_json(std::chrono::milliseconds timeout = 2000ms) {
    const auto f = read(timeout);
    if (!f || f->opcode != 0x1) return std::nullopt;
    return Json::parse(f->payload);
  }

  // Frames until one satisfies `pred` (or none within the timeout).
  std::optional<Frame> read_until(const std::function<bool(const Frame&)>& pred,
                                  std::chrono::milliseconds timeout = 2000ms) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      const auto f = read(std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now()));
      if (!f) return std::nullopt;
      if (pred(*f)) return f;
    }
    return std::nullopt;
  }

  // Whether the server closed the connection (EOF, or a close frame then EOF) within timeout.
  bool ends_within(std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      if (closed_) return true;
      (void)parse();
      buffer_.clear();
      (void)fill(std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now()));
    }
    return closed_;
  }
  [[nodiscard]] bool closed() const { return closed_; }

 private:
  bool fill(std::chrono::milliseconds timeout) {
    pollfd p{fd_, POLLIN, 0};
    if (::poll(&p, 1, static_cast<int>(std::max<long>(timeout.count(), 0))) <= 0) return false;
    char chunk[65536];
    const ssize_t n = ::recv(fd_, chunk, sizeof(chunk), 0);
    if (n <= 0) {
      closed_ = true;
      return false;
    }
    buffer_.append(chunk, static_cast<std::size_t>(n));
    return true;
  }

  std::optional<Frame> parse() {
    if (buffer_.size() < 2) return std::nullopt;
    const auto b = [&](std::size_t i) { return static_cast<std::uint8_t>(buffer_[i]); };
    std::size_t len = b(1) & 0x7F;
    std::size_t at = 2;
    if (len == 126) {
      if (buffer_.size() < 4) return std::nullopt;
      len = (std::size_t{b(2)} << 8) | b(3);
      at = 4;
    } else if (len == 127) {
      if (buffer_.size() < 10) return std::nullopt;
      len = 0;
      for (std::size_t i = 0; i < 8; ++i) len = (len << 8) | b(2 + i);
      at = 10;
    }
    if ((b(1) & 0x80) != 0) return std::nullopt;  // servers never mask (RFC 6455 §5.1)
    if (buffer_.size() < at + len) return std::nullopt;
    Frame f{b(0) & 0x0F, buffer_.substr(at, len)};
    buffer_.erase(0, at + len);
    return f;
  }

  int fd_{-1};
  std::string buffer_{};
  bool closed_{false};
};

ServerOptions loopback_any_port() {
  ServerOptions o;
  o.port = 0;
  o.name = "teleop test";
  o.metadata = {{"teleop_version", "test"}};
  return o;
}

ChannelSpec spec(const std::string& topic, const std::string& schema = "foobar") {
  return ChannelSpec{topic, "teleop.v1.Test", schema};
}

bool eventually(const std::function<bool()>& pred) {
  for (int i = 0; i < 400; ++i) {
    if (pred()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return pred();
}

// A client through the handshake with server info and advertise read; its channel list.
Json open_client(RawClient& c) {
  const std::string head = c.handshake();
  EXPECT_NE(head.find("HTTP/1.1 101"), std::string::npos) << head;
  const auto info = c.read_json();
  EXPECT_TRUE(info.has_value());
  EXPECT_EQ(info.value_or(Json{})["op"], "serverInfo");
  const auto adv = c.read_json();
  EXPECT_TRUE(adv.has_value());
  EXPECT_EQ(adv.value_or(Json{})["op"], "advertise");
  return adv.value_or(Json{})["channels"];
}

std::uint32_t u32_le(const std::string& s, std::size_t at) {
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    v |= static_cast<std::uint32_t>(static_cast<std::uint8_t>(s[at + i])) << (8 * i);
  }
  return v;
}
std::uint64_t u64_le(const std::string& s, std::size_t at) {
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < 8; ++i) {
    v |= static_cast<std::uint64_t>(static_cast<std::uint8_t>(s[at + i])) << (8 * i);
  }
  return v;
}

TEST(FoxgloveBase64, MatchesTheRfc4648TestVectors) {
  EXPECT_EQ(base64_encode(""), "");
  EXPECT_EQ(base64_encode("f"), "Zg==");
  EXPECT_EQ(base64_encode("fo"), "Zm8=");
  EXPECT_EQ(base64_encode("foo"), "Zm9v");
  EXPECT_EQ(base64_encode("foob"), "Zm9vYg==");
  EXPECT_EQ(base64_encode("fooba"), "Zm9vYmE=");
  EXPECT_EQ(base64_encode("foobar"), "Zm9vYmFy");
  EXPECT_EQ(base64_encode(std::string("\xff\xfe\x00", 3)), "//4A");
}

TEST(FoxgloveServer, HandshakeSelectsTheSubprotocolThenServerInfoAndAdvertise) {
  FoxgloveServer server(loopback_any_port());
  ASSERT_GT(server.port(), 0);
  const auto a = server.add_channel(spec("/slave/cycle", "foo"));
  const auto b = server.add_channel(spec("/supervisor/stability", "foobar"));
  RawClient c(server.port());
  const std::string head = c.handshake("other.protocol, foxglove.websocket.v1");
  EXPECT_NE(head.find("HTTP/1.1 101"), std::string::npos) << head;
  EXPECT_NE(head.find(std::string("Sec-WebSocket-Accept: ") + kRfcAccept), std::string::npos)
      << head;
  EXPECT_NE(head.find("Sec-WebSocket-Protocol: foxglove.websocket.v1"), std::string::npos) << head;
  const auto info = c.read_json();
  ASSERT_TRUE(info.has_value());
  EXPECT_EQ((*info)["op"], "serverInfo");
  EXPECT_EQ((*info)["name"], "teleop test");
  EXPECT_TRUE((*info)["capabilities"].is_array());
  EXPECT_EQ((*info)["metadata"]["teleop_version"], "test");
  const auto adv = c.read_json();
  ASSERT_TRUE(adv.has_value());
  EXPECT_EQ((*adv)["op"], "advertise");
  ASSERT_EQ((*adv)["channels"].size(), 2U);
  const Json& ch0 = (*adv)["channels"][0];
  EXPECT_EQ(ch0["id"], a);
  EXPECT_EQ(ch0["topic"], "/slave/cycle");
  EXPECT_EQ(ch0["encoding"], "protobuf");
  EXPECT_EQ(ch0["schemaEncoding"], "protobuf");
  EXPECT_EQ(ch0["schemaName"], "teleop.v1.Test");
  EXPECT_EQ(ch0["schema"], "Zm9v");
  EXPECT_EQ((*adv)["channels"][1]["id"], b);
  EXPECT_EQ((*adv)["channels"][1]["schema"], "Zm9vYmFy");
  EXPECT_NE(a, b);
  // A channel added later is advertised to the connected client at once.
  const auto late = server.add_channel(spec("/late"));
  const auto adv2 = c.read_json();
  ASSERT_TRUE(adv2.has_value());
  EXPECT_EQ((*adv2)["channels"][0]["id"], late);
  EXPECT_EQ((*adv2)["channels"][0]["topic"], "/late");
}

TEST(FoxgloveServer, RefusesAClientWithoutTheSubprotocol) {
  FoxgloveServer server(loopback_any_port());
  RawClient c(server.port());
  const std::string head = c.handshake("");
  EXPECT_EQ(head.find("HTTP/1.1 101"), std::string::npos) << head;
  EXPECT_NE(head.find("HTTP/1.1 4"), std::string::npos) << head;
  EXPECT_EQ(server.stats().refused, 1U);
}

TEST(FoxgloveServer, MessageDataFrameIsOpcodeSubscriptionTimestampPayloadLittleEndian) {
  std::mutex events_mutex;
  std::vector<std::string> events;
  ServerOptions options = loopback_any_port();
  options.on_event = [&](const std::string& line) {
    std::lock_guard lock(events_mutex);
    events.push_back(line);
  };
  FoxgloveServer server(options);
  const auto ch = server.add_channel(spec("/slave/cycle"));
  const auto other = server.add_channel(spec("/master/cycle"));
  RawClient c(server.port());
  (void)open_client(c);
  EXPECT_FALSE(server.has_subscribers(ch));
  c.send_text(
      Json{{"op", "subscribe"}, {"subscriptions", {{{"id", 0x01020304}, {"channelId", ch}}}}}
          .dump());
  ASSERT_TRUE(eventually([&] { return server.has_subscribers(ch); }));
  EXPECT_FALSE(server.has_subscribers(other));
  server.publish(other, 5, "not subscribed");
  server.publish(ch, 0x1122334455667788ULL, std::string("pay\0load", 8));
  const auto f = c.read();
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->opcode, 0x2);  // a binary WebSocket frame
  ASSERT_EQ(f->payload.size(), 1U + 4U + 8U + 8U);
  EXPECT_EQ(static_cast<std::uint8_t>(f->payload[0]), 0x01);
  // Little-endian by byte, as the spec requires.
  EXPECT_EQ(static_cast<std::uint8_t>(f->payload[1]), 0x04);
  EXPECT_EQ(static_cast<std::uint8_t>(f->payload[4]), 0x01);
  EXPECT_EQ(static_cast<std::uint8_t>(f->payload[5]), 0x88);
  EXPECT_EQ(static_cast<std::uint8_t>(f->payload[12]), 0x11);
  EXPECT_EQ(u32_le(f->payload, 1), 0x01020304U);
  EXPECT_EQ(u64_le(f->payload, 5), 0x1122334455667788ULL);
  EXPECT_EQ(f->payload.substr(13), std::string("pay\0load", 8));
  // Unsubscribed: nothing more arrives.
  c.send_text(Json{{"op", "unsubscribe"}, {"subscriptionIds", {0x01020304}}}.dump());
  ASSERT_TRUE(eventually([&] { return !server.has_subscribers(ch); }));
  server.publish(ch, 7, "after");
  EXPECT_FALSE(c.read(200ms).has_value());
  EXPECT_EQ(server.stats().messages_sent, 1U);
  // Each step told as a line naming the client's address and the topic.
  std::lock_guard lock(events_mutex);
  ASSERT_EQ(events.size(), 3U);
  EXPECT_NE(events[0].find("127.0.0.1:"), std::string::npos) << events[0];
  EXPECT_NE(events[0].find(" connected"), std::string::npos) << events[0];
  EXPECT_NE(events[1].find(" subscribed to /slave/cycle"), std::string::npos) << events[1];
  EXPECT_NE(events[2].find(" unsubscribed from /slave/cycle"), std::string::npos) << events[2];
}

// A latched channel (the stability report, published only when it changes) gives a new
// subscriber the newest message at once, with its own timestamp.
TEST(FoxgloveServer, ALatchedChannelGivesANewSubscriberTheNewestMessage) {
  FoxgloveServer server(loopback_any_port());
  ChannelSpec s = spec("/supervisor/stability");
  s.latched = true;
  const auto ch = server.add_channel(s);
  const auto plain = server.add_channel(spec("/slave/cycle"));
  server.publish(ch, 100, "older");
  server.publish(ch, 200, "newest");
  server.publish(plain, 300, "gone");
  RawClient c(server.port());
  (void)open_client(c);
  c.send_text(
      Json{{"op", "subscribe"},
           {"subscriptions", {{{"id", 5}, {"channelId", ch}}, {{"id", 6}, {"channelId", plain}}}}}
          .dump());
  const auto f = c.read();
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(u32_le(f->payload, 1), 5U);
  EXPECT_EQ(u64_le(f->payload, 5), 200U);
  EXPECT_EQ(f->payload.substr(13), "newest");
  EXPECT_FALSE(c.read(200ms).has_value());  // nothing kept for the plain channel
}

// Each of these gets a status with level 2 naming the problem; the connection stays and
// serves a valid subscription afterwards.
TEST(FoxgloveServer, MalformedJsonOpsGetAnErrorStatusAndTheConnectionStays) {
  FoxgloveServer server(loopback_any_port());
  const auto ch = server.add_channel(spec("/slave/cycle"));
  RawClient c(server.port());
  (void)open_client(c);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"{not json", "not JSON"},
      {"[1,2,3]", "'op'"},
      {"42", "'op'"},
      {R"({"op": 7})", "'op'"},
      {R"({"noop": "subscribe"})", "'op'"},
      {R"({"op": "launchMissiles"})", "unknown op 'launchMissiles'"},
      {R"({"op": "subscribe"})", "'subscriptions' must be an array"},
      {R"({"op": "subscribe", "subscriptions": {"id": 1}})", "'subscriptions' must be an array"},
      {R"({"op": "subscribe", "subscriptions": [{"id": -1, "channelId": 1}]})", "whole numbers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1.5, "channelId": 1}]})", "whole numbers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 4294967296, "channelId": 1}]})",
       "whole numbers"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": "1"}]})", "whole numbers"},
      {R"({"op": "subscribe", "subscriptions": [null]})", "subscriptions[0]"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 999}]})",
       "channel 999 is not advertised"},
      {R"({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 0}]})",
       "channel 0 is not advertised"},
      {R"({"op": "unsubscribe", "subscriptionIds": "all"})", "'subscriptionIds' must be an array"},
      {R"({"op": "advertise", "channels": []})", "clientPublish"},
      {R"({"op": "getParameters", "parameterNames": []})", "parameters"},
      {R"({"op": "fetchAsset", "uri": "file:///etc/passwd", "requestId": 1})", "assets"},
  };
  for (const auto& [text, expected] : bad) {
    c.send_text(text);
    const auto status = c.read_json();
    ASSERT_TRUE(status.has_value()) << "no reply to " << text;
    EXPECT_EQ((*status)["op"], "status") << text;
    EXPECT_EQ((*status)["level"], 2) << text;
    EXPECT_NE((*status)["message"].get<std::string>().find(expected), std::string::npos)
        << text << " -> " << (*status)["message"];
  }
  // A binary message (client publish, which is not offered).
  c.send_raw(RawClient::frame(0x2, std::string("\x01\x00\x00\x00\x00xyz", 8)));
  const auto binary_status = c.read_json();
  ASSERT_TRUE(binary_status.has_value());
  EXPECT_EQ((*binary_status)["level"], 2);
  // Duplicates: a second subscription to the same channel, or the same id again.
  c.send_text(R"({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 1}]})");
  c.send_text(R"({"op": "subscribe", "subscriptions": [{"id": 2, "channelId": 1}]})");
  const auto dup_channel = c.read_json();
  ASSERT_TRUE(dup_channel.has_value());
  EXPECT_NE((*dup_channel)["message"].get<std::string>().find("already subscribed"),
            std::string::npos);
  c.send_text(R"({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": 1}]})");
  const auto dup_id = c.read_json();
  ASSERT_TRUE(dup_id.has_value());
  EXPECT_NE((*dup_id)["message"].get<std::string>().find("already in use"), std::string::npos);
  EXPECT_EQ(server.stats().bad_requests, bad.size() + 3U);
  // Still connected and served.
  ASSERT_TRUE(eventually([&] { return server.has_subscribers(ch); }));
  server.publish(ch, 1, "ok");
  const auto data = c.read_until([](const Frame& f) { return f.opcode == 0x2; });
  ASSERT_TRUE(data.has_value());
  EXPECT_EQ(u32_le(data->payload, 1), 1U);
  EXPECT_EQ(data->payload.substr(13), "ok");
}

// Frames and bytes no proper client sends: each ends at most its own connection (RFC 6455
// says the server fails it), never the server, which serves a new client afterwards.
TEST(FoxgloveServer, MalformedFramesEndOnlyTheirConnection) {
  ServerOptions o = loopback_any_port();
  o.max_request_bytes = 4096;
  FoxgloveServer server(o);
  const auto ch = server.add_channel(spec("/slave/cycle"));
  const std::vector<std::pair<std::string, std::string>> hostile = {
      {"unmasked client frame", RawClient::frame(0x1, R"({"op":"subscribe"})", false)},
      {"reserved opcode 0x3", RawClient::frame(0x3, "xx")},
      {"RSV1 set without an extension", RawClient::frame(0x1, "{}", true, 0xC0)},
      {"invalid UTF-8 in a text frame", RawClient::frame(0x1, "{\"op\":\"\xff\xfe\"}")},
      {"message over the size limit", RawClient::frame(0x1, std::string(10000, ' '))},
      {"a 2^62-byte length", std::string("\x81\xFF\x40\x00\x00\x00\x00\x00\x00\x00mask", 14)},
      {"fragmented control frame", RawClient::frame(0x9, "ping", true, 0x00)},
      {"continuation with nothing to continue", RawClient::frame(0x0, "tail")},
  };
  for (const auto& [what, bytes] : hostile) {
    RawClient c(server.port());
    (void)open_client(c);
    c.send_raw(bytes);
    EXPECT_TRUE(c.ends_within(3000ms)) << what << ": the connection was not failed";
  }
  {
    // Garbage instead of a handshake, and a handshake cut short.
    RawClient g(server.port());
    g.send_raw(std::string("\x00\x01\x02 GARBAGE \r\n\r\n", 16));
    EXPECT_TRUE(g.ends_within(3000ms));
    RawClient h(server.port());
    h.send_raw("GET / HTTP/1.1\r\nUpgrade: websocket\r\n");
  }
  // The server is still there and serves a well-behaved client.
  RawClient good(server.port());
  const Json channels = open_client(good);
  ASSERT_EQ(channels.size(), 1U);
  good.send_text(
      Json{{"op", "subscribe"}, {"subscriptions", {{{"id", 9}, {"channelId", ch}}}}}.dump());
  ASSERT_TRUE(eventually([&] { return server.has_subscribers(ch); }));
  server.publish(ch, 3, "still serving");
  const auto f = good.read();
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->payload.substr(13), "still serving");
  EXPECT_GE(server.stats().connections, hostile.size() + 1);
}

// A client that never reads: its messages drop once its buffer is full; the server's memory
// for it stays bounded and other clients are not held up.
TEST(FoxgloveServer, ASlowClientLosesMessagesNotMemory) {
  ServerOptions o = loopback_any_port();
  o.max_buffered_bytes = 64 * 1024;
  FoxgloveServer server(o);
  const auto ch = server.add_channel(spec("/slave/cycle"));
  RawClient slow(server.port());
  (void)open_client(slow);
  slow.send_text(
      Json{{"op", "subscribe"}, {"subscriptions", {{{"id", 1}, {"channelId", ch}}}}}.dump());
  ASSERT_TRUE(eventually([&] { return server.has_subscribers(ch); }));
  const std::string chunk(10 * 1024, 'x');
  constexpr int kMessages = 4000;  // 40 MB offered, never read
  for (int i = 0; i < kMessages; ++i) {
    server.publish(ch, static_cast<std::uint64_t>(i), chunk);
    if (i % 100 == 0) std::this_thread::sleep_for(1ms);
  }
  ASSERT_TRUE(eventually([&] {
    const ServerStats s = server.stats();
    return s.messages_sent + s.messages_dropped >= static_cast<std::uint64_t>(kMessages);
  }));
  const ServerStats s = server.stats();
  EXPECT_GT(s.messages_dropped, 0U);
  // What was accepted fits the kernel's socket buffers plus the 64 KiB bound, far below the
  // 40 MB offered.
  EXPECT_LT(s.messages_sent * chunk.size(), 16U * 1024U * 1024U) << s.messages_sent;
  // Another client is still served.
  RawClient fresh(server.port());
  (void)open_client(fresh);
  fresh.send_text(
      Json{{"op", "subscribe"}, {"subscriptions", {{{"id", 2}, {"channelId", ch}}}}}.dump());
  ASSERT_TRUE(eventually([&] {
    server.publish(ch, 1, "hello");
    return fresh.read_until([](const Frame& f) { return f.opcode == 0x2; }, 50ms).has_value();
  }));
}

TEST(FoxgloveServer, ClientsBeyondTheLimitAreRefused) {
  ServerOptions o = loopback_any_port();
  o.max_clients = 2;
  FoxgloveServer server(o);
  RawClient a(server.port());
  RawClient b(server.port());
  (void)open_client(a);
  (void)open_client(b);
  RawClient c(server.port());
  const std::string head = c.handshake();
  EXPECT_EQ(head.find("HTTP/1.1 101"), std::string::npos) << head;
  EXPECT_EQ(server.stats().clients, 2U);
}

TEST(FoxgloveServer, CannotListenNamesTheAddressAndPort) {
  ServerOptions o = loopback_any_port();
  o.address = "not-an-address";
  try {
    FoxgloveServer s(o);
    FAIL() << "listened on a name that is not an address";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("not-an-address"), std::string::npos) << e.what();
  }
  FoxgloveServer first(loopback_any_port());
  ServerOptions same = loopback_any_port();
  same.port = first.port();
  try {
    FoxgloveServer s(same);
    FAIL() << "two servers on one port";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("127.0.0.1:" + std::to_string(first.port())),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace teleop::bridge
