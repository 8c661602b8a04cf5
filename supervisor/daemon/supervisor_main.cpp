// main() of teleop-supervisor.
#include <signal.h>
#include <spdlog/sinks/rotating_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <thread>

#include "common/core/command_line.hpp"
#include "common/core/version.hpp"
#include "common/record/session_recorder.hpp"
#include "common/record/session_retention.hpp"
#include "common/runtime/service_notify.hpp"
#include "common/stability/analyzer.hpp"
#include "supervisor/daemon/supervisor_app.hpp"

namespace teleop::supervisor {
namespace {

void usage(std::ostream& os) {
  os << "usage: teleop-supervisor CONFIG [--set PATH=VALUE]... [--record-dir DIR] [--no-record]\n\n"
        "Watches the teleoperator CONFIG describes: analyses it with the measured round trip,\n"
        "publishes stability reports and alarms, guards parameter changes, escalates when the\n"
        "live system misbehaves, and records the session (MCAP) in DIR. Stops on "
        "SIGINT/SIGTERM.\n\n"
        "options:\n"
        "  --set PATH=VALUE  override one field of CONFIG (repeatable, each path once)\n"
        "  --record-dir DIR  where the session file and the log go\n"
        "  --no-record       supervise without recording\n"
        "  --version         print the version and exit\n"
        "  -h, --help        this text\n\n"
        "An option's value may also follow an '=' (--record-dir=DIR).\n";
}

// The configuration file as read, for the session's attachment ("" when it cannot be read
// again: the core then attaches the loaded configuration).
std::string read_config_text(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream text;
  text << in.rdbuf();
  return in ? text.str() : std::string();
}

// The session file and the log file in `dir`. A directory that cannot be created or written
// (read-only, a file in the way) is not fatal: the supervisor supervises without recording
// and says why (options.record_failure, a CRITICAL alarm at start).
// A new session file in `dir`, then the retention policy applied around it (docs/supervisor.md
// "Session retention"): the oldest sessions removed, never this one.
std::unique_ptr<record::SessionSink> new_session(const std::filesystem::path& dir,
                                                 const record::RetentionPolicy& policy) {
  std::filesystem::create_directories(dir);
  std::unique_ptr<record::SessionSink> sink = record::make_session_recorder(dir);
  std::vector<std::string> failures;
  for (const std::filesystem::path& p :
       record::apply_retention(dir, policy, sink->file(), &failures)) {
    spdlog::info("session retention: removed {}", p.string());
  }
  for (const std::string& f : failures) spdlog::warn("session retention: not removed: {}", f);
  return sink;
}

void start_recording(const std::filesystem::path& dir, const record::RetentionPolicy& policy,
                     SupervisorOptions& options, std::vector<spdlog::sink_ptr>& sinks) {
  try {
    options.sink = new_session(dir, policy);
  } catch (const std::exception& e) {
    options.sink.reset();
    options.record_failure = "cannot record in " + dir.string() + ": " + e.what();
    return;
  }
  try {
    sinks.push_back(std::make_shared<spdlog::sinks::rotating_file_sink_mt>(
        (dir / "teleop-supervisor.log").string(), 5 * 1024 * 1024, 3));
  } catch (const std::exception& e) {
    std::cerr << "teleop-supervisor: no log file in " << dir.string() << ": " << e.what() << "\n";
  }
}

// The supervisor's command line.
struct SupervisorArgs {
  std::string config_path{};
  std::vector<std::string> overrides{};
  std::optional<std::string> record_dir{};
  bool record{true};
};

// The command line read (nullopt), or the exit code when it was --help, --version or wrong.
std::optional<int> parse_args(const std::vector<std::string>& args, SupervisorArgs& out) {
  try {
    cli::ArgCursor cur(args);
    while (cur.next()) {
      const std::string& a = cur.arg();
      if (a == "--help" || a == "-h") {
        usage(std::cout);
        return 0;
      }
      if (a == "--version") {
        std::cout << "teleop-supervisor " << version() << "\n";
        return 0;
      }
      if (a == "--set") {
        out.overrides.push_back(cur.value("--set"));
      } else if (a == "--record-dir") {
        out.record_dir = cur.value("--record-dir");
      } else if (a == "--no-record") {
        out.record = false;
      } else if (out.config_path.empty() && a.rfind("-", 0) != 0) {
        out.config_path = a;
      } else {
        throw cli::UsageError("unexpected argument '" + a + "'");
      }
    }
  } catch (const cli::UsageError& e) {
    std::cerr << "teleop-supervisor: " << e.what() << "\n";
    usage(std::cerr);
    return 2;
  }
  if (out.config_path.empty()) {
    usage(std::cerr);
    return 2;
  }
  return std::nullopt;
}

}  // namespace

int run_supervisor_main(int argc, char** argv) {
  // The analyses share the machine with the nodes' loops: one core (stability/analyzer.hpp).
  stability::set_analysis_threads(1);
  SupervisorArgs parsed;
  if (const auto rc = parse_args(std::vector<std::string>(argv + 1, argv + argc), parsed)) {
    return *rc;
  }
  const std::string& config_path = parsed.config_path;
  const std::vector<std::string>& overrides = parsed.overrides;
  const std::optional<std::string>& record_dir = parsed.record_dir;
  const bool record = parsed.record;
  // A file-size limit (RLIMIT_FSIZE) then fails the recorder's write with EFBIG, as a full disk
  // fails it with ENOSPC, instead of killing the supervisor.
  signal(SIGXFSZ, SIG_IGN);
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  std::unique_ptr<SupervisorApp> app;
  std::optional<runtime::ServiceNotifier> notifier;
  try {
    // The file, validated once, as the whole typed system (system_compiler.hpp); a file of
    // several axes through its one-axis view for the settings and endpoints, and supervised as
    // n axes (supervisor/core/axes_supervision.hpp).
    const config::LoadedConfig loaded = config::parse_config_file(config_path, overrides);
    config::CompiledSystem system = compile_supervised(loaded);
    const v1::Supervisor& s = system.source().config.supervisor();
    const bool recording = record && (!s.has_record() || s.record());
    const std::filesystem::path dir =
        record_dir ? *record_dir : (s.record_dir().empty() ? "." : s.record_dir());
    SupervisorOptions options;
    options.config_text = read_config_text(config_path);
    std::vector<spdlog::sink_ptr> sinks{std::make_shared<spdlog::sinks::stderr_color_sink_mt>()};
    options.record_dir = dir.string();
    const record::RetentionPolicy retention{system.supervisor().max_sessions,
                                            system.supervisor().max_sessions_bytes};
    options.new_sink = [dir, retention] { return new_session(dir, retention); };
    if (recording) start_recording(dir, retention, options, sinks);
    auto logger = std::make_shared<spdlog::logger>("teleop-supervisor", sinks.begin(), sinks.end());
    logger->set_pattern("[%H:%M:%S.%e] [teleop-supervisor] [%^%l%$] %v");
    // Every line reaches the log file at once: a kill -9 keeps everything logged before it.
    logger->flush_on(spdlog::level::trace);
    spdlog::set_default_logger(logger);
    if (!options.record_failure.empty()) {
      spdlog::critical("not recording: {} (supervising without recording)", options.record_failure);
    }
    if (options.sink) spdlog::info("recording to {}", options.sink->file());
    // systemd (Type=notify): logs whether the watchdog is on, once the logger is set up.
    notifier.emplace("main loop");
    app = several_axes(loaded)
              ? std::make_unique<SupervisorApp>(loaded, std::move(options))
              : std::make_unique<SupervisorApp>(std::move(system), std::move(options));
  } catch (const config::ConfigError& e) {
    std::cerr << "teleop-supervisor: invalid configuration:\n" << e.what() << "\n";
    if (notifier) notifier->status(std::string("invalid configuration: ") + e.what());
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "teleop-supervisor: " << e.what() << "\n";
    if (notifier) notifier->status(std::string("failed to start: ") + e.what());
    return 1;
  }
  std::atomic<bool> stop{false};
  std::atomic<bool> finished{false};
  // This thread takes the signals and speaks to systemd: READY once the main loop runs (its
  // endpoints bound), the watchdog fed only while the main loop keeps iterating, STOPPING.
  std::thread waiter([&] {
    bool ready = false;
    while (!finished.load()) {
      const std::uint64_t beats = app->loop_iterations();
      if (!ready && beats > 0) {
        notifier->ready("supervising " + config_path);
        ready = true;
      }
      const std::chrono::nanoseconds wait =
          ready ? notifier->heartbeat(beats) : std::chrono::nanoseconds(5'000'000);
      const timespec poll{static_cast<time_t>(wait.count() / 1'000'000'000),
                          static_cast<long>(wait.count() % 1'000'000'000)};
      const int sig = sigtimedwait(&signals, nullptr, &poll);
      if (sig == SIGINT || sig == SIGTERM) {
        notifier->stopping("signal " + std::to_string(sig) + ": stopping");
        stop = true;
        return;
      }
    }
  });
  int rc = 0;
  std::string failure;
  try {
    app->run(stop);
  } catch (const std::exception& e) {
    std::cerr << "teleop-supervisor: " << e.what() << "\n";
    failure = e.what();
    rc = 1;
  }
  finished = true;
  waiter.join();
  if (rc != 0) notifier->stopping("failed: " + failure);
  app.reset();  // closes the session file (summary written)
  spdlog::info("stopped");
  return rc;
}

}  // namespace teleop::supervisor

int main(int argc, char** argv) { return teleop::supervisor::run_supervisor_main(argc, argv); }
