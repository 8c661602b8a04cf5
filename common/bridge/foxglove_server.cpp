// The Foxglove WebSocket protocol server (foxglove_server.hpp). websocketpp 0.8 does not
// compile as C++20 with GCC 12 (template-ids as constructor names), so this one file is built
// as C++17 (common/bridge/CMakeLists.txt); its header exposes no websocketpp type.
#include "common/bridge/foxglove_server.hpp"

#include <array>
#include <atomic>
#include <chrono>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <thread>
#include <vector>
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

namespace teleop::bridge {

namespace {

using Server = websocketpp::server<websocketpp::config::asio>;
using Hdl = websocketpp::connection_hdl;
using Json = nlohmann::json;

// Level of a `status` message (spec: 0 info, 1 warning, 2 error).
constexpr int kError = 2;
constexpr int kWarning = 1;
// Messages posted to the server thread and not yet delivered, and their bytes; beyond either,
// publish() drops (the server thread stalled: memory stays bounded).
constexpr int kMaxPendingPosts = 20000;
constexpr std::size_t kMaxPendingBytes = std::size_t{64} << 20;

// Ops of the spec that need a capability this server does not advertise.
constexpr std::array<std::pair<std::string_view, std::string_view>, 9> kUnsupportedOps{{
    {"advertise", "clientPublish"},
    {"unadvertise", "clientPublish"},
    {"getParameters", "parameters"},
    {"setParameters", "parameters"},
    {"subscribeParameterUpdates", "parametersSubscribe"},
    {"unsubscribeParameterUpdates", "parametersSubscribe"},
    {"subscribeConnectionGraph", "connectionGraph"},
    {"unsubscribeConnectionGraph", "connectionGraph"},
    {"fetchAsset", "assets"},
}};

std::string dump(const Json& j) {
  // Client text is echoed in error statuses: never let invalid UTF-8 make dump() throw.
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

// A uint32 from a JSON number that is a whole number in range; false otherwise.
bool to_u32(const Json& j, std::uint32_t& out) {
  if (j.is_number_unsigned()) {
    const auto v = j.get<std::uint64_t>();
    if (v > 0xFFFFFFFFULL) return false;
    out = static_cast<std::uint32_t>(v);
    return true;
  }
  if (j.is_number_integer()) {
    const auto v = j.get<std::int64_t>();
    if (v < 0 || v > 0xFFFFFFFFLL) return false;
    out = static_cast<std::uint32_t>(v);
    return true;
  }
  return false;
}

struct Channel {
  ChannelSpec spec;
  std::string schema_base64;
  std::atomic<std::uint32_t> subscribers{0};
  // Latched channels: the newest message and its time (server thread only).
  std::optional<std::pair<std::uint64_t, std::string>> last{};
};

struct Client {
  std::map<std::uint32_t, std::uint32_t> subscriptions{};  // subscription id -> channel id
};

}  // namespace

struct FoxgloveServer::Impl {
  ServerOptions options;
  Server server{};
  std::thread thread{};
  std::uint16_t port{0};
  std::string session_id{};

  mutable std::mutex channels_mutex{};
  std::vector<std::unique_ptr<Channel>> channels{};  // channel id = index + 1

  // Server thread only.
  std::map<Hdl, Client, std::owner_less<Hdl>> clients{};

  std::atomic<std::uint64_t> connections{0};
  std::atomic<std::uint64_t> clients_now{0};
  std::atomic<std::uint64_t> sent{0};
  std::atomic<std::uint64_t> dropped{0};
  std::atomic<std::uint64_t> bad{0};
  std::atomic<std::uint64_t> refused{0};
  std::atomic<int> pending{0};
  std::atomic<std::size_t> pending_bytes{0};

  explicit Impl(ServerOptions o) : options(std::move(o)) {}

  Channel* channel(std::uint32_t id) const {
    std::lock_guard<std::mutex> lock(channels_mutex);
    if (id == 0 || id > channels.size()) return nullptr;
    return channels[id - 1].get();
  }

