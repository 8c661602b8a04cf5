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

namespace {

// estop_everywhere, step by step: the sockets, the requests, the replies.
class EstopFanout {
 public:
  explicit EstopFanout(std::chrono::milliseconds timeout) : timeout_(timeout) {}

  // One socket per node (and one for the supervisor), set up first so the sends go out
  // back to back. A target whose socket cannot be set up gets the error.
  void open(const std::vector<EstopTarget>& nodes,
            const std::optional<SupervisorTarget>& supervisor) {
    for (const EstopTarget& t : nodes) {
      EstopOutcome o;
      o.name = t.name;
      o.endpoint = t.endpoint;
      try {
        sockets_.push_back(std::make_unique<zmq::socket_t>(transport::make_command_client(
            ctx_, t.endpoint, transport::client_security(t.keys.secret_key_file, t.keys.server_key),
            timeout_)));
      } catch (const std::exception& e) {
        o.error = e.what();
        sockets_.push_back(nullptr);
      }
      result_.nodes.push_back(std::move(o));
    }
    if (!supervisor) return;
    try {
      sup_ = std::make_unique<zmq::socket_t>(transport::make_command_client(
          ctx_, supervisor->endpoint,
          transport::client_security(supervisor->key_file, supervisor->server_key), timeout_));
      sup_->set(zmq::sockopt::linger, kSupervisorLingerMs);
    } catch (const std::exception& e) {
      result_.supervisor_error = e.what();
    }
  }

  // ESTOP to every node, then the supervisor's node-command ESTOP; none waits.
  void send(const std::string& requested_by) {
    v1::NodeCommand estop;
    estop.set_kind(v1::NodeCommand::ESTOP);
    const std::string estop_bytes = estop.SerializeAsString();
    sent_at_ = Clock::now();
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    result_.sent_monotonic_ns = static_cast<long long>(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec;
    for (std::size_t i = 0; i < sockets_.size(); ++i) {
      if (!sockets_[i]) continue;
      try {
        // A connecting socket queues the request; it leaves as soon as the link is up.
        if (!sockets_[i]->send(zmq::buffer(estop_bytes), zmq::send_flags::dontwait)) {
          result_.nodes[i].error = "could not queue the request";
          sockets_[i].reset();
        }
      } catch (const zmq::error_t& e) {
        result_.nodes[i].error = e.what();
        sockets_[i].reset();
      }
    }
    if (sup_) send_to_supervisor(requested_by);
  }

  // The replies, together, until every node has answered (directly, or to the supervisor's
  // forwarded e-stop when its reply comes first) or the timeout passed.
  void await_replies() {
    const auto deadline = sent_at_ + timeout_;
    while (pending()) {
      const auto now = Clock::now();
      if (now >= deadline) break;
      std::vector<zmq::pollitem_t> items;
      std::vector<int> owner;  // index into sockets_, -1 the supervisor
      for (std::size_t i = 0; i < sockets_.size(); ++i) {
        if (!sockets_[i]) continue;
        items.push_back({sockets_[i]->handle(), 0, ZMQ_POLLIN, 0});
        owner.push_back(static_cast<int>(i));
      }
      if (sup_) {
        items.push_back({sup_->handle(), 0, ZMQ_POLLIN, 0});
        owner.push_back(-1);
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now);
      try {
        (void)zmq::poll(items.data(), items.size(), std::max(left, std::chrono::milliseconds(1)));
      } catch (const zmq::error_t&) {
        continue;
      }
      for (std::size_t k = 0; k < items.size(); ++k) {
        if ((items[k].revents & ZMQ_POLLIN) != 0) take_reply(owner[k]);
      }
    }
  }

  // A node that did not answer directly, but whose answer to the supervisor's forwarded
  // e-stop came with the supervisor's reply.
  void take_forwarded_replies() {
    for (EstopOutcome& o : result_.nodes) {
      if (o.reply) continue;
      if (const v1::NodeCommandOutcome* via = through_supervisor(o.name)) {
        o.reply = via->reply();
        o.via_supervisor = true;
      }
    }
  }

  EstopResult& result() { return result_; }

 private:
  void send_to_supervisor(const std::string& requested_by) {
    v1::SupervisorRequest req;
    req.mutable_node_command()->set_kind(v1::NodeCommand::ESTOP);
    req.mutable_node_command()->set_target("both");
    req.mutable_node_command()->set_requested_by(requested_by);
    const std::string bytes = req.SerializeAsString();
    try {
      result_.supervisor_asked =
          sup_->send(zmq::buffer(bytes), zmq::send_flags::dontwait).has_value();
    } catch (const zmq::error_t& e) {
      result_.supervisor_error = e.what();
    }
    if (!result_.supervisor_asked) sup_.reset();
  }

  [[nodiscard]] const v1::NodeCommandOutcome* through_supervisor(const std::string& name) const {
    if (!result_.supervisor) return nullptr;
    for (const v1::NodeCommandOutcome& o : result_.supervisor->node_command().outcomes()) {
      if (o.node() == name && o.replied()) return &o;
    }
    return nullptr;
  }

  [[nodiscard]] bool pending() const {
    for (std::size_t i = 0; i < sockets_.size(); ++i) {
      if (sockets_[i] && through_supervisor(result_.nodes[i].name) == nullptr) return true;
    }
    return false;
  }

  // The reply waiting on node socket `owner` (-1: the supervisor's); that socket is done.
  void take_reply(int owner) {
    zmq::socket_t& s = owner < 0 ? *sup_ : *sockets_[static_cast<std::size_t>(owner)];
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
    if (!got) return;
    if (owner < 0) {
      v1::SupervisorReply r;
      if (r.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) result_.supervisor = r;
      sup_.reset();
      return;
    }
    const auto i = static_cast<std::size_t>(owner);
    v1::NodeCommandReply r;
    if (r.ParseFromArray(msg.data(), static_cast<int>(msg.size()))) {
      result_.nodes[i].reply = r;
      result_.nodes[i].reply_ns =
          std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - sent_at_).count();
    } else {
      result_.nodes[i].error = "unreadable reply";
    }
    sockets_[i].reset();
  }

  zmq::context_t ctx_{1};
  std::chrono::milliseconds timeout_;
  EstopResult result_{};
  std::vector<std::unique_ptr<zmq::socket_t>> sockets_{};
  std::unique_ptr<zmq::socket_t> sup_{};
  Clock::time_point sent_at_{};
};

}  // namespace

EstopResult estop_everywhere(const std::vector<EstopTarget>& nodes,
                             const std::optional<SupervisorTarget>& supervisor,
                             const std::string& requested_by, int timeout_ms) {
  EstopFanout fanout{std::chrono::milliseconds(timeout_ms)};
  fanout.open(nodes, supervisor);
  fanout.send(requested_by);
  fanout.await_replies();
  fanout.take_forwarded_replies();
  return std::move(fanout.result());
}

}  // namespace teleop::ctl
