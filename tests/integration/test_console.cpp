// The operator console `teleopctl console` (issue 6) in a real terminal: tmux on a private
// server socket runs it at 80x24 against the real master, slave and supervisor processes on
// free loopback ports (or against `teleopctl replay --speed 1`), keys go in with send-keys
// and the screen comes back with capture-pane. Every check of the screen polls it until the
// condition holds, bounded only against a hang; what the console claims is checked against
// the nodes' own telemetry and against `teleopctl analyze`, an independent path.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>

#include "common/record/session.hpp"
#include "common/record/session_recorder.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"
#include "tests/integration/cli_harness.hpp"
#include "tests/integration/node_harness.hpp"

namespace teleop::test {
namespace {

namespace fs = std::filesystem;

constexpr auto kScreenBound = 20s;

std::string sh_quote(const std::string& s) {
  std::string q = "'";
  for (const char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

// What the console prints for a stiffness ({:.0f}).
std::string whole(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.0f", v);
  return buf;
}

bool have_tmux() { return run("tmux -V").exit_code == 0; }

constexpr const char* kNoTmux =
    "tmux is missing: the console tests drive teleopctl console in a real terminal through "
    "tmux. Run scripts/install-deps.sh (it installs tmux).";

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream ss(text);
  std::string line;
  while (std::getline(ss, line)) lines.push_back(line);
  return lines;
}

bool has_line_starting(const std::string& screen, const std::string& prefix) {
  for (const std::string& l : lines_of(screen)) {
    if (l.rfind(prefix, 0) == 0) return true;
  }
  return false;
}

std::string line_starting(const std::string& screen, const std::string& prefix) {
  for (const std::string& l : lines_of(screen)) {
    if (l.rfind(prefix, 0) == 0) return l;
  }
  return {};
}

// A command in an 80x24 terminal of a tmux server of its own; the server (and so the
// command) is killed when this goes. When the command exits the pane says so and stays.
class Terminal {
 public:
  explicit Terminal(const std::string& command)
      : socket_("teleop-test-" + std::to_string(::getpid()) + "-" + std::to_string(next_id())) {
    const std::string wrapped = command + "; echo \"[console exited with status $?]\"; sleep 3600";
    const CliResult r = run(tmux() + " new-session -d -x 80 -y 24 " + sh_quote(wrapped));
    started_ = r.exit_code == 0;
    start_output_ = r.out;
    if (started_) {
      socket_path_ = run(tmux() + " display-message -p -t 0 '#{socket_path}'", false).out;
      while (!socket_path_.empty() && socket_path_.back() == '\n') socket_path_.pop_back();
    }
  }
  ~Terminal() {
    (void)run(tmux() + " kill-server", true);
    // kill-server leaves the socket file behind.
    if (!socket_path_.empty()) ::unlink(socket_path_.c_str());
  }
  Terminal(const Terminal&) = delete;
  Terminal& operator=(const Terminal&) = delete;

  [[nodiscard]] bool started() const { return started_; }
  [[nodiscard]] const std::string& start_output() const { return start_output_; }

  [[nodiscard]] std::string screen() const {
    return run(tmux() + " capture-pane -p -t 0", false).out;
  }
  // Literal text, character by character.
  void type(const std::string& text) const {
    (void)run(tmux() + " send-keys -t 0 -l -- " + sh_quote(text));
  }
  // A named key (Enter, Space, Escape) or a single character.
  void key(const std::string& name) const {
    (void)run(tmux() + " send-keys -t 0 " + sh_quote(name));
  }

  // Polls the screen until `pred` holds (true) or the bound passes (false); `last` is the
  // screen last seen.
  bool wait_for(const std::function<bool(const std::string&)>& pred, std::string& last,
                std::chrono::milliseconds bound = kScreenBound) const {
    const auto until = std::chrono::steady_clock::now() + bound;
    while (true) {
      last = screen();
      if (pred(last)) return true;
      if (std::chrono::steady_clock::now() >= until) return false;
      std::this_thread::sleep_for(100ms);
    }
  }
  bool wait_for_text(const std::string& text, std::string& last,
                     std::chrono::milliseconds bound = kScreenBound) const {
    return wait_for([&](const std::string& s) { return s.find(text) != std::string::npos; }, last,
                    bound);
  }

 private:
  static int next_id() {
    static int id = 0;
    return ++id;
  }
  [[nodiscard]] std::string tmux() const { return "tmux -L " + socket_; }

  std::string socket_;
  std::string socket_path_{};
  bool started_{false};
  std::string start_output_{};
};

// --- the live system ---------------------------------------------------------------------

struct SystemPorts {
  Ports nodes{};
  int report{free_port()};
  int request{free_port()};
};

// The paddles at 1 kHz with a wall 5 mm ahead of the slave at 1000 N/m, a fixed human pushing
// 0.5 N, the supervisor's endpoints on free ports. The model assumes 2 samples of round trip
// (the loopback link measures 1-2), so the supervisor's model stays put while the test reads
// it.
constexpr double kFixture = 1000.0;

std::string system_config(const SystemPorts& p, const fs::path& record_dir) {
  return "round_trip_delay_samples: 2\n" +
         paddles_system(node_section(p.nodes, true, "", 80), node_section(p.nodes, false, "", 80),
                        "fixture { stiffness_N_per_m: 1000 position_m: 0.005 }", 0.5) +
         "supervisor { report_endpoint: \"" + tcp(p.report) + "\" request_endpoint: \"" +
         tcp(p.request) + "\" record_dir: \"" + record_dir.string() + "\" }\n" +
         kAllowUnauthenticatedRetune;
}

bool linked(const v1::Telemetry& t) { return t.link().accepted() > 0; }

// The master, the slave and the supervisor from one file, the nodes' telemetry tapped.
class LiveSystem {
 public:
  // `record_subdir`: the supervisor's record directory under the test's own.
  explicit LiveSystem(const std::string& record_subdir = "sessions") {
    config_ = dir_.write("system.textproto", system_config(ports_, dir_.path() / record_subdir));
    supervisor_ = std::make_unique<Process>(
        SUPERVISOR_BIN, std::vector<std::string>{config_.string()}, dir_.path() / "supervisor.log");
    master_ = std::make_unique<Process>(MASTER_BIN, std::vector<std::string>{config_.string()},
                                        dir_.path() / "master.log");
    slave_ = std::make_unique<Process>(SLAVE_BIN, std::vector<std::string>{config_.string()},
                                       dir_.path() / "slave.log");
  }
  // Both linked and the supervisor hearing both.
  [[nodiscard]] bool up() {
    return mt.wait_for(linked) && st.wait_for(linked) && eventually([&] {
             const auto s = supervisor_status(ctx, ports_.request);
             return s && s->master_alive() && s->slave_alive();
           });
  }
  // Armed and engaged through the nodes' own command endpoints (cleared first after a stop).
  void engage_directly(bool clear = false) {
    if (clear) {
      for (const int port : {ports_.nodes.master_command, ports_.nodes.slave_command}) {
        const auto r = send_command(ctx, tcp(port), v1::NodeCommand::CLEAR);
        ASSERT_TRUE(r.has_value() && r->ok()) << "clear on " << port;
      }
    }
    for (const auto kind : {v1::NodeCommand::ARM, v1::NodeCommand::ENGAGE}) {
      for (const int port : {ports_.nodes.master_command, ports_.nodes.slave_command}) {
        const auto r = send_command(ctx, tcp(port), kind);
        ASSERT_TRUE(r.has_value()) << "no reply from " << port;
        ASSERT_TRUE(r->ok()) << r->message();
      }
    }
    ASSERT_TRUE(mt.wait_for_mode(v1::ENGAGED)) << logs();
    ASSERT_TRUE(st.wait_for_mode(v1::ENGAGED)) << logs();
  }
  [[nodiscard]] std::string console_command(const std::string& flags = "") const {
    return std::string(TELEOPCTL_PATH) + " console " + config_.string() + flags;
  }
  // kill -9 of the supervisor; returns once it is gone.
  void kill_supervisor() {
    supervisor_->signal(SIGKILL);
    (void)supervisor_->wait();
  }
  [[nodiscard]] std::string supervisor_flag() const {
    return "--supervisor 127.0.0.1:" + std::to_string(ports_.request);
  }
  [[nodiscard]] const fs::path& config() const { return config_; }
  [[nodiscard]] std::string logs() const {
    return "--- master\n" + master_->log() + "--- slave\n" + slave_->log() + "--- supervisor\n" +
           supervisor_->log();
  }

  // The supervisor's round trip (report.roundTripSamples of `teleopctl status --json`) and
  // sample rate; nullopt when status fails.
  struct Model {
    int round_trip_samples{0};
    double sample_rate_hz{0.0};
  };
  [[nodiscard]] std::optional<Model> model() const {
    const CliResult r = teleopctl("status --json " + supervisor_flag(), false);
    if (r.exit_code != 0) return std::nullopt;
    const nlohmann::json j = nlohmann::json::parse(r.out, nullptr, false);
    if (j.is_discarded() || !j.contains("report")) return std::nullopt;
    return Model{j["report"].value("round_trip_samples", 0),
                 j["report"].value("sample_rate_hz", 0.0)};
  }
  // `teleopctl analyze --max-stiffness slave --json` of this system's file with that model.
  [[nodiscard]] std::optional<double> analysed_limit(const Model& m, std::string& out) const {
    std::string sets = " --set round_trip_delay_samples=" + std::to_string(m.round_trip_samples);
    if (m.sample_rate_hz > 0.0 && m.sample_rate_hz != 1000.0) {
      sets += " --set sample_rate_hz=" + exact(m.sample_rate_hz);
    }
    const CliResult r =
        teleopctl("analyze " + config_.string() + " --max-stiffness slave --json" + sets, false);
    out = r.out;
    if (r.exit_code != 0) return std::nullopt;
    const nlohmann::json j = nlohmann::json::parse(r.out, nullptr, false);
    if (j.is_discarded() || !j["limits"][0]["max_stable_stiffness_N_per_m"].is_number()) {
      return std::nullopt;  // no stable stiffness at that round trip: `out` says why
    }
    return j["limits"][0]["max_stable_stiffness_N_per_m"].get<double>();
  }
  // The limit for the supervisor's current model (asserting on the way).
  [[nodiscard]] double current_limit() const {
    const auto m = model();
    EXPECT_TRUE(m.has_value()) << "teleopctl status --json failed";
    if (!m) return 0.0;
    std::string out;
    const auto limit = analysed_limit(*m, out);
    EXPECT_TRUE(limit.has_value()) << out;
    std::cout << "supervisor's model: round trip " << m->round_trip_samples << " samples at "
              << m->sample_rate_hz << " Hz; teleopctl analyze: slave fixture limit "
              << limit.value_or(0.0) << " N/m\n";
    return limit.value_or(0.0);
  }

  // Declared in this order: the taps subscribe before the constructor starts the nodes.
  zmq::context_t ctx{1};

 private:
  TempDir dir_{};
  SystemPorts ports_{};
  fs::path config_{};

 public:
  TelemetryTap mt{ctx, tcp(ports_.nodes.master_telemetry)};
  TelemetryTap st{ctx, tcp(ports_.nodes.slave_telemetry)};

 private:
  std::unique_ptr<Process> supervisor_;
  std::unique_ptr<Process> master_;
  std::unique_ptr<Process> slave_;
};

bool both_engaged_on_screen(const std::string& s) {
  return has_line_starting(s, "master ENGAGED") && has_line_starting(s, "slave  ENGAGED");
}

// The console in an 80x24 terminal over the running system; with `engaged`, both nodes are
// engaged directly first (not from the console) and the screen shows both engaged. `screen`
// is the screen last seen. Asserts on the way: call it through ASSERT_NO_FATAL_FAILURE.
void open_console(LiveSystem& sys, std::optional<Terminal>& term, std::string& screen, bool engaged,
                  const std::string& flags = "") {
  ASSERT_TRUE(have_tmux()) << kNoTmux;
  ASSERT_TRUE(sys.up()) << sys.logs();
  if (engaged) {
    sys.engage_directly();
    if (::testing::Test::HasFatalFailure()) return;
  }
  term.emplace(sys.console_command(flags));
  ASSERT_TRUE(term->started()) << term->start_output();
  if (engaged) {
    ASSERT_TRUE(term->wait_for(both_engaged_on_screen, screen)) << screen;
  }
}

// Where the stiffness and e-stop tests start.
void open_console_engaged(LiveSystem& sys, std::optional<Terminal>& term, std::string& screen,
                          const std::string& flags = "") {
  open_console(sys, term, screen, true, flags);
}

// --- tests -------------------------------------------------------------------------------

TEST(Console, ConsoleShowsBothNodesEngaged) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console(sys, term, screen, false));
  // The console's first screens: the summary arriving, both nodes disarmed.
  ASSERT_TRUE(term->wait_for(
      [](const std::string& s) {
        return has_line_starting(s, "TELEOP CONSOLE  live ") &&
               s.find("WAITING FOR THE SUMMARY") == std::string::npos &&
               has_line_starting(s, "master DISARMED") && has_line_starting(s, "slave  DISARMED");
      },
      screen))
      << screen;
  EXPECT_NE(screen.find("[read-write]"), std::string::npos) << screen;