  static Json advertised(std::uint32_t id, const Channel& c) {
    return Json{{"id", id},
                {"topic", c.spec.topic},
                {"encoding", c.spec.encoding},
                {"schemaName", c.spec.schema_name},
                {"schema", c.schema_base64},
                {"schemaEncoding", c.spec.schema_encoding}};
  }

  // One frame to one client, unless its buffer is full (then dropped and counted): whether it
  // was handed to the connection.
  bool send_frame(Hdl h, const std::string& bytes, websocketpp::frame::opcode::value opcode) {
    websocketpp::lib::error_code ec;
    const Server::connection_ptr con = server.get_con_from_hdl(h, ec);
    if (ec || !con) return false;
    if (con->get_buffered_amount() > options.max_buffered_bytes) {
      dropped.fetch_add(1, std::memory_order_relaxed);
      return false;
    }
    return !con->send(bytes, opcode);
  }

  void send_text(Hdl h, const std::string& text) {
    (void)send_frame(h, text, websocketpp::frame::opcode::text);
  }

  void event(Hdl h, const std::string& what) {
    if (!options.on_event) return;
    websocketpp::lib::error_code ec;
    const Server::connection_ptr con = server.get_con_from_hdl(h, ec);
    options.on_event((ec || !con ? std::string("a client") : con->get_remote_endpoint()) + " " +
                     what);
  }

  void status(Hdl h, int level, const std::string& message) {
    send_text(h, dump(Json{{"op", "status"}, {"level", level}, {"message", message}}));
  }

  void reject(Hdl h, const std::string& message) {
    bad.fetch_add(1, std::memory_order_relaxed);
    status(h, kError, message);
  }

  bool validate(Hdl h) {
    websocketpp::lib::error_code ec;
    const Server::connection_ptr con = server.get_con_from_hdl(h, ec);
    if (ec || !con) return false;
    if (clients.size() >= options.max_clients) {
      refused.fetch_add(1, std::memory_order_relaxed);
      con->set_status(websocketpp::http::status_code::service_unavailable);
      return false;
    }
    for (const std::string& p : con->get_requested_subprotocols()) {
      if (p == kSubprotocol) {
        con->select_subprotocol(std::string(kSubprotocol), ec);
        return !ec;
      }
    }
    refused.fetch_add(1, std::memory_order_relaxed);
    con->set_status(websocketpp::http::status_code::bad_request);
    con->set_body("this server speaks the WebSocket subprotocol foxglove.websocket.v1 only\n");
    return false;
  }

  void on_open(Hdl h) {
    clients[h] = Client{};
    connections.fetch_add(1, std::memory_order_relaxed);
    clients_now.store(clients.size(), std::memory_order_relaxed);
    Json info{{"op", "serverInfo"},
              {"name", options.name},
              {"capabilities", Json::array()},
              {"sessionId", session_id}};
    info["metadata"] = Json::object();
    for (const auto& [k, v] : options.metadata) info["metadata"][k] = v;
    send_text(h, dump(info));
    Json list = Json::array();
    {
      std::lock_guard<std::mutex> lock(channels_mutex);
      for (std::size_t i = 0; i < channels.size(); ++i) {
        list.push_back(advertised(static_cast<std::uint32_t>(i + 1), *channels[i]));
      }
    }
    send_text(h, dump(Json{{"op", "advertise"}, {"channels", list}}));
    event(h, "connected");
  }

  void on_close(Hdl h) {
    const auto it = clients.find(h);
    if (it == clients.end()) return;
    for (const auto& [sub, ch] : it->second.subscriptions) {
      if (Channel* c = channel(ch)) c->subscribers.fetch_sub(1, std::memory_order_relaxed);
    }
    clients.erase(it);
    clients_now.store(clients.size(), std::memory_order_relaxed);
    event(h, "disconnected");
  }

