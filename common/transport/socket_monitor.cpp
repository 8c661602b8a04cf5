#include "common/transport/socket_monitor.hpp"

#include <zmq.h>

#include <cstring>
#include <stdexcept>

namespace teleop::transport {
namespace {

constexpr int kEvents = ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_DISCONNECTED |
                        ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL | ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                        ZMQ_EVENT_HANDSHAKE_FAILED_AUTH;

std::atomic<std::uint64_t> g_next_id{0};

}  // namespace

SocketMonitor::SocketMonitor(zmq::context_t& ctx, const std::vector<zmq::socket_t*>& sockets,
                             const std::string& tag)
    : sockets_(sockets) {
  const std::uint64_t id = g_next_id.fetch_add(1);
  for (std::size_t i = 0; i < sockets_.size(); ++i) {
    const std::string address =
        "inproc://monitor-" + tag + "-" + std::to_string(id) + "-" + std::to_string(i);
    if (zmq_socket_monitor(sockets_[i]->handle(), address.c_str(), kEvents) != 0) {
      throw std::runtime_error("cannot monitor a socket: " +
                               std::string(zmq_strerror(zmq_errno())));
    }
    zmq::socket_t pair(ctx, zmq::socket_type::pair);
    pair.set(zmq::sockopt::linger, 0);
    pair.connect(address);
    pairs_.push_back(std::move(pair));
  }
  thread_ = std::thread([this] { run(); });
}

SocketMonitor::~SocketMonitor() { stop(); }

void SocketMonitor::stop() {
  if (!running_.exchange(false)) return;
  if (thread_.joinable()) thread_.join();
  for (zmq::socket_t* s : sockets_) (void)zmq_socket_monitor(s->handle(), nullptr, 0);
  pairs_.clear();
}

ConnectionCounts SocketMonitor::counts() const {
  return {counts_[0].load(), counts_[1].load(), counts_[2].load(), counts_[3].load()};
}

void SocketMonitor::run() {
  std::vector<zmq::pollitem_t> items;
  for (zmq::socket_t& p : pairs_) items.push_back({p.handle(), 0, ZMQ_POLLIN, 0});
  while (running_.load()) {
    try {
      if (zmq::poll(items.data(), items.size(), std::chrono::milliseconds(50)) <= 0) continue;
    } catch (const zmq::error_t&) {
      continue;
    }
    for (std::size_t i = 0; i < items.size(); ++i) {
      if ((items[i].revents & ZMQ_POLLIN) == 0) continue;
      // An event is two frames: 2 bytes event id + 4 bytes value, then the endpoint.
      zmq::message_t event;
      while (pairs_[i].recv(event, zmq::recv_flags::dontwait)) {
        std::uint16_t kind = 0;
        if (event.size() >= sizeof(kind)) std::memcpy(&kind, event.data(), sizeof(kind));
        zmq::message_t endpoint;
        while (event.more() && pairs_[i].recv(endpoint, zmq::recv_flags::dontwait)) {
          if (!endpoint.more()) break;
        }
        switch (kind) {
          case ZMQ_EVENT_ACCEPTED:
            counts_[0].fetch_add(1);
            break;
          case ZMQ_EVENT_DISCONNECTED:
            counts_[1].fetch_add(1);
            break;
          case ZMQ_EVENT_HANDSHAKE_FAILED_AUTH:
            counts_[3].fetch_add(1);
            counts_[2].fetch_add(1);
            break;
          case ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL:
          case ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL:
            counts_[2].fetch_add(1);
            break;
          default:
            break;
        }
      }
    }
  }
}

}  // namespace teleop::transport