  // Engaged from the console's own keys: a arm, e engage (through the supervisor).
  term->key("a");
  ASSERT_TRUE(sys.mt.wait_for_mode(v1::ARMED)) << term->screen() << sys.logs();
  ASSERT_TRUE(sys.st.wait_for_mode(v1::ARMED)) << term->screen() << sys.logs();
  term->key("e");
  ASSERT_TRUE(sys.mt.wait_for_mode(v1::ENGAGED)) << term->screen() << sys.logs();
  ASSERT_TRUE(sys.st.wait_for_mode(v1::ENGAGED)) << term->screen() << sys.logs();
  ASSERT_TRUE(term->wait_for(both_engaged_on_screen, screen)) << screen;
  std::cout << screen;

  // The fixture row: the configured stiffness and the analysed limit for the supervisor's
  // round trip (re-read each poll, should the measured round trip change meanwhile).
  std::map<int, double> limits;
  std::string expected;
  std::string why;
  const bool shown = term->wait_for(
      [&](const std::string& s) {
        const auto m = sys.model();
        if (!m) {
          why = "teleopctl status --json failed";
          return false;
        }
        if (!limits.contains(m->round_trip_samples)) {
          std::string out;
          const auto limit = sys.analysed_limit(*m, out);
          if (!limit) {
            why = "teleopctl analyze failed: " + out;
            return false;
          }
          limits[m->round_trip_samples] = *limit;
          std::cout << "round trip " << m->round_trip_samples << " samples: analysed limit "
                    << *limit << " N/m\n";
        }
        const double limit = limits[m->round_trip_samples];
        std::smatch match;
        const std::string row = line_starting(s, "slave  fixture");
        expected = "slave  fixture " + whole(kFixture) + " of " + whole(limit) +
                   " N/m (round trip " + std::to_string(m->round_trip_samples) + " samples)";
        if (!std::regex_search(row, match,
                               std::regex(R"(^slave  fixture\s+(\d+) of\s+(\d+) N/m)"))) {
          why = "no fixture row with a limit: '" + row + "'";
          return false;
        }
        why = "row '" + row + "'";
        return match[1] == whole(kFixture) && match[2] == whole(limit);
      },
      screen);
  EXPECT_TRUE(shown) << "expected " << expected << "; " << why << "\nscreen:\n" << screen;
  // Still both engaged on the same screen.
  EXPECT_TRUE(both_engaged_on_screen(screen)) << screen;
}

TEST(Console, UnstableStiffnessIsRefusedOnScreenWithItsReason) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console_engaged(sys, term, screen));
  const double limit = sys.current_limit();
  ASSERT_GT(limit, kFixture);

  // 1.5 x the limit: refused straight from the prediction, with the reason; no y asked for.
  const std::string too_stiff = whole(std::round(1.5 * limit));
  term->key("s");
  ASSERT_TRUE(term->wait_for_text("set (PATH=VALUE ...)> ", screen)) << screen;
  term->type("slave.fixture.stiffness_N_per_m=" + too_stiff);
  term->key("Enter");
  std::string reason;
  const bool refused = term->wait_for(
      [&](const std::string& s) {
        const std::size_t at = s.find("REFUSED");
        if (at == std::string::npos) return false;
        // The reason, joined across the lines it wraps over.
        reason.clear();
        for (const std::string& l : lines_of(s.substr(at))) reason += l;
        return reason.find("unstable") != std::string::npos;
      },
      screen);
  ASSERT_TRUE(refused) << "expected REFUSED ... unstable on screen:\n" << screen;
  std::cout << screen;
  EXPECT_EQ(screen.find("apply it?"), std::string::npos) << screen;
  // The nodes: still the file's stiffness, no change in any cycle, half a second on.
  const std::size_t m0 = sys.mt.messages();
  const std::size_t s0 = sys.st.messages();
  ASSERT_TRUE(
      eventually([&] { return sys.mt.messages() >= m0 + 50 && sys.st.messages() >= s0 + 50; }));
  for (const TelemetryTap* tap : {&sys.mt, &sys.st}) {
    ASSERT_TRUE(tap->last().has_value());
    EXPECT_EQ(tap->last()->active().slave_fixture_stiffness_n_per_m(), kFixture);
    EXPECT_EQ(tap->last()->active().change_id(), 0u);
    for (const auto& c : tap->cycles()) ASSERT_EQ(c.parameter_change_id(), 0u);
  }

  // 0.5 x the limit: the prediction first, then y applies it and both nodes ramp it in.
  const std::string lower_text = whole(std::round(0.5 * limit));
  const double lower = std::stod(lower_text);
  term->key("s");
  ASSERT_TRUE(term->wait_for_text("set (PATH=VALUE ...)> ", screen)) << screen;
  term->type("slave.fixture.stiffness_N_per_m=" + lower_text);
  term->key("Enter");
  ASSERT_TRUE(term->wait_for(
      [&](const std::string& s) {
        return s.find("prediction for slave.fixture.stiffness_N_per_m=" + lower_text) !=
                   std::string::npos &&
               s.find("apply it? y applies") != std::string::npos;
      },
      screen))
      << screen;
  std::cout << screen;
  term->key("y");
  ASSERT_TRUE(term->wait_for_text("APPLIED slave.fixture.stiffness_N_per_m=" + lower_text, screen))
      << screen;
  std::cout << screen;
  for (const TelemetryTap* tap : {&sys.mt, &sys.st}) {
    EXPECT_TRUE(tap->wait_for([&](const v1::Telemetry& t) {
      return t.active().change_id() != 0 && t.active().ramp_progress() == 1.0 &&
             std::abs(t.active().slave_fixture_stiffness_n_per_m() - lower) < 1e-6;
    })) << "active slave fixture stiffness "
        << (tap->last() ? tap->last()->active().slave_fixture_stiffness_n_per_m() : -1.0);
  }
  // And the screen's fixture row follows.
  EXPECT_TRUE(term->wait_for(
      [&](const std::string& s) {
        return std::regex_search(line_starting(s, "slave  fixture"),
                                 std::regex("^slave  fixture\\s+" + lower_text + " of"));
      },
      screen))
      << screen;
}

