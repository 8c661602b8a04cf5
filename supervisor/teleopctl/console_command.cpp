#include "supervisor/teleopctl/console_command.hpp"

#include <curses.h>
#include <fmt/core.h>
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <optional>
#include <regex>
#include <tuple>
#include <utility>
#include <zmq.hpp>

#include "common/config/config_loader.hpp"
#include "common/config/node_loader.hpp"
#include "common/transport/zmq_security.hpp"
#include "common/transport/zmq_sockets.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/console_view.hpp"
#include "supervisor/teleopctl/estop_fanout.hpp"
#include "supervisor/teleopctl/local_launch.hpp"
#include "supervisor/teleopctl/node_command.hpp"
#include "supervisor/teleopctl/set_command.hpp"

namespace teleop::ctl {
namespace {

std::atomic<bool> g_interrupted{false};
extern "C" void on_console_signal(int) { g_interrupted = true; }

std::int64_t monotonic_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// The local wall clock: HH:MM:SS, and seconds since midnight with their fraction (so that an
// alarm's wall-clock second, now minus its age, does not flicker between redraws).
std::pair<std::string, double> wall_clock() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  const time_t now = ts.tv_sec;
  tm local{};
  localtime_r(&now, &local);
  char text[16];
  strftime(text, sizeof(text), "%H:%M:%S", &local);
  return {text, local.tm_hour * 3600.0 + local.tm_min * 60.0 + local.tm_sec +
                    static_cast<double>(ts.tv_nsec) * 1e-9};
}

struct ConsoleArgs {
  std::string config_path{};
  std::string report{"tcp://127.0.0.1:5566"};
  // --supervisor (the request endpoint), --key, --server-key, --timeout-ms: as for status/set.
  SupervisorClientFlags sup{};
  std::string control{"tcp://127.0.0.1:5568"};
  bool read_only{false};
  bool replay{false};
  double refresh_hz{10.0};
  bool report_set{false};
};

// Restores the terminal whatever happens.
struct Screen {
  Screen() {
    initscr();
    cbreak();
    noecho();
    keypad(stdscr, TRUE);
    nodelay(stdscr, TRUE);
    curs_set(0);
  }
  ~Screen() { endwin(); }
  Screen(const Screen&) = delete;
  Screen& operator=(const Screen&) = delete;
};

class Console {
 public:
  Console(ConsoleArgs args, NodeClientKeys master_keys, NodeClientKeys slave_keys,
          std::string master_command, std::string slave_command)
      : a_(std::move(args)),
        master_keys_(std::move(master_keys)),
        slave_keys_(std::move(slave_keys)),
        master_command_(std::move(master_command)),
        slave_command_(std::move(slave_command)) {
    view_.replay = a_.replay;
    view_.read_only = a_.read_only;
    view_.source = a_.report;
  }

