#include "supervisor/teleopctl/replay_live.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <ostream>
#include <stdexcept>
#include <string_view>
#include <zmq.hpp>

#include "common/config/node_loader.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/replay_supervision.hpp"
#include "teleop/v1/supervisor.pb.h"

namespace teleop::ctl {
namespace {

[[nodiscard]] double seconds_since(std::uint64_t t, std::uint64_t t0) {
  return t >= t0 ? static_cast<double>(t - t0) * 1e-9 : -static_cast<double>(t0 - t) * 1e-9;
}

// The flag's endpoint, else the configured one, else the default.
[[nodiscard]] std::string endpoint(const std::optional<std::string>& flag,
                                   const std::string& configured, std::string_view fallback) {
  if (flag) return *flag;
  return configured.empty() ? std::string(fallback) : configured;
}

class LiveReplay {
 public:
  LiveReplay(const record::SessionReader& session, const LiveReplayOptions& o, std::ostream& err)
      : o_(o),
        cfg_(record::recorded_config(session, o.overrides)),
        sc_(cfg_ ? cfg_->config : v1::SystemConfig{}),
        master_ep_(endpoint(o.master_endpoint, sc_.master().node().telemetry_endpoint(),
                            config::default_endpoints(transport::Role::kMaster).telemetry)),
        slave_ep_(endpoint(o.slave_endpoint, sc_.slave().node().telemetry_endpoint(),
                           config::default_endpoints(transport::Role::kSlave).telemetry)),
        report_ep_(endpoint(o.report_endpoint, sc_.supervisor().report_endpoint(),
                            defaults::kSupervisorReportEndpoint)),
        items_(live_items(session)),
        t0_(session.first_log_time_ns()),
        duration_s_(seconds_since(session.last_log_time_ns(), t0_)),
        summary_(cfg_, summary_items(session), err),
        security_(plaintext_security(sc_)),
        pubs_{publisher(master_ep_), publisher(slave_ep_), publisher(report_ep_)},
        control_(command_server()),
        playing_(!o.start_paused),
        speed_(o.speed) {}

  int run(std::ostream& out);

 private:
  using Clock = std::chrono::steady_clock;
  static constexpr std::chrono::milliseconds kSummaryPeriod{100};

  struct Item {
    int kind{0};  // 0 master telemetry, 1 slave telemetry, 2 report, 3 alarm
    std::uint64_t log_time_ns{0};
    std::string_view data{};
  };

  [[nodiscard]] static std::vector<Item> live_items(const record::SessionReader& session);
  // Plaintext (the replay holds no node's keys); off loopback only with security.insecure.
  [[nodiscard]] static transport::LinkSecurity plaintext_security(const v1::SystemConfig& sc);
  [[nodiscard]] zmq::socket_t publisher(const std::string& ep);
  [[nodiscard]] zmq::socket_t command_server();

  [[nodiscard]] double pos_of(std::size_t i) const {
    return seconds_since(items_[i].log_time_ns, t0_);
  }
  [[nodiscard]] double position() const;
  void send_until(double p);
  [[nodiscard]] std::string status(const char* state, double p) const;
  [[nodiscard]] const char* state_name() const {
    return next_ >= items_.size() ? "finished" : playing_ ? "playing" : "paused";
  }
  void publish_summary();
  // Until the next message or summary is due (at most 100 ms).
  [[nodiscard]] long timeout_ms() const;
  void count_subscriptions();
  void serve_request();
  [[nodiscard]] std::string answer(const std::string& request,
                                   const std::vector<std::string>& words, double p);

  const LiveReplayOptions& o_;
  const std::optional<config::LoadedConfig> cfg_;
  const v1::SystemConfig sc_;
  const std::string master_ep_;
  const std::string slave_ep_;
  const std::string report_ep_;
  const std::vector<Item> items_;
  const std::uint64_t t0_;
  const double duration_s_;
  ReplaySummary summary_;
  const transport::LinkSecurity security_;
  zmq::context_t ctx_{1};
  std::array<zmq::socket_t, 3> pubs_;
  zmq::socket_t control_;