TEST(Console, EstopDrivesBothNodesSafeAndTheScreenSaysSo) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console_engaged(sys, term, screen));

  term->key("x");
  const bool safe = term->wait_for(
      [](const std::string& s) {
        return s.find("both nodes confirmed safe") != std::string::npos &&
               has_line_starting(s, "master SAFE") && has_line_starting(s, "slave  SAFE");
      },
      screen);
  EXPECT_TRUE(safe) << screen;
  std::cout << screen;
  EXPECT_NE(screen.find("E-STOP: "), std::string::npos) << screen;
  // Independently: the nodes' own telemetry.
  EXPECT_TRUE(sys.mt.wait_for_mode(v1::SAFE)) << sys.logs();
  EXPECT_TRUE(sys.st.wait_for_mode(v1::SAFE)) << sys.logs();
}

TEST(Console, EstopIsOneKeyAwayOnTheHelpScreenAndWhileTypingAChange) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console_engaged(sys, term, screen));
  auto both_safe_after = [&](const std::string& note) {
    return term->wait_for(
        [&](const std::string& s) {
          const std::size_t at = s.find(note);
          return at != std::string::npos &&
                 s.find("both nodes confirmed safe", at) != std::string::npos &&
                 has_line_starting(s, "master SAFE") && has_line_starting(s, "slave  SAFE");
        },
        screen);
  };

  // On the help screen, x is the e-stop (and leaves the help).
  term->key("?");
  ASSERT_TRUE(term->wait_for_text("E-STOP both nodes", screen)) << screen;
  term->key("x");
  EXPECT_TRUE(both_safe_after("E-STOP: ")) << screen;
  EXPECT_TRUE(sys.mt.wait_for_mode(v1::SAFE)) << sys.logs();
  EXPECT_TRUE(sys.st.wait_for_mode(v1::SAFE)) << sys.logs();

  // Engaged again; typing a change, where x is a letter, Ctrl-X is the e-stop.
  ASSERT_NO_FATAL_FAILURE(sys.engage_directly(true));
  ASSERT_TRUE(term->wait_for(both_engaged_on_screen, screen)) << screen;
  term->key("s");
  ASSERT_TRUE(term->wait_for_text("Ctrl-X E-STOP", screen)) << screen;
  term->type("gains.kps=1");
  term->key("C-x");
  EXPECT_TRUE(both_safe_after("typing cancelled for the e-stop")) << screen;
  EXPECT_TRUE(sys.mt.wait_for_mode(v1::SAFE)) << sys.logs();
  EXPECT_TRUE(sys.st.wait_for_mode(v1::SAFE)) << sys.logs();
  // What was typed never went to the supervisor: no prediction for it.
  EXPECT_EQ(screen.find("prediction for gains.kps=1"), std::string::npos) << screen;
  std::cout << screen;
}