  int run() {
    zmq::context_t ctx(1);
    zmq::socket_t sub(ctx, zmq::socket_type::sub);
    sub.set(zmq::sockopt::linger, 0);
    sub.set(zmq::sockopt::rcvhwm, 100);
    const transport::LinkSecurity sec = transport::client_security(a_.sup.key, a_.sup.server_key);
    (void)transport::apply_link_security(ctx, sub, a_.report, transport::LinkRole::kClient, sec);
    sub.set(zmq::sockopt::subscribe, "status");
    sub.connect(a_.report);
    if (!a_.replay) {
      // Whether this client may command (a read-only key may not).
      v1::SupervisorRequest req;
      req.mutable_status();
      if (const auto r = request(req, 2000); r && r->has_status()) {
        if (!r->status().client_may_command()) view_.read_only = true;
        accept(r->status());
      } else {
        say("the supervisor at " + a_.sup.endpoint + " did not answer; waiting for its summary");
      }
    }
    Screen screen;
    const auto min_interval_ns = static_cast<std::int64_t>(1e9 / a_.refresh_hz);
    std::int64_t last_draw = 0;
    bool dirty = true;
    while (!quit_ && !g_interrupted.load()) {
      // The terminal too: a key (the e-stop) is taken the moment it arrives.
      zmq::pollitem_t items[] = {{sub.handle(), 0, ZMQ_POLLIN, 0},
                                 {nullptr, STDIN_FILENO, ZMQ_POLLIN, 0}};
      try {
        (void)zmq::poll(items, 2, std::chrono::milliseconds(20));
      } catch (const zmq::error_t&) {
      }
      zmq::message_t topic;
      zmq::message_t body;
      while (sub.recv(topic, zmq::recv_flags::dontwait)) {
        if (!topic.more() || !sub.recv(body, zmq::recv_flags::dontwait)) continue;
        v1::SupervisorStatus s;
        if (s.ParseFromArray(body.data(), static_cast<int>(body.size()))) {
          accept(s);
          dirty = true;
        }
      }
      for (int ch = getch(); ch != ERR; ch = getch()) {
        on_key(ch);
        dirty = true;
      }
      const std::int64_t now = monotonic_ns();
      // Redraw at a bounded rate; at least once a second so the summary's age stays true.
      if ((dirty && now - last_draw >= min_interval_ns) || now - last_draw >= 1'000'000'000) {
        draw(now);
        last_draw = now;
        dirty = false;
      }
    }
    return kExitOk;
  }

 private:
  void accept(const v1::SupervisorStatus& s) {
    view_.status = s;
    received_ns_ = monotonic_ns();
    alarms_.merge(s);
    view_.alarm_history = alarms_.newest_first();
  }

  void say(std::string text) {
    view_.messages.push_back(std::move(text));
    if (view_.messages.size() > 20) view_.messages.erase(view_.messages.begin());
  }

  void draw(std::int64_t now) {
    view_.status_age_ns = view_.status ? now - received_ns_ : 0;
    std::tie(view_.clock, view_.clock_s) = wall_clock();
    int rows = 0;
    int cols = 0;
    getmaxyx(stdscr, rows, cols);
    const std::vector<std::string> lines = render_console(view_, rows, cols);
    erase();
    for (std::size_t i = 0; i < lines.size(); ++i) {
      mvaddnstr(static_cast<int>(i), 0, lines[i].c_str(), cols);
    }
    refresh();
  }

  // One request to the supervisor, bounded by `timeout_ms` (each request's own default) or by
  // --timeout-ms when given. (The e-stop does not come here: estop().)
  std::optional<v1::SupervisorReply> request(const v1::SupervisorRequest& req, int timeout_ms) {
    if (a_.sup.timeout_given) timeout_ms = a_.sup.timeout_ms;
    try {
      return supervisor_request(a_.sup.endpoint, req, timeout_ms, a_.sup.key, a_.sup.server_key);
    } catch (const std::exception& e) {
      say(std::string("request failed: ") + e.what());
      return std::nullopt;
    }
  }

  // --- keys ------------------------------------------------------------------------------
  static constexpr int kCtrlX = 24;