  bool playing_;
  bool stopped_{false};
  double speed_;
  double anchor_pos_{0.0};
  Clock::time_point anchor_wall_{Clock::now()};
  std::size_t next_{0};
  std::array<std::uint64_t, 4> sent_{};
  std::array<std::uint64_t, 3> subscriptions_{};
  Clock::time_point next_summary_{Clock::now()};
};

std::vector<LiveReplay::Item> LiveReplay::live_items(const record::SessionReader& session) {
  namespace topic = record::topic;
  std::vector<Item> items;
  session.mcap().for_each_message(record::Order::kLogTime, [&](const record::MessageView& m) {
    const std::string& t = m.channel->topic;
    const int kind = t == topic::kMasterTelemetry  ? 0
                     : t == topic::kSlaveTelemetry ? 1
                     : t == topic::kStability      ? 2
                     : t == topic::kAlarms         ? 3
                                                   : -1;
    if (kind >= 0) items.push_back({kind, m.log_time_ns, m.data});
  });
  return items;
}

transport::LinkSecurity LiveReplay::plaintext_security(const v1::SystemConfig& sc) {
  transport::LinkSecurity security;
  security.insecure = sc.security().insecure();
  return security;
}

zmq::socket_t LiveReplay::publisher(const std::string& ep) {
  // XPUB: a PUB that also sees its subscriptions, so "status" can say who listens.
  zmq::socket_t s(ctx_, zmq::socket_type::xpub);
  s.set(zmq::sockopt::linger, 0);
  s.set(zmq::sockopt::sndhwm, 100000);
  s.set(zmq::sockopt::xpub_verbose, 1);
  // Its only inbound traffic is the handshake and subscriptions (see zmq_sockets.hpp).
  s.set(zmq::sockopt::maxmsgsize, transport::kMaxPublisherInboundBytes);
  (void)transport::apply_link_security(ctx_, s, ep, transport::LinkRole::kServer, security_);
  try {
    s.bind(ep);
  } catch (const zmq::error_t& e) {
    throw std::runtime_error(fmt::format("{}: cannot bind: {}", ep, e.what()));
  }
  return s;
}

zmq::socket_t LiveReplay::command_server() {
  try {
    return transport::make_command_server(ctx_, o_.control, security_);
  } catch (const zmq::error_t& e) {
    throw std::runtime_error(fmt::format("--control {}: cannot bind: {}", o_.control, e.what()));
  }
}

double LiveReplay::position() const {
  const double p =
      playing_ ? anchor_pos_ +
                     std::chrono::duration<double>(Clock::now() - anchor_wall_).count() * speed_
               : anchor_pos_;
  return std::min(p, duration_s_);
}

void LiveReplay::send_until(double p) {
  while (next_ < items_.size() && pos_of(next_) <= p) {
    const Item& it = items_[next_];
    if (it.kind <= 1) {
      (void)pubs_[static_cast<std::size_t>(it.kind)].send(
          zmq::buffer(it.data.data(), it.data.size()), zmq::send_flags::dontwait);
    } else {
      const char* tag = it.kind == 2 ? "report" : "alarm";
      (void)pubs_[2].send(zmq::buffer(std::string_view(tag)),
                          zmq::send_flags::sndmore | zmq::send_flags::dontwait);
      (void)pubs_[2].send(zmq::buffer(it.data.data(), it.data.size()), zmq::send_flags::dontwait);
    }
    ++sent_[static_cast<std::size_t>(it.kind)];
    ++next_;
  }
}

std::string LiveReplay::status(const char* state, double p) const {
  return fmt::format(
      "{} at {:.6f} s of {:.6f} s; speed {:g}; sent {} messages, the file has {}: "
      "master={} slave={} report={} alarm={}; subscriptions: master={} slave={} report={}",
      state, p, duration_s_, speed_, sent_[0] + sent_[1] + sent_[2] + sent_[3], items_.size(),
      sent_[0], sent_[1], sent_[2], sent_[3], subscriptions_[0], subscriptions_[1],
      subscriptions_[2]);
}

// The summary stream (as teleop-supervisor's, topic "status" on the report endpoint), every
// 100 ms of wall time whether playing, paused or finished and held.
void LiveReplay::publish_summary() {
  const double p = position();
  summary_.advance_to(t0_ + static_cast<std::uint64_t>(std::llround(std::max(0.0, p) * 1e9)));
  v1::SupervisorStatus st = summary_.status();
  v1::ReplayPosition* r = st.mutable_replay();
  r->set_file(o_.file);
  r->set_state(state_name());
  r->set_position_s(p);
  r->set_duration_s(duration_s_);
  r->set_speed(speed_);
  r->set_control_endpoint(o_.control);
  const std::string bytes = st.SerializeAsString();
  (void)pubs_[2].send(zmq::str_buffer("status"),
                      zmq::send_flags::sndmore | zmq::send_flags::dontwait);
  (void)pubs_[2].send(zmq::buffer(bytes), zmq::send_flags::dontwait);
}

long LiveReplay::timeout_ms() const {
  const auto to_summary =
      std::chrono::ceil<std::chrono::milliseconds>(next_summary_ - Clock::now()).count();
  long timeout = std::clamp(static_cast<long>(to_summary), 0L, 100L);
  if (playing_ && next_ < items_.size()) {
    const double wait_s = (pos_of(next_) - position()) / speed_;
    timeout = std::clamp(static_cast<long>(std::ceil(wait_s * 1e3)), 0L, timeout);
  }
  return timeout;
}

void LiveReplay::count_subscriptions() {
  zmq::message_t msg;
  for (std::size_t i = 0; i < pubs_.size(); ++i) {
    while (transport::receive_whole(pubs_[i], msg).parts > 0) {
      if (msg.size() > 0 && static_cast<const unsigned char*>(msg.data())[0] == 1) {
        ++subscriptions_[i];
      }
    }
  }
}

// The whole request (every part), so the control socket can always answer: a multi-part one is
// refused (issue 14 finding 4's sibling).
void LiveReplay::serve_request() {
  zmq::message_t msg;
  const transport::Received got = transport::receive_whole(control_, msg);
  if (got.parts == 0) return;
  if (got.parts != 1) {
    (void)transport::send_noexcept(
        control_,
        fmt::format("error: malformed request: {} parts (a request is one frame)", got.parts));
    return;
  }
  const std::string request = msg.to_string();
  // Everything due up to now goes out first, so the reply's position and counts agree.
  const double p = position();
  if (playing_) send_until(p);
  const std::vector<std::string> words = split(request, ' ');
  std::string reply;
  try {
    reply = answer(request, words, p);
  } catch (const std::exception& e) {
    reply = fmt::format("error: {}", e.what());
  }
  (void)transport::send_noexcept(control_, reply);
  // A console sees a pause, seek or change of speed at once, not up to 100 ms later.
  if (words.front() != "status") next_summary_ = Clock::now();
}

std::string LiveReplay::answer(const std::string& request, const std::vector<std::string>& words,
                               double p) {
  const std::string& verb = words.front();
  if (verb == "pause" && words.size() == 1) {
    anchor_pos_ = p;
    playing_ = false;
    return status(next_ < items_.size() ? "paused" : "finished", p);
  }
  if (verb == "resume" && words.size() == 1) {
    anchor_pos_ = p;
    anchor_wall_ = Clock::now();
    playing_ = next_ < items_.size();
    return status(state_name(), p);
  }
  if (verb == "toggle" && words.size() == 1) {
    // Pause when playing, resume when paused: a console's key that never acts on a state it
    // has not seen yet.
    anchor_pos_ = p;
    anchor_wall_ = Clock::now();
    playing_ = !playing_ && next_ < items_.size();
    return status(state_name(), p);
  }
  if (verb == "seek" && words.size() == 2 && !words[1].empty()) {
    // "seek 12.5" goes to 12.5 s; "seek +5" / "seek -5" moves from where the replay is
    // (clamped to the file), so that keys pressed quickly add up.
    const bool relative = words[1].front() == '+' || words[1].front() == '-';
    // (from_chars takes no '+')
    double s = parse_number(words[1].front() == '+' ? words[1].substr(1) : words[1], "seek");
    if (relative) s = std::max(0.0, p + s);
    if (s < 0.0) throw UsageError("seek: a position from 0 s on (+S/-S: relative)");
    anchor_pos_ = std::min(s, duration_s_);
    anchor_wall_ = Clock::now();
    next_ = 0;
    while (next_ < items_.size() && pos_of(next_) < anchor_pos_) ++next_;
    return status(state_name(), anchor_pos_);
  }
  if (verb == "speed" && words.size() == 2 && !words[1].empty()) {
    // "speed 2" plays at 2x; "speed x2" / "speed x0.5" multiplies the speed in force.
    const bool factor = words[1].front() == 'x';
    double x = parse_number(factor ? words[1].substr(1) : words[1], "speed");
    if (factor) x *= speed_;
    if (!(x > 0.0) || !std::isfinite(x)) throw UsageError("speed: must be positive");
    anchor_pos_ = p;
    anchor_wall_ = Clock::now();
    speed_ = x;
    return status(state_name(), p);
  }
  if (verb == "status" && words.size() == 1) return status(state_name(), p);
  if (verb == "stop" && words.size() == 1) {
    stopped_ = true;
    return status("stopped", p);
  }
  return fmt::format(
      "error: unknown request '{}' (pause, resume, toggle, seek SECONDS|+S|-S, "
      "speed X|xF, status, stop)",
      request);
}

int LiveReplay::run(std::ostream& out) {
  out << fmt::format(
             "replaying {} ({} messages, {:.3f} s) at speed {:g}: master telemetry on {}, slave "
             "telemetry on {}, reports and alarms on {}; control on {}{}\n",
             o_.file, items_.size(), duration_s_, speed_, master_ep_, slave_ep_, report_ep_,
             o_.control, playing_ ? "" : " (paused: send 'resume')")
      << std::flush;

  while (!stopped_) {
    if (playing_) {
      send_until(position());
      if (next_ >= items_.size()) {
        anchor_pos_ = duration_s_;
        playing_ = false;
        if (!o_.hold) break;
      }
    }
    if (Clock::now() >= next_summary_) {
      publish_summary();
      next_summary_ = std::max(next_summary_ + kSummaryPeriod, Clock::now());
    }
    // Sleep until the next message or summary is due or a request or subscription arrives.
    std::array<zmq::pollitem_t, 4> poll_items{{{control_.handle(), 0, ZMQ_POLLIN, 0},
                                               {pubs_[0].handle(), 0, ZMQ_POLLIN, 0},
                                               {pubs_[1].handle(), 0, ZMQ_POLLIN, 0},
                                               {pubs_[2].handle(), 0, ZMQ_POLLIN, 0}}};
    try {
      (void)zmq::poll(poll_items.data(), poll_items.size(),
                      std::chrono::milliseconds(timeout_ms()));
    } catch (const zmq::error_t& e) {
      if (e.num() == EINTR) continue;
      throw;
    }
    count_subscriptions();
    serve_request();
  }
  out << status(stopped_ ? "stopped" : "finished", position()) << "\n";
  return kExitOk;
}

}  // namespace

int replay_live(const record::SessionReader& session, const LiveReplayOptions& options,
                std::ostream& out, std::ostream& err) {
  LiveReplay replay(session, options, err);
  return replay.run(out);
}

}  // namespace teleop::ctl