TEST(Console, EstopGoesStraightToTheNodesWhenTheSupervisorIsGone) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console_engaged(sys, term, screen));
  sys.kill_supervisor();
  // The screen says its numbers are old (no summary for over a second) ...
  EXPECT_TRUE(term->wait_for(
      [](const std::string& s) { return s.find("NO SUMMARY FOR") != std::string::npos; }, screen))
      << screen;
  // ... and the e-stop still reaches both nodes, directly, each confirming.
  term->key("x");
  EXPECT_TRUE(term->wait_for(
      [](const std::string& s) {
        return s.find("sent to the nodes directly") != std::string::npos &&
               s.find("both nodes confirmed safe") != std::string::npos;
      },
      screen))
      << screen;
  EXPECT_TRUE(sys.mt.wait_for_mode(v1::SAFE)) << sys.logs();
  EXPECT_TRUE(sys.st.wait_for_mode(v1::SAFE)) << sys.logs();
}

TEST(Console, ReadOnlyConsoleChangesNothingButCanEstop) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console_engaged(sys, term, screen, " --read-only"));
  EXPECT_NE(screen.find("[read-only]"), std::string::npos) << screen;
  term->key("d");  // disengage: refused on this side, nothing sent
  EXPECT_TRUE(term->wait_for(
      [](const std::string& s) { return s.find("read-only console") != std::string::npos; },
      screen))
      << screen;
  // Both nodes stay engaged over the next 300 cycles of the master's own telemetry.
  const std::size_t seen = sys.mt.cycles().size();
  ASSERT_TRUE(eventually([&] { return sys.mt.cycles().size() > seen + 300; })) << sys.logs();
  const std::vector<v1::CycleRecord> after = sys.mt.cycles();
  for (std::size_t i = seen; i < after.size(); ++i) ASSERT_EQ(after[i].mode(), v1::ENGAGED) << i;
  EXPECT_EQ(sys.st.mode(), v1::ENGAGED);
  term->key("x");
  EXPECT_TRUE(term->wait_for(
      [](const std::string& s) { return s.find("both nodes confirmed safe") != std::string::npos; },
      screen))
      << screen;
  EXPECT_TRUE(sys.mt.wait_for_mode(v1::SAFE)) << sys.logs();
}