  void on_key(int ch) {
    // The e-stop is one key away in every state of a live console: x on the help screen and
    // while a change waits for y (either is left first), Ctrl-X while typing (where x is a
    // letter) and anywhere else.
    const bool live = !a_.replay;
    const bool typing = !typing_.empty() || prompting_;
    if (live && (ch == kCtrlX || (!typing && (ch == 'x' || ch == 'X')))) {
      if (typing) {
        typing_.clear();
        prompting_ = false;
        view_.prompt.clear();
        say("typing cancelled for the e-stop");
      }
      if (confirming_) say("change cancelled for the e-stop: nothing was applied");
      confirming_ = false;
      view_.help = false;
      estop();
      return;
    }
    if (view_.help) {
      view_.help = false;
      return;
    }
    if (typing) {
      on_prompt_key(ch);
      return;
    }
    if (confirming_) {
      confirming_ = false;
      if (ch == 'y' || ch == 'Y') {
        apply_change(false);
      } else {
        say("change cancelled: nothing was applied");
      }
      return;
    }
    if (ch == 'q' || ch == 'Q') {
      quit_ = true;
      return;
    }
    if (ch == '?') {
      view_.help = true;
      return;
    }
    if (ch == KEY_RESIZE) return;
    if (ch == 't') {  // the per-axis table of nodes with several axes (issue 18)
      view_.axes_table = !view_.axes_table;
      return;
    }
    if (a_.replay) {
      on_replay_key(ch);
      return;
    }
    const char* kinds = "aedcul";
    if (std::string(kinds).find(static_cast<char>(ch)) != std::string::npos || ch == 's' ||
        ch == 'r') {
      if (view_.read_only) {
        say("read-only console: it can watch and e-stop (x), nothing else");
        return;
      }
    }
    switch (ch) {
      case 'a':
        node_command(v1::NodeCommand::ARM);
        break;
      case 'e':
        node_command(v1::NodeCommand::ENGAGE);
        break;
      case 'd':
        node_command(v1::NodeCommand::DISENGAGE);
        break;
      case 'c':
        node_command(v1::NodeCommand::CLUTCH);
        break;
      case 'u':
        node_command(v1::NodeCommand::UNCLUTCH);
        break;
      case 'l':
        node_command(v1::NodeCommand::CLEAR);
        break;
      case 's':
        prompting_ = true;
        prompt_label_ = "set (PATH=VALUE ...)> ";
        update_prompt();
        break;
      case 'r':
        toggle_recording();
        break;
      default:
        break;
    }
  }

  void on_prompt_key(int ch) {
    if (ch == 27) {  // Esc
      typing_.clear();
      prompting_ = false;
      view_.prompt.clear();
      say("cancelled");
      return;
    }
    if (ch == '\n' || ch == '\r' || ch == KEY_ENTER) {
      const std::string line = typing_;
      typing_.clear();
      prompting_ = false;
      view_.prompt.clear();
      if (a_.replay) {
        replay_control("seek " + line);
      } else {
        predict(line);
      }
      return;
    }
    if (ch == KEY_BACKSPACE || ch == 127 || ch == 8) {
      if (!typing_.empty()) typing_.pop_back();
    } else if (ch >= 32 && ch < 127 && typing_.size() < 200) {
      typing_.push_back(static_cast<char>(ch));
    }
    update_prompt();
  }

  void update_prompt() { view_.prompt = prompt_label_ + typing_ + "_"; }

  // --- live commands ---------------------------------------------------------------------
  static std::string outcome_text(const v1::NodeCommandResult& r) {
    std::string text;
    for (const v1::NodeCommandOutcome& o : r.outcomes()) {
      if (!text.empty()) text += ", ";
      if (!o.replied()) {
        text += o.node() + " NO REPLY";
        continue;
      }
      text += o.node() + " " + v1::NodeMode_Name(o.reply().mode());
      if (!o.reply().ok()) text += " (refused: " + o.reply().message() + ")";
    }
    return text;
  }

  void node_command(v1::NodeCommand::Kind kind) {
    v1::SupervisorRequest req;
    req.mutable_node_command()->set_kind(kind);
    req.mutable_node_command()->set_target("both");
    req.mutable_node_command()->set_requested_by("console");
    const auto r = request(req, 3000);
    const std::string name = v1::NodeCommand::Kind_Name(kind);
    if (!r) {
      say(name + ": NO REPLY from the supervisor at " + a_.sup.endpoint);
    } else if (!r->error().empty()) {
      say(name + ": " + r->error());
    } else {
      say(name + ": " + outcome_text(r->node_command()));
    }
  }

