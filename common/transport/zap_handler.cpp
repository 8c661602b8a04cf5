#include "common/transport/zap_handler.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <stdexcept>
#include <utility>
#include <zmq.hpp>

#include "common/transport/zmq_security.hpp"

namespace teleop::transport {

namespace {

// RFC 27 fixes the address; libzmq looks the handler up on the socket's own context.
constexpr const char* kZapEndpoint = "inproc://zeromq.zap.01";
constexpr std::size_t kKeyBytes = 32;

// Which contexts have a handler, so a CURVE server is never set up on one without (libzmq
// would then accept any client key).
std::mutex& registry_mutex() {
  static std::mutex m;
  return m;
}
std::vector<std::pair<void*, ZapHandler*>>& registry() {
  static std::vector<std::pair<void*, ZapHandler*>> r;
  return r;
}

std::string z85_of(const std::string& binary_key) {
  std::array<char, kZ85KeyChars + 1> text{};
  zmq_z85_encode(text.data(), reinterpret_cast<const std::uint8_t*>(binary_key.data()),
                 binary_key.size());
  return std::string(text.data(), kZ85KeyChars);
}

std::string binary_of(const std::string& z85_key) {
  std::string bytes(kKeyBytes, '\0');
  zmq_z85_decode(reinterpret_cast<std::uint8_t*>(bytes.data()), z85_key.c_str());
  return bytes;
}

void send_reply(zmq::socket_t& socket, const std::string& request_id, std::string_view status,
                std::string_view text, std::string_view user_id) {
  // Version, request id, status code, status text, user id, metadata (empty).
  socket.send(zmq::str_buffer("1.0"), zmq::send_flags::sndmore);
  socket.send(zmq::buffer(request_id), zmq::send_flags::sndmore);
  socket.send(zmq::buffer(status), zmq::send_flags::sndmore);
  socket.send(zmq::buffer(text), zmq::send_flags::sndmore);
  socket.send(zmq::buffer(user_id), zmq::send_flags::sndmore);
  socket.send(zmq::message_t{}, zmq::send_flags::none);
}

}  // namespace

ZapHandler::ZapHandler(zmq::context_t& ctx) : context_handle_(ctx.handle()) {
  const std::lock_guard registry_lock(registry_mutex());
  for (const auto& entry : registry()) {
    if (entry.first == context_handle_) {
      throw std::runtime_error("a ZapHandler already serves this ZeroMQ context");
    }
  }
  zap_socket_ = std::make_unique<zmq::socket_t>(ctx, zmq::socket_type::rep);
  zap_socket_->set(zmq::sockopt::linger, 0);
  try {
    zap_socket_->bind(kZapEndpoint);
  } catch (const zmq::error_t& e) {
    throw std::runtime_error(fmt::format(
        "cannot serve ZAP: {} on this context: {} (another ZAP handler?)", kZapEndpoint, e.what()));
  }
  // PAIR over inproc between two threads of one process: the stop signal. (PAIR's reconnect
  // weakness is a TCP matter; inproc has nothing to reconnect.)
  const std::string control_endpoint =
      fmt::format("inproc://teleop.zap.control.{}", static_cast<const void*>(this));
  control_recv_ = std::make_unique<zmq::socket_t>(ctx, zmq::socket_type::pair);
  control_recv_->set(zmq::sockopt::linger, 0);
  control_recv_->bind(control_endpoint);
  control_send_ = std::make_unique<zmq::socket_t>(ctx, zmq::socket_type::pair);
  control_send_->set(zmq::sockopt::linger, 0);
  control_send_->connect(control_endpoint);
  refusals_.reserve(kRecentRefusals);
  // The sockets move to the thread here; starting a thread is the full memory barrier
  // ZeroMQ asks for when a socket changes threads.
  registry().reserve(registry().size() + 1);  // so registering below cannot throw
  thread_ = std::thread([this] { run(); });
  registry().emplace_back(context_handle_, this);
}

ZapHandler::~ZapHandler() {
  {
    const std::lock_guard registry_lock(registry_mutex());
    auto& r = registry();
    r.erase(std::remove_if(r.begin(), r.end(), [this](const auto& e) { return e.second == this; }),
            r.end());
  }
  try {
    control_send_->send(zmq::str_buffer("stop"), zmq::send_flags::none);
  } catch (const zmq::error_t& e) {
    // The thread would never see the signal; joining would hang. This is a broken context,
    // not a recoverable state.
    spdlog::critical("ZAP handler: cannot signal its thread to stop: {}", e.what());
    std::terminate();
  }
  thread_.join();
  // Closed here, after join (the thread is done with them), and before the context ends.
  zap_socket_.reset();
  control_recv_.reset();
  control_send_.reset();
}

std::string ZapHandler::add_domain(const std::string& label,
                                   const std::vector<std::string>& allowed_client_keys) {
  Domain domain{label, {}};
  for (const std::string& key : allowed_client_keys) {
    if (const auto problem = z85_key_problem(key)) {
      throw std::invalid_argument(fmt::format("{}: allowed client key is {}", label, *problem));
    }
    domain.allowed_keys.insert(binary_of(key));
  }
  const std::lock_guard lock(mutex_);
  // A number, not the label: ZAP domains are limited to 255 bytes and must be unique per
  // socket even when two sockets share an endpoint text such as "tcp://127.0.0.1:*".
  std::string name = fmt::format("teleop.{}", next_domain_++);
  domains_.emplace(name, std::move(domain));
  return name;
}

std::vector<ZapRefusal> ZapHandler::recent_refusals() const {
  const std::lock_guard lock(mutex_);
  return refusals_;
}

ZapHandler* ZapHandler::serving(zmq::context_t& ctx) {
  const std::lock_guard registry_lock(registry_mutex());
  for (const auto& entry : registry()) {
    if (entry.first == ctx.handle()) return entry.second;
  }
  return nullptr;
}

void ZapHandler::run() noexcept {
  std::array<zmq::pollitem_t, 2> items{};
  items[0] = {control_recv_->handle(), 0, ZMQ_POLLIN, 0};
  items[1] = {zap_socket_->handle(), 0, ZMQ_POLLIN, 0};
  while (true) {
    try {
      zmq::poll(items.data(), items.size(), std::chrono::milliseconds{-1});
      if ((items[0].revents & ZMQ_POLLIN) != 0) return;
      if ((items[1].revents & ZMQ_POLLIN) != 0) serve_one();
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) continue;
      if (e.num() == ETERM) return;
      // An unanswered request stalls that handshake, which fails closed; keep serving others.
      spdlog::error("ZAP handler: {}", e.what());
    } catch (const std::exception& e) {
      spdlog::error("ZAP handler: {}", e.what());
    }
  }
}