// The replay header: state, position and duration.
struct ReplayHeader {
  std::string state{};
  double position_s{0.0};
  double duration_s{0.0};
};

std::optional<ReplayHeader> replay_header(const std::string& screen) {
  std::smatch m;
  const std::string first = lines_of(screen).empty() ? "" : lines_of(screen).front();
  if (!std::regex_search(first, m,
                         std::regex(R"(^TELEOP REPLAY  (\S+) ([0-9.]+)/([0-9.]+) s  x)"))) {
    return std::nullopt;
  }
  return ReplayHeader{m[1], std::stod(m[2]), std::stod(m[3])};
}

// Polls the terminal until its replay header satisfies `pred`.
bool wait_for_header(const Terminal& term, std::string& screen,
                     const std::function<bool(const ReplayHeader&)>& pred) {
  return term.wait_for(
      [&](const std::string& s) {
        const auto h = replay_header(s);
        return h && pred(*h);
      },
      screen);
}

// 20 s of the master-side fixture scene (long enough to play through a test at x1), replayed
// with `teleopctl replay --speed 1 --hold` on free ports, and the console watching it in a
// terminal. Asserts on the way: call start() through ASSERT_NO_FATAL_FAILURE.
class ReplayedScene {
 public:
  void start(bool paused) {
    ASSERT_TRUE(have_tmux()) << kNoTmux;
    const CliResult sim = teleopctl(
        "simulate " + std::string(TELEOP_SOURCE_DIR) +
        "/examples/scenes/paddles_master_fixture.textproto --duration 20 --out " + file_.string());
    ASSERT_TRUE(sim.exit_code == 0 || sim.exit_code == 3) << sim.out;
    ASSERT_TRUE(fs::exists(file_)) << sim.out;
    const std::string control = tcp(free_port());
    const std::string report = tcp(free_port());
    std::vector<std::string> args = {
        "replay",        file_.string(),       "--speed",        "1",
        "--hold",        "--control",          control,          "--report",
        report,          "--master-telemetry", tcp(free_port()), "--slave-telemetry",
        tcp(free_port())};
    if (paused) args.emplace_back("--paused");
    replay_ = std::make_unique<Process>(TELEOPCTL_PATH, args, dir_.path() / "replay.log");
    term_.emplace(std::string(TELEOPCTL_PATH) + " console --replay --control " + control +
                  " --report " + report);
    ASSERT_TRUE(term_->started()) << term_->start_output();
  }
  [[nodiscard]] Terminal& term() { return *term_; }
  [[nodiscard]] std::string log() const { return replay_ ? replay_->log() : std::string(); }

