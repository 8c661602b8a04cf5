#include "supervisor/teleopctl/relay_command.hpp"

#include <fmt/core.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <map>
#include <optional>
#include <zmq.hpp>

#include "common/transport/zmq_sockets.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/node_command.hpp"

namespace teleop::ctl {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_relay_signal(int) { g_stop = true; }

double probability(const std::string& text, const char* flag) {
  const double p = parse_number(text, flag);
  if (!(p >= 0.0 && p <= 1.0)) throw UsageError(fmt::format("{} must be in [0, 1]", flag));
  return p;
}

double non_negative(const std::string& text, const char* flag) {
  const double v = parse_number(text, flag);
  if (!(v >= 0.0)) throw UsageError(fmt::format("{} must be >= 0", flag));
  return v;
}

using Clock = std::chrono::steady_clock;
using Frames = std::vector<zmq::message_t>;

}  // namespace

RelayPlanner::RelayPlanner(const RelayFaults& faults) : f_(faults), rng_(faults.seed) {}

RelayPlan RelayPlanner::plan(double since_first_s) {
  ++received;
  RelayPlan p;
  std::uniform_real_distribution<double> u(0.0, 1.0);
  // Every draw is made for every message, so one fault's setting does not shift another's
  // sequence of decisions.
  const double r_drop = u(rng_);
  const double r_dup = u(rng_);
  const double r_reorder = u(rng_);
  const double r_jitter = u(rng_);
  const double r_jitter2 = u(rng_);
  if (f_.blackout_at_s >= 0.0 && since_first_s >= f_.blackout_at_s &&
      since_first_s < f_.blackout_at_s + f_.blackout_ms * 1e-3) {
    ++blacked_out;
    return p;
  }
  if (r_drop < f_.drop) {
    ++dropped;
    return p;
  }
  auto delay = [&](double r) {
    return std::max(0.0, f_.delay_ms + (2.0 * r - 1.0) * f_.jitter_ms);
  };
  p.delays_ms.push_back(delay(r_jitter));
  if (f_.in_order) {
    const double at_ms = since_first_s * 1e3;
    p.delays_ms.front() = std::max(p.delays_ms.front(), last_send_ms_ - at_ms);
    last_send_ms_ = at_ms + p.delays_ms.front();
  }
  if (r_dup < f_.duplicate) {
    ++duplicated;
    p.delays_ms.push_back(std::max(p.delays_ms.front(), delay(r_jitter2)) + 0.05);
  }
  if (r_reorder < f_.reorder) {
    ++reordered;
    p.hold = true;
  }
  return p;
}

std::string relay_usage() {
  return "usage: teleopctl relay --from ENDPOINT --to ENDPOINT [--delay-ms D] [--jitter-ms J]\n"
         "                      [--drop P] [--duplicate P] [--reorder P]\n"
         "                      [--blackout-at-s T --blackout-ms M] [--in-order] [--seed S]\n\n"
         "The project's fault-injecting relay for one direction of a node link: subscribes to\n"
         "the NodeState publisher at --from, re-publishes every message on --to (bound) after\n"
         "D ms (plus uniform jitter in [-J, J]; with --in-order never before the message\n"
         "before it, as on one TCP connection), dropping with probability P, sending a second\n"
         "copy with probability P, holding one back until after the next with probability P,\n"
         "and dropping everything for M ms from T s after the first message. Decisions are\n"
         "seeded (--seed, default 1). Point the peer's node.peer_state_endpoint at --to; one\n"
         "relay per direction. Plaintext links only (frames are forwarded as they are). Prints\n"
         "its counts once a second and at the end; stops on SIGINT/SIGTERM.\n";
}