void ZapHandler::serve_one() {
  // Frames: version, request id, domain, address, identity, mechanism, credentials...
  std::vector<std::string> frames;
  zmq::message_t frame;
  do {
    if (!zap_socket_->recv(frame, zmq::recv_flags::none)) return;
    frames.push_back(frame.to_string());
  } while (frame.more());

  const std::string request_id = frames.size() > 1 ? frames[1] : std::string{};
  if (frames.size() < 6 || frames[0] != "1.0") {
    refuse(
        ZapRefusal{"", frames.size() > 3 ? frames[3] : std::string{}, "", "malformed ZAP request"});
    // A REP socket must answer before it can receive again, even a request it cannot parse.
    send_reply(*zap_socket_, request_id, "500", "malformed ZAP request", "");
    return;
  }
  const std::string& domain_name = frames[2];
  const std::string& address = frames[3];
  const std::string& mechanism = frames[5];
  const bool curve_key =
      mechanism == "CURVE" && frames.size() == 7 && frames[6].size() == kKeyBytes;
  const std::string key_z85 = curve_key ? z85_of(frames[6]) : std::string{};

  std::string label = domain_name;
  std::string reason;
  {
    const std::lock_guard lock(mutex_);
    const auto it = domains_.find(domain_name);
    if (it == domains_.end()) {
      reason = fmt::format("unknown ZAP domain '{}' (socket not set up by apply_link_security)",
                           domain_name);
    } else {
      label = it->second.label;
      if (!curve_key) {
        reason = fmt::format("mechanism {} is not allowed: CURVE is required", mechanism);
      } else if (it->second.allowed_keys.count(frames[6]) == 0) {
        reason = "client key is not in allowed_client_keys";
      }
    }
  }
  // Counted before the reply, so whoever observes the outcome (a message arriving, a
  // connection dropped) also sees it counted.
  if (!reason.empty()) {
    refuse(ZapRefusal{key_z85, address, label, reason});
    send_reply(*zap_socket_, request_id, "400", reason, "");
    return;
  }
  accepted_.fetch_add(1);
  spdlog::info("ZAP: accepted CURVE client {} from {} on {}", key_z85, address, label);
  send_reply(*zap_socket_, request_id, "200", "OK", key_z85);
}

void ZapHandler::refuse(ZapRefusal refusal) {
  spdlog::warn("ZAP: refused client {} from {} on {}: {}",
               refusal.client_key_z85.empty() ? "(no CURVE key)" : refusal.client_key_z85,
               refusal.peer_address, refusal.domain_label, refusal.reason);
  {
    const std::lock_guard lock(mutex_);
    if (refusals_.size() == kRecentRefusals) refusals_.erase(refusals_.begin());
    refusals_.push_back(std::move(refusal));
  }
  // Counted after the record is stored, so a reader that sees the count also sees the entry.
  refused_.fetch_add(1);
}

}  // namespace teleop::transport