 private:
  TempDir dir_{};
  fs::path file_{dir_.path() / "session.mcap"};
  std::unique_ptr<Process> replay_{};
  std::optional<Terminal> term_{};
};

TEST(Console, ReplayCanBePausedAndResumed) {
  ReplayedScene scene;
  ASSERT_NO_FATAL_FAILURE(scene.start(false));
  Terminal& term = scene.term();
  std::string screen;
  ASSERT_TRUE(
      wait_for_header(term, screen, [](const ReplayHeader& h) { return h.state == "playing"; }))
      << "no 'playing' in the header (does the replay publish the \"status\" summary?)\n"
      << screen << "--- replay\n"
      << scene.log();
  std::cout << screen;
  EXPECT_NE(lines_of(screen).front().find("session.mcap"), std::string::npos) << screen;
  EXPECT_NEAR(replay_header(screen)->duration_s, 20.0, 0.1) << screen;

  // Space: paused, and the position stays where it is.
  term.key("Space");
  ASSERT_TRUE(
      wait_for_header(term, screen, [](const ReplayHeader& h) { return h.state == "paused"; }))
      << screen << "--- replay\n"
      << scene.log();
  std::cout << screen;
  const double paused_at = replay_header(screen)->position_s;
  std::this_thread::sleep_for(500ms);
  screen = term.screen();
  const auto later = replay_header(screen);
  ASSERT_TRUE(later.has_value()) << screen;
  EXPECT_EQ(later->state, "paused") << screen;
  EXPECT_EQ(later->position_s, paused_at) << screen;

  // Space again: playing, and the position moves on from there.
  term.key("Space");
  ASSERT_TRUE(wait_for_header(
      term, screen,
      [&](const ReplayHeader& h) { return h.state == "playing" && h.position_s > paused_at; }))
      << "paused at " << paused_at << "\n"
      << screen << "--- replay\n"
      << scene.log();
  std::cout << screen;
}