  void subscribe(Hdl h, Client& client, const Json& request) {
    const auto list = request.find("subscriptions");
    if (list == request.end() || !list->is_array()) {
      reject(h, "subscribe: 'subscriptions' must be an array of {id, channelId}");
      return;
    }
    std::size_t index = 0;
    for (const Json& s : *list) {
      const std::string where = "subscribe: subscriptions[" + std::to_string(index++) + "]";
      std::uint32_t id = 0;
      std::uint32_t ch = 0;
      if (!s.is_object() || !s.contains("id") || !s.contains("channelId") || !to_u32(s["id"], id) ||
          !to_u32(s["channelId"], ch)) {
        reject(h, where + ": needs 'id' and 'channelId', whole numbers in [0, 2^32)");
        continue;
      }
      Channel* c = channel(ch);
      if (c == nullptr) {
        reject(h, where + ": channel " + std::to_string(ch) + " is not advertised");
        continue;
      }
      if (client.subscriptions.count(id) != 0) {
        reject(h, where + ": subscription id " + std::to_string(id) + " is already in use");
        continue;
      }
      bool already = false;
      for (const auto& [sub, other] : client.subscriptions) already = already || other == ch;
      if (already) {
        reject(h, where + ": channel " + std::to_string(ch) + " (" + c->spec.topic +
                      ") is already subscribed by this client");
        continue;
      }
      client.subscriptions[id] = ch;
      c->subscribers.fetch_add(1, std::memory_order_relaxed);
      event(h, "subscribed to " + c->spec.topic);
      if (c->last) send_data(h, id, c->last->first, c->last->second);
    }
  }

  void unsubscribe(Hdl h, Client& client, const Json& request) {
    const auto list = request.find("subscriptionIds");
    if (list == request.end() || !list->is_array()) {
      reject(h, "unsubscribe: 'subscriptionIds' must be an array of numbers");
      return;
    }
    for (const Json& s : *list) {
      std::uint32_t id = 0;
      const auto it = to_u32(s, id) ? client.subscriptions.find(id) : client.subscriptions.end();
      if (it == client.subscriptions.end()) {
        bad.fetch_add(1, std::memory_order_relaxed);
        status(h, kWarning, "unsubscribe: " + dump(s) + " is not a subscription of this client");
        continue;
      }
      if (Channel* c = channel(it->second)) {
        c->subscribers.fetch_sub(1, std::memory_order_relaxed);
        event(h, "unsubscribed from " + c->spec.topic);
      }
      client.subscriptions.erase(it);
    }
  }

  void on_text(Hdl h, const std::string& text) {
    const Json request = Json::parse(text, nullptr, false);
    if (request.is_discarded()) {
      reject(h, "not JSON: every text message must be a JSON object with an 'op' field");
      return;
    }
    if (!request.is_object() || !request.contains("op") || !request["op"].is_string()) {
      reject(h, "a text message must be a JSON object with a string 'op' field");
      return;
    }
    const auto it = clients.find(h);
    if (it == clients.end()) return;
    const std::string op = request["op"].get<std::string>();
    if (op == "subscribe") {
      subscribe(h, it->second, request);
      return;
    }
    if (op == "unsubscribe") {
      unsubscribe(h, it->second, request);
      return;
    }
    for (const auto& [name, capability] : kUnsupportedOps) {
      if (op == name) {
        reject(h, "op '" + op + "' needs the capability '" + std::string(capability) +
                      "', which this server does not advertise");
        return;
      }
    }
    reject(h, "unknown op '" + op + "'");
  }

  void on_message(Hdl h, const Server::message_ptr& m) {
    if (m->get_opcode() != websocketpp::frame::opcode::text) {
      reject(h,
             "binary client messages (client publish, service calls) are not supported: "
             "this server advertises no capability");
      return;
    }
    on_text(h, m->get_payload());
  }

  void send_data(Hdl h, std::uint32_t sub, std::uint64_t time_ns, const std::string& payload) {
    if (send_frame(h, message_data_frame(sub, time_ns, payload),
                   websocketpp::frame::opcode::binary)) {
      sent.fetch_add(1, std::memory_order_relaxed);
    }
  }

