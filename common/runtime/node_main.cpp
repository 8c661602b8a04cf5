// main() of the node processes: configuration -> device -> NodeApp, until a signal or SHUTDOWN.
#include <signal.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"
#include "common/config/control_fingerprint.hpp"
#include "common/config/node_loader.hpp"
#include "common/config/system_compiler.hpp"
#include "common/core/command_line.hpp"
#include "common/core/version.hpp"
#include "common/device/sim_device.hpp"
#include "common/device/sim_device_axes.hpp"
#include "common/device/usb_device.hpp"
#include "common/runtime/node_app.hpp"
#include "common/runtime/service_notify.hpp"
#include "common/stability/analyzer.hpp"

namespace teleop::runtime {
namespace {

void usage(std::ostream& os, const char* name) {
  os << "usage: " << name << " CONFIG [--set PATH=VALUE]...\n\n"
     << "Runs this side of the teleoperator described by CONFIG (a SystemConfig in protobuf text\n"
        "format): its device, its 1 kHz loop, its link to the peer and its command and telemetry\n"
        "endpoints. Stops on SIGINT/SIGTERM or a shutdown command.\n\n"
        "options:\n"
        "  --set PATH=VALUE  override one field of CONFIG (repeatable, each path once)\n"
        "  --version         print the version and exit\n"
        "  -h, --help        this text\n\n"
        "An option's value may also follow an '=' (--set=PATH=VALUE).\n";
}

// Builds the device the configuration names; configure() and activate() errors name it.
std::unique_ptr<device::HapticDevice> open_device(const config::NodeSetup& setup) {
  device::MakeDeviceResult made =
      device::make_device(setup.device_kind, setup.sim, config::usb_device_config(setup.usb));
  if (!made.status.ok() || !made.device) {
    throw std::runtime_error(std::string("device: ") + made.status.message);
  }
  if (const device::Status s = made.device->configure(); !s.ok()) {
    throw std::runtime_error(std::string("device: ") + s.message);
  }
  if (const device::Status s = made.device->activate(); !s.ok()) {
    throw std::runtime_error(std::string("device: ") + s.message);
  }
  return std::move(made.device);
}

// docs/nodes.md "Before engage": the node's own stability analysis of its configuration, here at
// start (never on the RT thread, which only reads the outcome). A failed one refuses arm and
// engage unless experiment.allow_unstable is set, which is then said loudly.
// With n > 1 axes the same check of the n-axis loop (check_configuration_axes), into the n-axis
// core's settings.
void apply_check(const config::ConfigurationCheck& c, config::NodeSetup& setup) {
  const std::string refusal = c.permits_coupling ? std::string() : "arm and engage " + c.refusal;
  setup.settings.permits_coupling = c.permits_coupling;
  setup.settings.coupling_refusal = refusal;
  setup.axes_settings.permits_coupling = c.permits_coupling;
  setup.axes_settings.coupling_refusal = refusal;
  setup.check = c;
  spdlog::info(
      "configuration fingerprint {}; own analysis at {} sample(s) of round trip: {} "
      "(least damping ratio {:.4f}, required {:.4f})",
      config::fingerprint_hex(setup.settings.config_fingerprint), c.round_trip_samples, c.verdict,
      c.min_damping_ratio, c.required_damping_ratio);
  if (!c.permits_coupling) {
    spdlog::warn("{}", setup.settings.coupling_refusal);
  } else if (c.allow_unstable) {
    spdlog::warn(
        "EXPERIMENT: experiment.allow_unstable is set: this node arms a configuration "
        "its analysis calls {} (least damping ratio {:.4f})",
        c.verdict, c.min_damping_ratio);
  }
}

void apply_configuration_check(const config::CompiledSystem& system, config::NodeSetup& setup) {
  apply_check(config::check_configuration(system.teleop(), system.allow_unstable()), setup);
}

// A configuration with axes > 1: its setup and the n-axis node, after its own analysis of the
// n-axis loop (as apply_configuration_check for one axis: an unstable or invalid loop refuses
// arm and engage unless experiment.allow_unstable).
std::unique_ptr<NodeApp> make_axes_node(const config::LoadedConfig& loaded, transport::Role role) {
  config::NodeSetup setup = config::to_node_axes_setup(loaded, role);
  setup.settings.session_id = random_session_id();
  spdlog::info("{} task-space axes", setup.axes);
  apply_check(config::check_configuration_axes(config::to_axes_params(loaded),
                                               loaded.config.experiment().allow_unstable()),
              setup);
  auto device = open_axes_device(setup);
  return std::make_unique<NodeApp>(std::move(setup), std::move(device));
}

}  // namespace

int run_node_main(transport::Role role, int argc, char** argv) {
  const char* name = role == transport::Role::kMaster ? "teleop-master" : "teleop-slave";
  // The start-up analysis shares the machine with the peer's loop: one core.
  stability::set_analysis_threads(1);
  std::vector<std::string> args(argv + 1, argv + argc);
  std::string config_path;
  std::vector<std::string> overrides;
  try {
    cli::ArgCursor cur(args);
    while (cur.next()) {
      const std::string& a = cur.arg();
      if (a == "--help" || a == "-h") {
        usage(std::cout, name);
        return 0;
      }
      if (a == "--version") {
        std::cout << name << " " << version() << "\n";
        return 0;
      }
      if (a == "--set") {
        overrides.push_back(cur.value("--set"));
      } else if (config_path.empty() && a.rfind("-", 0) != 0) {
        config_path = a;
      } else {
        throw cli::UsageError("unexpected argument '" + a + "'");
      }
    }
  } catch (const cli::UsageError& e) {
    std::cerr << name << ": " << e.what() << "\n";
    usage(std::cerr, name);
    return 2;
  }
  if (config_path.empty()) {
    usage(std::cerr, name);
    return 2;
  }
  spdlog::set_pattern(std::string("[%H:%M:%S.%e] [") + name + "] [%^%l%$] %v");

  // Signals are taken by this thread only: block them before any thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  // systemd (Type=notify): READY once the loop cycles, the watchdog fed from this thread
  // while it keeps cycling, STOPPING on the way out. A no-op without NOTIFY_SOCKET.
  ServiceNotifier notifier("RT loop");
  std::unique_ptr<NodeApp> app;
  try {
    // The file, validated once, as the whole typed system (system_compiler.hpp).
    config::LoadedConfig loaded = config::parse_config_file(config_path, overrides);
    if (config::configured_axes(loaded.config) > 1) {
      app = make_axes_node(loaded, role);
    } else {
      const config::CompiledSystem system = config::compile_system(std::move(loaded));
      config::NodeSetup setup = system.node(role);
      setup.settings.session_id = random_session_id();
      apply_configuration_check(system, setup);
      app = std::make_unique<NodeApp>(setup, open_device(setup));
    }
    app->start();
  } catch (const config::ConfigError& e) {
    std::cerr << name << ": invalid configuration:\n" << e.what() << "\n";
    notifier.status(std::string("invalid configuration: ") + e.what());
    return 1;
  } catch (const std::exception& e) {
    std::cerr << name << ": " << e.what() << "\n";
    notifier.status(std::string("failed to start: ") + e.what());
    return 1;
  }
  const config::NodeSetup& s = app->setup();
  spdlog::info("session {:016x}: state {} (peer {}), commands {}, telemetry {}, {:.0f} Hz",
               app->session_id(), s.endpoints.state, s.endpoints.peer_state, s.endpoints.command,
               s.endpoints.telemetry, 1e9 / static_cast<double>(s.settings.period.count()));
  bool ready = false;
  std::string stopping = "shutdown command: stopping";
  while (!app->shutdown_requested()) {
    const std::uint64_t cycles = app->loop_cycles();
    if (!ready && cycles > 0) {
      notifier.ready(fmt::format(
          "{} loop at {:.0f} Hz, session {:016x}, commands on {}{}", name,
          1e9 / static_cast<double>(s.settings.period.count()), app->session_id(),
          s.endpoints.command,
          app->refused().empty()
              ? std::string()
              : fmt::format(", {} RT settings refused (see the log)", app->refused().size())));
      ready = true;
    }
    // Until the loop's first cycle, look again soon; then as the watchdog needs (<= 100 ms).
    const std::chrono::nanoseconds wait =
        ready ? notifier.heartbeat(cycles) : std::chrono::nanoseconds(5'000'000);
    const timespec poll{static_cast<time_t>(wait.count() / 1'000'000'000),
                        static_cast<long>(wait.count() % 1'000'000'000)};
    const int sig = sigtimedwait(&signals, nullptr, &poll);
    if (sig == SIGINT || sig == SIGTERM) {
      spdlog::info("signal {}: stopping", sig);
      stopping = fmt::format("signal {}: stopping", sig);
      break;
    }
  }
  notifier.stopping(stopping);
  app->stop();
  spdlog::info("stopped");
  return 0;
}

}  // namespace teleop::runtime