namespace {

struct RelayArgs {
  std::string from;
  std::string to;
  RelayFaults faults;
};

RelayArgs parse_relay_args(const std::vector<std::string>& args) {
  RelayArgs r;
  RelayFaults& f = r.faults;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& a = cur.arg();
    if (a == "--from") {
      r.from = to_endpoint(cur.value("--from"));
    } else if (a == "--to") {
      r.to = to_endpoint(cur.value("--to"));
    } else if (a == "--delay-ms") {
      f.delay_ms = non_negative(cur.value("--delay-ms"), "--delay-ms");
    } else if (a == "--jitter-ms") {
      f.jitter_ms = non_negative(cur.value("--jitter-ms"), "--jitter-ms");
    } else if (a == "--in-order") {
      f.in_order = true;
    } else if (a == "--drop") {
      f.drop = probability(cur.value("--drop"), "--drop");
    } else if (a == "--duplicate") {
      f.duplicate = probability(cur.value("--duplicate"), "--duplicate");
    } else if (a == "--reorder") {
      f.reorder = probability(cur.value("--reorder"), "--reorder");
    } else if (a == "--blackout-at-s") {
      f.blackout_at_s = non_negative(cur.value("--blackout-at-s"), "--blackout-at-s");
    } else if (a == "--blackout-ms") {
      f.blackout_ms = non_negative(cur.value("--blackout-ms"), "--blackout-ms");
    } else if (a == "--seed") {
      f.seed = static_cast<std::uint64_t>(non_negative(cur.value("--seed"), "--seed"));
    } else {
      throw UsageError("unknown argument '" + a + "'");
    }
  }
  if (r.from.empty() || r.to.empty()) throw UsageError("--from and --to are required");
  if (f.blackout_ms > 0.0 && f.blackout_at_s < 0.0) {
    throw UsageError("--blackout-ms goes with --blackout-at-s");
  }
  return r;
}

zmq::socket_t connect_subscriber(zmq::context_t& ctx, const std::string& from) {
  zmq::socket_t sub(ctx, zmq::socket_type::sub);
  sub.set(zmq::sockopt::linger, 0);
  sub.set(zmq::sockopt::rcvhwm, 100000);
  sub.set(zmq::sockopt::maxmsgsize, std::int64_t{16} << 20);
  sub.set(zmq::sockopt::reconnect_ivl, 10);
  sub.set(zmq::sockopt::subscribe, "");
  sub.connect(from);
  return sub;
}

zmq::socket_t bind_publisher(zmq::context_t& ctx, const std::string& to) {
  zmq::socket_t pub(ctx, zmq::socket_type::pub);
  pub.set(zmq::sockopt::linger, 0);
  pub.set(zmq::sockopt::sndhwm, 100000);
  // Its only inbound traffic is the handshake and subscriptions (see zmq_sockets.hpp).
  pub.set(zmq::sockopt::maxmsgsize, transport::kMaxPublisherInboundBytes);
  try {
    pub.bind(to);
  } catch (const zmq::error_t& e) {
    throw std::runtime_error(fmt::format("--to {}: cannot bind: {}", to, e.what()));
  }
  return pub;
}

// The relayed messages between their arrival and their release, as the planner decides.
class RelayQueue {
 public:
  explicit RelayQueue(const RelayFaults& faults) : planner_(faults) {}

  // Sends every message whose release time has come.
  void send_due(zmq::socket_t& pub, Clock::time_point now) {
    while (!queue_.empty() && queue_.begin()->first <= now) {
      const Frames& frames = *queue_.begin()->second;
      for (std::size_t i = 0; i < frames.size(); ++i) {
        zmq::message_t copy;
        copy.copy(const_cast<zmq::message_t&>(frames[i]));
        (void)pub.send(
            copy, i + 1 < frames.size() ? zmq::send_flags::sndmore : zmq::send_flags::dontwait);
      }
      ++sent_;
      queue_.erase(queue_.begin());
    }
  }

  // A held message that no next one came for within 50 ms goes out as planned.
  void release_stale_hold(Clock::time_point now) {
    if (held_ && now - held_times_.front() > std::chrono::milliseconds(50)) {
      for (const auto& t : held_times_) queue_.emplace(t, held_);
      held_.reset();
    }
  }