  void deliver(std::uint32_t ch, std::uint64_t time_ns, const std::string& payload) {
    if (Channel* c = channel(ch); c != nullptr && c->spec.latched)
      c->last.emplace(time_ns, payload);
    for (auto& [h, client] : clients) {
      for (const auto& [sub, channel_id] : client.subscriptions) {
        if (channel_id == ch) send_data(h, sub, time_ns, payload);
      }
    }
  }

  // Runs a handler; whatever it throws is counted and answered, never lets the thread end.
  template <typename F>
  void guarded(Hdl h, F&& f) {
    try {
      f();
    } catch (const std::exception& e) {
      try {
        reject(h, std::string("request not handled: ") + e.what());
      } catch (...) {
      }
    } catch (...) {
      bad.fetch_add(1, std::memory_order_relaxed);
    }
  }

  void install_handlers() {
    server.set_validate_handler([this](Hdl h) {
      bool ok = false;
      guarded(h, [&] { ok = validate(h); });
      return ok;
    });
    server.set_open_handler([this](Hdl h) { guarded(h, [&] { on_open(h); }); });
    server.set_close_handler([this](Hdl h) { guarded(h, [&] { on_close(h); }); });
    server.set_fail_handler([this](Hdl h) { guarded(h, [&] { on_close(h); }); });
    server.set_message_handler(
        [this](Hdl h, Server::message_ptr m) { guarded(h, [&] { on_message(h, m); }); });
  }

  void listen() {
    server.clear_access_channels(websocketpp::log::alevel::all);
    server.clear_error_channels(websocketpp::log::elevel::all);
    server.init_asio();
    server.set_reuse_addr(true);
    server.set_max_message_size(options.max_request_bytes);
    server.set_max_http_body_size(options.max_request_bytes);
    install_handlers();
    const std::string where = options.address + ":" + std::to_string(options.port);
    websocketpp::lib::error_code ec;
    const auto address = websocketpp::lib::asio::ip::make_address(options.address, ec);
    if (ec) {
      throw std::runtime_error("bridge address '" + options.address + "' is not an IP address (" +
                               ec.message() + ")");
    }
    server.listen(websocketpp::lib::asio::ip::tcp::endpoint(address, options.port), ec);
    if (ec) throw std::runtime_error("cannot listen on " + where + ": " + ec.message());
    server.start_accept(ec);
    if (ec) throw std::runtime_error("cannot accept on " + where + ": " + ec.message());
    port = server.get_local_endpoint(ec).port();
    session_id = std::to_string(std::chrono::duration_cast<std::chrono::nanoseconds>(
                                    std::chrono::system_clock::now().time_since_epoch())
                                    .count());
  }

  void run() {
    for (;;) {
      try {
        server.run();
        return;
      } catch (...) {
        bad.fetch_add(1, std::memory_order_relaxed);  // resume: run() may be called again
      }
    }
  }

