#include "supervisor/teleopctl/estop_fanout.hpp"

#include <fmt/core.h>
#include <time.h>

#include <chrono>
#include <memory>
#include <zmq.hpp>

#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"

namespace teleop::ctl {
namespace {

using Clock = std::chrono::steady_clock;

// How long the supervisor's request may still be flushed once the nodes have answered: its
// connection is usually up by then and the bytes leave at once; a frozen supervisor's are
// dropped after this.
constexpr int kSupervisorLingerMs = 100;

}  // namespace

bool EstopResult::all_safe() const {
  for (const EstopOutcome& o : nodes) {
    if (!o.safe()) return false;
  }
  return !nodes.empty();
}

std::string EstopResult::nodes_text() const {
  std::string text;
  for (const EstopOutcome& o : nodes) {
    if (!text.empty()) text += ", ";
    if (o.reply) {
      text += o.name + " " + v1::NodeMode_Name(o.reply->mode()) +
              (o.via_supervisor ? " (through the supervisor)" : "");
    } else if (!o.error.empty()) {
      text += o.name + " NOT SENT (" + o.error + ")";
    } else {
      text += o.name + " NO REPLY";
    }
  }
  return text;
}

EstopResult estop_everywhere(const std::vector<EstopTarget>& nodes,
                             const std::optional<SupervisorTarget>& supervisor,
                             const std::string& requested_by, int timeout_ms) {
  EstopResult result;
  zmq::context_t ctx(1);
  const auto timeout = std::chrono::milliseconds(timeout_ms);
  // One socket per node (and one for the supervisor), set up first so the sends go out
  // back to back.
  std::vector<std::unique_ptr<zmq::socket_t>> sockets;
  for (const EstopTarget& t : nodes) {
    EstopOutcome o;
    o.name = t.name;
    o.endpoint = t.endpoint;
    try {
      transport::LinkSecurity sec;
      if (!t.keys.secret_key_file.empty()) {
        sec.own = transport::load_secret_key_file(t.keys.secret_key_file);
      }
      if (!t.keys.server_key.empty()) {
        sec.server_public_key = transport::load_public_key(t.keys.server_key);
      }
      sockets.push_back(std::make_unique<zmq::socket_t>(
          transport::make_command_client(ctx, t.endpoint, sec, timeout)));
    } catch (const std::exception& e) {
      o.error = e.what();
      sockets.push_back(nullptr);
    }
    result.nodes.push_back(std::move(o));
  }
  std::unique_ptr<zmq::socket_t> sup;
  if (supervisor) {
    try {
      transport::LinkSecurity sec;
      if (!supervisor->key_file.empty()) {
        sec.own = transport::load_secret_key_file(supervisor->key_file);
      }
      if (!supervisor->server_key.empty()) {
        sec.server_public_key = transport::load_public_key(supervisor->server_key);
      }
      sup = std::make_unique<zmq::socket_t>(
          transport::make_command_client(ctx, supervisor->endpoint, sec, timeout));
      sup->set(zmq::sockopt::linger, kSupervisorLingerMs);
    } catch (const std::exception& e) {
      result.supervisor_error = e.what();
    }
  }

  v1::NodeCommand estop;
  estop.set_kind(v1::NodeCommand::ESTOP);
  const std::string estop_bytes = estop.SerializeAsString();
  const auto sent_at = Clock::now();
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  result.sent_monotonic_ns = static_cast<long long>(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec;
  for (std::size_t i = 0; i < sockets.size(); ++i) {
    if (!sockets[i]) continue;
    try {
      // A connecting socket queues the request; it leaves as soon as the link is up.
      if (!sockets[i]->send(zmq::buffer(estop_bytes), zmq::send_flags::dontwait)) {
        result.nodes[i].error = "could not queue the request";
        sockets[i].reset();
      }
    } catch (const zmq::error_t& e) {
      result.nodes[i].error = e.what();
      sockets[i].reset();
    }
  }
  if (sup) {
    v1::SupervisorRequest req;
    req.mutable_node_command()->set_kind(v1::NodeCommand::ESTOP);
    req.mutable_node_command()->set_target("both");
    req.mutable_node_command()->set_requested_by(requested_by);
    const std::string bytes = req.SerializeAsString();
    try {
      result.supervisor_asked =
          sup->send(zmq::buffer(bytes), zmq::send_flags::dontwait).has_value();
    } catch (const zmq::error_t& e) {
      result.supervisor_error = e.what();
    }
    if (!result.supervisor_asked) sup.reset();
  }

  // The replies, together, until every node has answered (directly, or to the supervisor's
  // forwarded e-stop when its reply comes first) or the timeout passed.
  const auto deadline = sent_at + timeout;
  auto through_supervisor = [&](const std::string& name) -> const v1::NodeCommandOutcome* {
    if (!result.supervisor) return nullptr;
    for (const v1::NodeCommandOutcome& o : result.supervisor->node_command().outcomes()) {
      if (o.node() == name && o.replied()) return &o;
    }
    return nullptr;
  };
  auto pending = [&] {
    for (std::size_t i = 0; i < sockets.size(); ++i) {
      if (sockets[i] && through_supervisor(result.nodes[i].name) == nullptr) return true;
    }
    return false;
  };
  while (pending()) {
    const auto now = Clock::now();
    if (now >= deadline) break;
    std::vector<zmq::pollitem_t> items;
    std::vector<int> owner;  // index into sockets, -1 the supervisor
    for (std::size_t i = 0; i < sockets.size(); ++i) {
      if (!sockets[i]) continue;
      items.push_back({sockets[i]->handle(), 0, ZMQ_POLLIN, 0});
      owner.push_back(static_cast<int>(i));
    }
    if (sup) {
      items.push_back({sup->handle(), 0, ZMQ_POLLIN, 0});
      owner.push_back(-1);
    }
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now);
    try {
      (void)zmq::poll(items.data(), items.size(), std::max(left, std::chrono::milliseconds(1)));
    } catch (const zmq::error_t&) {
      continue;
    }
    for (std::size_t k = 0; k < items.size(); ++k) {
      if ((items[k].revents & ZMQ_POLLIN) == 0) continue;
      zmq::socket_t& s = owner[k] < 0 ? *sup : *sockets[static_cast<std::size_t>(owner[k])];
      zmq::message_t msg;
      bool got = false;
      try {
        got = s.recv(msg, zmq::recv_flags::dontwait).has_value();
        // Only the first frame is the reply.
        zmq::message_t rest;
        while (got && msg.more() && s.recv(rest, zmq::recv_flags::dontwait)) {
        }
      } catch (const zmq::error_t&) {
      }
      if (!got) continue;
      if (owner[k] < 0) {
        v1::SupervisorReply r;
        if (r.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) result.supervisor = r;
        sup.reset();
        continue;
      }
      const auto i = static_cast<std::size_t>(owner[k]);
      v1::NodeCommandReply r;
      if (r.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
        result.nodes[i].reply = r;
        result.nodes[i].reply_ns =
            std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - sent_at).count();
      } else {
        result.nodes[i].error = "unreadable reply";
      }
      sockets[i].reset();
    }
  }
  for (EstopOutcome& o : result.nodes) {
    if (o.reply) continue;
    if (const v1::NodeCommandOutcome* via = through_supervisor(o.name)) {
      o.reply = via->reply();
      o.via_supervisor = true;
    }
  }
  return result;
}

}  // namespace teleop::ctl