  // Straight to both nodes at once, the supervisor told in the same instant but never
  // waited for (estop_fanout.hpp); each node bounded by --timeout-ms or 500 ms.
  void estop() {
    const int timeout_ms = a_.sup.timeout_given ? a_.sup.timeout_ms : 500;
    const EstopResult r = estop_everywhere(
        {{"master", master_command_, master_keys_}, {"slave", slave_command_, slave_keys_}},
        SupervisorTarget{a_.sup.endpoint, a_.sup.server_key.empty() ? "" : a_.sup.key,
                         a_.sup.server_key},
        "console", timeout_ms);
    // Two lines of at most 80 columns: who answered, then the verdict with the send's instant
    // on this host's monotonic clock (the nodes' too, for their telemetry).
    say("E-STOP: sent to the nodes directly: " + r.nodes_text());
    if (!r.supervisor_error.empty()) say("E-STOP: supervisor not told: " + r.supervisor_error);
    say(fmt::format(
        "{} (sent at CLOCK_MONOTONIC {}.{:09d} s)",
        r.all_safe() ? "-- both nodes confirmed safe" : "-- NOT CONFIRMED: check the nodes",
        r.sent_monotonic_ns / 1'000'000'000LL, r.sent_monotonic_ns % 1'000'000'000LL));
  }

  void predict(const std::string& line) {
    settings_.clear();
    try {
      for (const std::string& word : split(line, ' ')) {
        if (!word.empty()) settings_.push_back(parse_setting(word));
      }
      if (settings_.empty()) throw UsageError("nothing to set");
    } catch (const std::exception& e) {
      say(std::string("set: ") + e.what());
      return;
    }
    pending_text_ = line;
    apply_change(true);
  }

  void apply_change(bool dry_run) {
    const v1::Gains gains = view_.status ? view_.status->report().gains() : v1::Gains{};
    v1::SupervisorRequest req;
    *req.mutable_change() = make_change_request(settings_, gains, dry_run, "console");
    const auto r = request(req, 5000);
    if (!r) {
      say("set " + pending_text_ + ": NO REPLY from the supervisor at " + a_.sup.endpoint);
      return;
    }
    if (!r->error().empty()) {
      say("set " + pending_text_ + ": " + r->error());
      return;
    }
    const v1::ParameterChangeReply& c = r->change();
    const v1::StabilityReport& p = c.prediction();
    std::string limits;
    if (p.has_max_stable_slave_stiffness_n_per_m()) {
      limits += fmt::format(", slave max {:.0f} N/m", p.max_stable_slave_stiffness_n_per_m());
    }
    if (p.has_max_stable_master_stiffness_n_per_m()) {
      limits += fmt::format(", master max {:.0f} N/m", p.max_stable_master_stiffness_n_per_m());
    }
    if (dry_run) {
      say(fmt::format("prediction for {}: {}, zeta min {:.4f} (required {:.4f}){}", pending_text_,
                      p.verdict(), p.min_damping_ratio(), p.required_damping_ratio(), limits));
      if (c.accepted()) {
        say("apply it? y applies (ramped by both nodes), any other key cancels");
        confirming_ = true;
      } else {
        say("REFUSED by the supervisor: " + strip_refused(c.reason()));
      }
      return;
    }
    if (c.accepted()) {
      say(fmt::format("APPLIED {}: change {} at master sequence {}", pending_text_, c.change_id(),
                      c.apply_at_master_sequence()));
    } else {
      say("REFUSED by the supervisor: " + strip_refused(c.reason()));
    }
  }

  static std::string strip_refused(const std::string& reason) {
    return reason.rfind("refused: ", 0) == 0 ? reason.substr(9) : reason;
  }

  void toggle_recording() {
    const bool recording = view_.status && !view_.status->recording_file().empty();
    v1::SupervisorRequest req;
    req.mutable_recording()->set_record(!recording);
    const auto r = request(req, 5000);
    if (!r) {
      say("recording: NO REPLY from the supervisor");
    } else if (!r->error().empty()) {
      say("recording: " + r->error());
    } else if (r->has_status()) {
      accept(r->status());
      say(r->status().recording_file().empty() ? "recording stopped"
                                               : "recording to " + r->status().recording_file());
    }
  }