  void stop() {
    // Close every client (going away), give the close frames a moment, then stop the loop.
    websocketpp::lib::asio::post(server.get_io_service(), [this] {
      websocketpp::lib::error_code ec;
      server.stop_listening(ec);
      for (auto& [h, client] : clients) {
        server.close(h, websocketpp::close::status::going_away, "server stopping", ec);
      }
    });
    for (int i = 0; i < 40 && clients_now.load() > 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    server.stop();
    if (thread.joinable()) thread.join();
  }
};

FoxgloveServer::FoxgloveServer(ServerOptions options)
    : impl_(std::make_unique<Impl>(std::move(options))) {
  impl_->listen();
  impl_->thread = std::thread([this] { impl_->run(); });
}

FoxgloveServer::~FoxgloveServer() {
  try {
    impl_->stop();
  } catch (...) {
  }
}

std::uint32_t FoxgloveServer::add_channel(ChannelSpec spec) {
  auto c = std::make_unique<Channel>();
  c->schema_base64 = base64_encode(spec.schema_data);
  c->spec = std::move(spec);
  std::uint32_t id = 0;
  Json advertise;
  {
    std::lock_guard<std::mutex> lock(impl_->channels_mutex);
    impl_->channels.push_back(std::move(c));
    id = static_cast<std::uint32_t>(impl_->channels.size());
    advertise = Json{{"op", "advertise"},
                     {"channels", Json::array({Impl::advertised(id, *impl_->channels.back())})}};
  }
  auto text = std::make_shared<std::string>(dump(advertise));
  websocketpp::lib::asio::post(impl_->server.get_io_service(), [this, text] {
    for (auto& [h, client] : impl_->clients) impl_->send_text(h, *text);
  });
  return id;
}

void FoxgloveServer::publish(std::uint32_t channel, std::uint64_t receive_time_ns,
                             std::string_view payload) noexcept {
  Impl& m = *impl_;
  const Channel* c = m.channel(channel);
  if (c == nullptr || (!c->spec.latched && c->subscribers.load(std::memory_order_relaxed) == 0)) {
    return;
  }
  if (m.pending.load(std::memory_order_relaxed) > kMaxPendingPosts ||
      m.pending_bytes.load(std::memory_order_relaxed) + payload.size() > kMaxPendingBytes) {
    m.dropped.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  try {
    auto data = std::make_shared<std::string>(payload);
    m.pending.fetch_add(1, std::memory_order_relaxed);
    m.pending_bytes.fetch_add(data->size(), std::memory_order_relaxed);
    websocketpp::lib::asio::post(m.server.get_io_service(), [&m, channel, receive_time_ns, data] {
      m.pending.fetch_sub(1, std::memory_order_relaxed);
      m.pending_bytes.fetch_sub(data->size(), std::memory_order_relaxed);
      try {
        m.deliver(channel, receive_time_ns, *data);
      } catch (...) {
        m.dropped.fetch_add(1, std::memory_order_relaxed);
      }
    });
  } catch (...) {
    m.dropped.fetch_add(1, std::memory_order_relaxed);
  }
}

bool FoxgloveServer::has_subscribers(std::uint32_t channel) const noexcept {
  const Channel* c = impl_->channel(channel);
  return c != nullptr && c->subscribers.load(std::memory_order_relaxed) > 0;
}

std::uint16_t FoxgloveServer::port() const noexcept { return impl_->port; }

ServerStats FoxgloveServer::stats() const noexcept {
  const Impl& m = *impl_;
  ServerStats s;
  s.connections = m.connections.load();
  s.clients = m.clients_now.load();
  s.messages_sent = m.sent.load();
  s.messages_dropped = m.dropped.load();
  s.bad_requests = m.bad.load();
  s.refused = m.refused.load();
  return s;
}

std::string base64_encode(std::string_view bytes) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 3 <= bytes.size(); i += 3) {
    const auto n = (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i])) << 16) |
                   (static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 1])) << 8) |
                   static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 2]));
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += kAlphabet[(n >> 6) & 63];
    out += kAlphabet[n & 63];
  }
  const std::size_t rest = bytes.size() - i;
  if (rest > 0) {
    std::uint32_t n = static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i])) << 16;
    if (rest == 2) n |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[i + 1])) << 8;
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += rest == 2 ? kAlphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string message_data_frame(std::uint32_t subscription_id, std::uint64_t receive_time_ns,
                               std::string_view payload) {
  std::string frame(13 + payload.size(), '\0');
  frame[0] = '\x01';
  for (int b = 0; b < 4; ++b) {
    frame[static_cast<std::size_t>(1 + b)] = static_cast<char>((subscription_id >> (8 * b)) & 0xFF);
  }
  for (int b = 0; b < 8; ++b) {
    frame[static_cast<std::size_t>(5 + b)] = static_cast<char>((receive_time_ns >> (8 * b)) & 0xFF);
  }
  std::copy(payload.begin(), payload.end(), frame.begin() + 13);
  return frame;
}

}  // namespace teleop::bridge