TEST(Console, ReplaySeeksAndChangesSpeedFromTheKeys) {
  // Started paused: every position below is where a key put it, not where the clock did.
  ReplayedScene scene;
  ASSERT_NO_FATAL_FAILURE(scene.start(true));
  Terminal& term = scene.term();
  std::string screen;
  auto at = [&](double position_s, const std::string& state = "paused") {
    return wait_for_header(term, screen, [&](const ReplayHeader& h) {
      return h.state == state && std::abs(h.position_s - position_s) <= 0.05;
    });
  };
  ASSERT_TRUE(at(0.0)) << screen << "--- replay\n" << scene.log();
  // '.' 5 s on, '>' 30 s on (clamped to the 20 s end), ',' 5 s back, '0' the start.
  term.key(".");
  ASSERT_TRUE(at(5.0)) << screen << "--- replay\n" << scene.log();
  term.key(".");
  ASSERT_TRUE(at(10.0)) << screen;
  term.key(",");
  ASSERT_TRUE(at(5.0)) << screen;
  term.key("0");
  ASSERT_TRUE(at(0.0)) << screen;
  // 'g' and a time: there.
  term.key("g");
  ASSERT_TRUE(term.wait_for_text("go to (s)> ", screen)) << screen;
  term.type("12.5");
  term.key("Enter");
  ASSERT_TRUE(at(12.5)) << screen;
  // ']' doubles the speed, '[' halves it: the header shows the replay's own speed.
  auto speed_shown = [&](const std::string& speed) {
    return term.wait_for(
        [&](const std::string& s) {
          return lines_of(s).front().find("s  x" + speed + "  ") != std::string::npos;
        },
        screen);
  };
  term.key("]");
  ASSERT_TRUE(speed_shown("2")) << screen;
  term.key("[");
  term.key("[");
  ASSERT_TRUE(speed_shown("0.5")) << screen;
  // Playing from 12.5 s at half speed: the position moves on from there.
  term.key("Space");
  ASSERT_TRUE(wait_for_header(term, screen, [](const ReplayHeader& h) {
    return h.state == "playing" && h.position_s > 12.6;
  })) << screen;
  std::cout << screen;
}

TEST(Console, RecordingStopsAndStartsAgainFromTheKeyEachFileWhole) {
  LiveSystem sys;
  std::optional<Terminal> term;
  std::string screen;
  ASSERT_NO_FATAL_FAILURE(open_console(sys, term, screen, false));
  // The supervisor records from its start (record_dir in the file).
  const std::regex file_re(R"(^recorder  (teleop-session-\S+\.mcap)  )");
  auto recording_file = [&](const std::string& s) {
    std::smatch m;
    const std::string row = line_starting(s, "recorder  ");
    return std::regex_search(row, m, file_re) ? std::string(m[1]) : std::string();
  };
  ASSERT_TRUE(
      term->wait_for([&](const std::string& s) { return !recording_file(s).empty(); }, screen))
      << screen;
  const std::string first = recording_file(screen);

  // r: stopped, and the screen says so and offers a new one.
  term->key("r");
  ASSERT_TRUE(term->wait_for(
      [](const std::string& s) {
        return s.find("recording stopped") != std::string::npos &&
               line_starting(s, "recorder  ").rfind("recorder  off (r starts one in ", 0) == 0;
      },
      screen))
      << screen << sys.logs();
  // r again: a new file, named on screen; r once more closes it.
  term->key("r");
  ASSERT_TRUE(term->wait_for(
      [&](const std::string& s) {
        const std::string f = recording_file(s);
        return !f.empty() && f != first && s.find("recording to ") != std::string::npos;
      },
      screen))
      << screen << sys.logs();
  const std::string second = recording_file(screen);
  // Let it hold some telemetry (the recorder line counts messages), then stop.
  ASSERT_TRUE(term->wait_for(
      [](const std::string& s) {
        std::smatch m;
        const std::string row = line_starting(s, "recorder  ");
        return std::regex_search(row, m, std::regex(R"(  (\d+) msgs)")) && std::stoi(m[1]) > 100;
      },
      screen))
      << screen;
  term->key("r");
  ASSERT_TRUE(term->wait_for(
      [](const std::string& s) {
        return line_starting(s, "recorder  ").rfind("recorder  off", 0) == 0;
      },
      screen))
      << screen;
  std::cout << screen;
  // Both files are whole MCAP files with the nodes' telemetry: teleopctl replay reads each
  // (it refuses a file without its summary and closing magic).
  const fs::path sessions = sys.config().parent_path() / "sessions";
  for (const std::string& f : {first, second}) {
    const CliResult r = teleopctl("replay " + (sessions / f).string() + " --json", false);
    ASSERT_EQ(r.exit_code, 0) << f << ": " << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << r.out;
    EXPECT_NE(r.out.find("/master/telemetry"), std::string::npos) << f << ": " << r.out;
  }
}