  // --- replay ----------------------------------------------------------------------------
  void on_replay_key(int ch) {
    // Relative requests: the replay applies each to its own state, so keys pressed faster
    // than the summary comes back add up (two '[' are a quarter of the speed).
    switch (ch) {
      case ' ':
        replay_control("toggle");
        break;
      case ',':
      case KEY_LEFT:
        replay_control("seek -5");
        break;
      case '.':
      case KEY_RIGHT:
        replay_control("seek +5");
        break;
      case '<':
        replay_control("seek -30");
        break;
      case '>':
        replay_control("seek +30");
        break;
      case '[':
        replay_control("speed x0.5");
        break;
      case ']':
        replay_control("speed x2");
        break;
      case '0':
        replay_control("seek 0");
        break;
      case 'g':
        prompting_ = true;
        prompt_label_ = "go to (s)> ";
        update_prompt();
        break;
      default:
        break;
    }
  }

  void replay_control(const std::string& text) {
    try {
      zmq::context_t ctx(1);
      zmq::socket_t client =
          transport::make_command_client(ctx, a_.control, {}, std::chrono::milliseconds(1000));
      const auto reply = transport::request_reply(client, text);
      if (!reply) {
        say("replay: NO REPLY on " + a_.control);
        return;
      }
      // The reply is the replay's own state ("paused at 12.500000 s of 20.000000 s; speed 1;
      // ..."): taken at once, so that the next key (a second '[') starts from it rather than
      // from a summary that has not caught up yet, and said in short.
      std::smatch m;
      static const std::regex kState(R"(^(\w+) at ([0-9.]+) s of ([0-9.]+) s; speed ([^;]+);)");
      if (std::regex_search(*reply, m, kState) && view_.status) {
        v1::ReplayPosition* r = view_.status->mutable_replay();
        r->set_state(m[1]);
        r->set_position_s(std::stod(m[2]));
        r->set_speed(std::stod(m[4]));
        say(fmt::format("replay: {} at {:.1f} s of {:.1f} s, speed x{:g}", r->state(),
                        r->position_s(), std::stod(m[3]), r->speed()));
      } else {
        say("replay: " + *reply);
      }
    } catch (const std::exception& e) {
      say(std::string("replay: ") + e.what());
    }
  }

  ConsoleArgs a_;
  NodeClientKeys master_keys_;
  NodeClientKeys slave_keys_;
  std::string master_command_;
  std::string slave_command_;
  ConsoleView view_{};
  AlarmHistory alarms_{};
  std::int64_t received_ns_{0};
  bool quit_{false};
  bool prompting_{false};
  bool confirming_{false};
  std::string prompt_label_{};
  std::string typing_{};
  std::string pending_text_{};
  std::vector<std::pair<std::string, double>> settings_{};
};

// No key given and a configuration without keys (or none): a live `teleopctl launch` that
// serves this supervisor endpoint lends its configuration and console key.
void use_local_launch(ConsoleArgs& a) {
  if (!a.sup.key.empty() || a.replay) return;
  std::string endpoint = a.sup.endpoint;
  if (!a.config_path.empty()) {
    const config::LoadedConfig c = config::load_config_file(a.config_path);
    if (!config_has_no_keys(c.config)) return;
    if (!a.sup.endpoint_given && !c.config.supervisor().request_endpoint().empty()) {
      endpoint = c.config.supervisor().request_endpoint();
    }
  }
  if (const auto l = find_local_launch(endpoint)) {
    a.config_path = l->config_file.string();
    a.sup.key = l->console_key_file;
  }
}

}  // namespace

