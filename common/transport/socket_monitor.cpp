#include "common/transport/socket_monitor.hpp"

#include <linux/tcp.h>
#include <malloc.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <zmq.h>

#include <chrono>
#include <cstring>
#include <map>
#include <optional>
#include <stdexcept>

namespace teleop::transport {
namespace {

constexpr int kEvents = ZMQ_EVENT_ACCEPTED | ZMQ_EVENT_DISCONNECTED |
                        ZMQ_EVENT_HANDSHAKE_FAILED_NO_DETAIL | ZMQ_EVENT_HANDSHAKE_FAILED_PROTOCOL |
                        ZMQ_EVENT_HANDSHAKE_FAILED_AUTH;

std::atomic<std::uint64_t> g_next_id{0};

using Tracked = SocketMonitor::Tracked;

bool names(int fd, sockaddr_storage& local, sockaddr_storage& peer) {
  socklen_t n = sizeof(local);
  socklen_t m = sizeof(peer);
  std::memset(&local, 0, sizeof(local));
  std::memset(&peer, 0, sizeof(peer));
  return ::getsockname(fd, reinterpret_cast<sockaddr*>(&local), &n) == 0 &&
         ::getpeername(fd, reinterpret_cast<sockaddr*>(&peer), &m) == 0;
}

bool same_connection(int fd, const Tracked& t) {
  sockaddr_storage local{};
  sockaddr_storage peer{};
  return names(fd, local, peer) && std::memcmp(&local, &t.local, sizeof(local)) == 0 &&
         std::memcmp(&peer, &t.peer, sizeof(peer)) == 0;
}

// TCP payload bytes received on `fd` (nullopt: not a TCP socket any more).
std::optional<std::uint64_t> bytes_received(int fd) {
  tcp_info info{};
  socklen_t n = sizeof(info);
  if (::getsockopt(fd, IPPROTO_TCP, TCP_INFO, &info, &n) != 0) return std::nullopt;
  return static_cast<std::uint64_t>(info.tcpi_bytes_received);
}

}  // namespace

SocketMonitor::SocketMonitor(zmq::context_t& ctx, const std::vector<zmq::socket_t*>& sockets,
                             const std::string& tag, std::vector<InboundBudget> budgets)
    : sockets_(sockets), budgets_(std::move(budgets)) {
  budgets_.resize(sockets_.size());
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
  return {counts_[0].load(), counts_[1].load(), counts_[2].load(), counts_[3].load(),
          counts_[4].load()};
}

void SocketMonitor::run() {
  std::vector<zmq::pollitem_t> items;
  for (zmq::socket_t& p : pairs_) items.push_back({p.handle(), 0, ZMQ_POLLIN, 0});
  // Per socket: the connections it accepted, by descriptor (budgeted sockets only).
  std::vector<std::map<int, Tracked>> tracked(sockets_.size());
  bool trim = false;
  while (running_.load()) {
    try {
      check_budgets(tracked, trim);
      if (zmq::poll(items.data(), items.size(), std::chrono::milliseconds(10)) <= 0) continue;
    } catch (const zmq::error_t&) {
      continue;
    }
    for (std::size_t i = 0; i < items.size(); ++i) {
      if ((items[i].revents & ZMQ_POLLIN) == 0) continue;
      // An event is two frames: 2 bytes event id + 4 bytes value, then the endpoint.
      zmq::message_t event;
      while (pairs_[i].recv(event, zmq::recv_flags::dontwait)) {
        std::uint16_t kind = 0;
        std::uint32_t value = 0;
        if (event.size() >= sizeof(kind)) std::memcpy(&kind, event.data(), sizeof(kind));
        if (event.size() >= sizeof(kind) + sizeof(value)) {
          std::memcpy(&value, static_cast<const char*>(event.data()) + sizeof(kind), sizeof(value));
        }
        const int fd = static_cast<int>(value);
        if (budgets_[i].burst_bytes > 0 && kind == ZMQ_EVENT_ACCEPTED) {
          Tracked t;
          t.since = std::chrono::steady_clock::now();
          if (names(fd, t.local, t.peer)) tracked[i][fd] = t;
        } else if (budgets_[i].burst_bytes > 0 && kind == ZMQ_EVENT_DISCONNECTED) {
          const auto it = tracked[i].find(fd);
          if (it != tracked[i].end()) {
            // A connection that sent much (and had a trie built for it): its memory goes back.
            if (it->second.received > budgets_[i].burst_bytes / 4) trim = true;
            tracked[i].erase(it);
          }
        }
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

void SocketMonitor::check_budgets(std::vector<std::map<int, Tracked>>& tracked, bool& trim) {
  const auto now = std::chrono::steady_clock::now();
  for (std::size_t i = 0; i < tracked.size(); ++i) {
    const InboundBudget& b = budgets_[i];
    for (auto it = tracked[i].begin(); it != tracked[i].end();) {
      const int fd = it->first;
      const std::optional<std::uint64_t> got = bytes_received(fd);
      if (!got || !same_connection(fd, it->second)) {
        it = tracked[i].erase(it);  // gone (its DISCONNECTED is on its way)
        continue;
      }
      it->second.received = *got;
      const double age_s = std::chrono::duration<double>(now - it->second.since).count();
      const double allowed =
          static_cast<double>(b.burst_bytes) + static_cast<double>(b.bytes_per_s) * age_s;
      if (static_cast<double>(*got) > allowed) {
        (void)::shutdown(fd, SHUT_RDWR);
        counts_[4].fetch_add(1);
        trim = true;
        it = tracked[i].erase(it);
        continue;
      }
      ++it;
    }
  }
  // What cut or flooding connections held (their queued messages, the publisher's trie) goes
  // back to the system, so a flood leaves no lasting (and, under mlockall, locked) growth:
  // trimmed at once and every 100 ms for 2 s after, while the sockets' threads drain what
  // was queued before the cut.
  if (trim) {
    trim_until_ = now + std::chrono::seconds(2);
    trim = false;
  }
  if (now < trim_until_ && now >= next_trim_) {
    (void)::malloc_trim(0);
    next_trim_ = now + std::chrono::milliseconds(100);
  }
}

}  // namespace teleop::transport