  // How long to wait for input: 1 ms, or none when a release is due within it.
  [[nodiscard]] std::chrono::milliseconds poll_timeout(Clock::time_point now) const {
    long timeout_us = 1000;
    if (!queue_.empty()) {
      timeout_us = std::clamp<long>(
          static_cast<long>(
              std::chrono::duration_cast<std::chrono::microseconds>(queue_.begin()->first - now)
                  .count()),
          0L, 1000L);
    }
    return std::chrono::milliseconds(timeout_us >= 1000 ? 1 : 0);
  }

  // Takes every message waiting on `sub` (all its frames) and queues it as planned.
  void receive(zmq::socket_t& sub) {
    zmq::message_t part;
    while (sub.recv(part, zmq::recv_flags::dontwait)) {
      auto frames = std::make_shared<Frames>();
      frames->push_back(std::move(part));
      while (frames->back().more()) {
        zmq::message_t next;
        if (!sub.recv(next, zmq::recv_flags::none)) break;
        frames->push_back(std::move(next));
      }
      take(std::move(frames), Clock::now());
    }
  }

  [[nodiscard]] std::string counts() const {
    return fmt::format(
        "relay: received {} sent {} dropped {} blacked out {} duplicated {} reordered {} "
        "queued {}\n",
        planner_.received, sent_, planner_.dropped, planner_.blacked_out, planner_.duplicated,
        planner_.reordered, queue_.size());
  }

 private:
  void take(std::shared_ptr<Frames> frames, Clock::time_point at) {
    if (!first_) first_ = at;
    const RelayPlan plan = planner_.plan(std::chrono::duration<double>(at - *first_).count());
    std::vector<Clock::time_point> times;
    for (const double d : plan.delays_ms) {
      times.push_back(at + std::chrono::duration_cast<Clock::duration>(
                               std::chrono::duration<double, std::milli>(d)));
    }
    if (times.empty()) return;
    // A held message goes out just after this one.
    if (held_) {
      const Clock::time_point after = times.front() + std::chrono::microseconds(10);
      for (const auto& t : held_times_) queue_.emplace(std::max(t, after), held_);
      held_.reset();
    }
    if (plan.hold) {
      held_ = std::move(frames);
      held_times_ = times;
    } else {
      for (const auto& t : times) queue_.emplace(t, frames);
    }
  }

  RelayPlanner planner_;
  // Messages waiting for their release time (several copies of one share its frames).
  std::multimap<Clock::time_point, std::shared_ptr<Frames>> queue_{};
  // A message held back until after the next one (null: none).
  std::shared_ptr<Frames> held_{};
  std::vector<Clock::time_point> held_times_{};
  std::optional<Clock::time_point> first_{};
  std::uint64_t sent_{0};
};

}  // namespace

int run_relay(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  const RelayArgs r = parse_relay_args(args);
  const RelayFaults& f = r.faults;
  return run_guarded("relay", err, [&]() -> int {
    zmq::context_t ctx(1);
    zmq::socket_t sub = connect_subscriber(ctx, r.from);
    zmq::socket_t pub = bind_publisher(ctx, r.to);
    struct sigaction sa {};
    sa.sa_handler = on_relay_signal;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    out << fmt::format(
               "relaying {} -> {}: delay {} ms, jitter {} ms, drop {}, duplicate {}, reorder {}, "
               "seed {}\n",
               r.from, r.to, f.delay_ms, f.jitter_ms, f.drop, f.duplicate, f.reorder, f.seed)
        << std::flush;
    RelayQueue queue(f);
    Clock::time_point next_report = Clock::now() + std::chrono::seconds(1);
    while (!g_stop.load()) {
      const Clock::time_point now = Clock::now();
      queue.send_due(pub, now);
      if (now >= next_report) {
        out << queue.counts() << std::flush;
        next_report += std::chrono::seconds(1);
      }
      queue.release_stale_hold(now);
      zmq::pollitem_t item{sub.handle(), 0, ZMQ_POLLIN, 0};
      try {
        (void)zmq::poll(&item, 1, queue.poll_timeout(now));
      } catch (const zmq::error_t&) {
        continue;
      }
      queue.receive(sub);
    }
    out << queue.counts() << std::flush;
    return kExitOk;
  });
}

}  // namespace teleop::ctl