std::string console_usage() {
  return "usage: teleopctl console [CONFIG] [--supervisor HOST:PORT] [--report HOST:PORT]\n"
         "                         [--key FILE] [--server-key KEY|FILE] [--read-only]\n"
         "                         [--timeout-ms N] [--refresh-hz N]\n"
         "       teleopctl console --replay [--control HOST:PORT] [--report HOST:PORT]\n\n"
         "The operator's full-screen console (80x24 or larger, no colour needed). It draws from\n"
         "the supervisor's summary stream (topic \"status\" on its report endpoint, default\n"
         "127.0.0.1:5566, ten times a second; redrawn at most --refresh-hz, default 10) and\n"
         "sends commands through its request endpoint (default 127.0.0.1:5567): x e-stop (to\n"
         "both nodes directly at once, the supervisor told too), a arm, e engage, d disengage,\n"
         "c clutch, u unclutch, l clear, s set a gain or fixture stiffness (the supervisor's\n"
         "prediction first, y applies), r start/stop recording, ? help, q quit. With CONFIG\n"
         "the endpoints and keys come from it (supervisor section, security\n"
         ".supervisor_public_key); --key is this console's key file (teleopctl keygen), whose\n"
         "public key the supervisor must list in security.client_public_keys, or in\n"
         "security.read_only_client_public_keys for a console that may only watch and e-stop.\n"
         "--read-only makes this console read-only whatever its key. --timeout-ms bounds\n"
         "each request to the supervisor and an e-stop's wait for each node (default 500 ms).\n"
         "Without CONFIG keys or --key: the keys of a live `teleopctl launch` on these\n"
         "endpoints, if any.\n"
         "--replay watches `teleopctl replay FILE --speed X` (control default 127.0.0.1:5568):\n"
         "space pause/resume, , . seek 5 s, < > 30 s, [ ] speed, 0 start, g go to.\n"
         "Without a terminal use teleopctl status, set and estop.\n";
}

int run_console(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  (void)out;
  ConsoleArgs a;
  ArgCursor cur(args);
  while (cur.next()) {
    const std::string& arg = cur.arg();
    if (a.sup.take(cur)) continue;
    if (arg == "--report") {
      a.report = to_endpoint(cur.value("--report"));
      a.report_set = true;
    } else if (arg == "--control") {
      a.control = to_endpoint(cur.value("--control"));
    } else if (arg == "--read-only") {
      a.read_only = true;
    } else if (arg == "--replay") {
      a.replay = true;
    } else if (arg == "--refresh-hz") {
      a.refresh_hz = parse_number(cur.value("--refresh-hz"), "--refresh-hz");
      if (!(a.refresh_hz >= 1.0 && a.refresh_hz <= 30.0)) {
        throw UsageError("--refresh-hz must be in [1, 30]");
      }
    } else {
      take_only_positional(arg, a.config_path);
    }
  }
  return run_guarded("console", err, [&]() -> int {
    use_local_launch(a);
    std::string master_command = config::default_endpoints(transport::Role::kMaster).command;
    std::string slave_command = config::default_endpoints(transport::Role::kSlave).command;
    NodeClientKeys master_keys;
    NodeClientKeys slave_keys;
    if (!a.config_path.empty()) {
      const config::LoadedConfig c = config::load_config_file(a.config_path);
      const v1::Supervisor& s = c.config.supervisor();
      if (!a.report_set && !s.report_endpoint().empty()) a.report = s.report_endpoint();
      if (!a.sup.endpoint_given && !s.request_endpoint().empty()) {
        a.sup.endpoint = s.request_endpoint();
      }
      if (a.sup.server_key.empty()) {
        a.sup.server_key = c.config.security().supervisor_public_key();
      }
      master_command = config::to_node_setup(c, transport::Role::kMaster).endpoints.command;
      slave_command = config::to_node_setup(c, transport::Role::kSlave).endpoints.command;
      if (!a.sup.key.empty()) {
        master_keys = {a.sup.key, c.config.security().master_public_key()};
        slave_keys = {a.sup.key, c.config.security().slave_public_key()};
      }
    }
    if (isatty(STDIN_FILENO) == 0 || isatty(STDOUT_FILENO) == 0) {
      err << "teleopctl console: needs a terminal; without one use teleopctl status [--json], "
             "teleopctl set and teleopctl estop\n";
      return kExitError;
    }
    struct sigaction sa {};
    sa.sa_handler = on_console_signal;
    sigaction(SIGINT, &sa, nullptr);
    sigaction(SIGTERM, &sa, nullptr);
    Console console(a, master_keys, slave_keys, master_command, slave_command);
    return console.run();
  });
}

}  // namespace teleop::ctl