TEST(Console, WithoutATerminalExitsOneNamingTeleopctlStatus) {
  // stdin from /dev/null and stdout a pipe: no terminal.
  const CliResult r = teleopctl("console < /dev/null");
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("teleopctl status"), std::string::npos) << r.out;
}

// --- several task-space axes (issue 18) ------------------------------------------------------

// 10 s of a 3-axis session at 1 kHz written here, every cycle the same: the master at (3, 4, 0)
// mm, load cell (0.3, -1.2, 0.4) N, command (0.6, 0.8, 0) N; the slave at (2.9, 4.1, 0.3) mm with
// the negated forces. Without a /config the replay's summary stands on the paddles (position
// scaling 1), so by hand: |x_m| = 5.00 mm, |F| = 1.30 N (largest on axis 1), |u| = 1.00 N,
// tracking error x_m - x_s = (0.1, -0.1, -0.3) mm, largest on axis 2.
void write_three_axis_session(const fs::path& file) {
  const std::unique_ptr<record::SessionSink> sink = record::make_session_recorder_at(file);
  const double x_m[] = {3e-3, 4e-3, 0.0};
  const double x_s[] = {2.9e-3, 4.1e-3, 0.3e-3};
  const double f[] = {0.3, -1.2, 0.4};
  const double u[] = {0.6, 0.8, 0.0};
  for (int message = 0; message < 100; ++message) {
    for (const bool master : {true, false}) {
      v1::Telemetry t;
      t.set_session_id(master ? 1 : 2);
      t.set_mode(v1::ENGAGED);
      t.mutable_loop()->set_period_s(1e-3);
      for (int k = 0; k < 100; ++k) {
        const int cycle = 100 * message + k;
        v1::CycleRecord* c = t.add_cycles();
        c->set_sequence(static_cast<std::uint64_t>(cycle + 1));
        c->set_sample_time_ns(1'000'000LL * cycle);
        c->set_mode(v1::ENGAGED);
        c->set_axes(3);
        for (int i = 0; i < 3; ++i) {
          const double sign = master ? 1.0 : -1.0;
          c->add_positions_m(master ? x_m[i] : x_s[i]);
          c->add_velocities_m_per_s(0.0);
          c->add_forces_n(sign * f[i]);
          c->add_commands_n(sign * u[i]);
          c->add_peer_positions_m(master ? x_s[i] : x_m[i]);
        }
      }
      const std::int64_t log_time = 1'000'000LL * (100 * message + 99);
      sink->record(record::topic::telemetry(master), "teleop.v1.Telemetry", log_time,
                   t.SerializeAsString());
    }
  }
}

TEST(Console, ThreeAxisNodesShowNormsWorstAxesAndTheirTable) {
  ASSERT_TRUE(have_tmux()) << kNoTmux;
  TempDir dir;
  const fs::path file = dir.path() / "axes.mcap";
  write_three_axis_session(file);
  const std::string control = tcp(free_port());
  const std::string report = tcp(free_port());
  Process replay(
      TELEOPCTL_PATH,
      {"replay", file.string(), "--speed", "1", "--hold", "--control", control, "--report", report,
       "--master-telemetry", tcp(free_port()), "--slave-telemetry", tcp(free_port())},
      dir.path() / "replay.log");
  Terminal term(std::string(TELEOPCTL_PATH) + " console --replay --control " + control +
                " --report " + report);
  ASSERT_TRUE(term.started()) << term.start_output();
  std::string screen;
  ASSERT_TRUE(
      term.wait_for_text("3 axes |u| 1.00N  worst: F axis 1 -1.20N, e axis 2 -0.30mm", screen))
      << screen << "--- replay\n"
      << replay.log();
  std::cout << screen;
  EXPECT_NE(line_starting(screen, "master ENGAGED").find("|x| 5.00mm |F|1.30N"), std::string::npos)
      << screen;
  EXPECT_NE(screen.find("3 axes |u| 1.00N  worst: F axis 1 +1.20N, e axis 2 -0.30mm"),
            std::string::npos)
      << screen;
  EXPECT_FALSE(has_line_starting(screen, "axis 0")) << screen;
  // t: the table, one row per axis, each side's x, F, u and the tracking error.
  term.key("t");
  ASSERT_TRUE(
      term.wait_for([](const std::string& s) { return has_line_starting(s, "axis 2"); }, screen))
      << screen;
  std::cout << screen;
  EXPECT_EQ(line_starting(screen, "axis 1"),
            "axis 1         4.00  -1.20   0.80         4.10   1.20  -0.80     -0.100")
      << screen;
  EXPECT_FALSE(has_line_starting(screen, "axis 3")) << screen;
  // t again: gone.
  term.key("t");
  ASSERT_TRUE(
      term.wait_for([](const std::string& s) { return !has_line_starting(s, "axis 0"); }, screen))
      << screen;
}

}  // namespace
}  // namespace teleop::test
