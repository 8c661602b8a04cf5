// teleop-supervisor (issue 5): subscribes to both nodes' telemetry, analyses the running
// configuration with what the nodes really run (measured rate and round trip, parameters in
// force), publishes StabilityReports and Alarms, guards parameter changes (analysed first,
// applied by both nodes at an agreed master sequence, ramped), watches heartbeats, overruns,
// loss, oscillation and passivity, escalates (warn -> lower the fixture stiffness within the
// guard -> disengage both nodes), and records the session.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/record/session.hpp"

namespace teleop::supervisor {

struct SupervisorOptions {
  std::unique_ptr<record::SessionSink> sink{};  // none: no recording
  // Starts a new session file on request (a console's "start recording"); none: refused.
  std::function<std::unique_ptr<record::SessionSink>()> new_sink{};
  std::string record_dir{};
  std::string log_file{};  // rotating log file; empty: terminal only
  // Recording was asked for but could not start (e.g. a read-only record directory): why.
  // The supervisor then supervises without recording and raises a CRITICAL alarm at start.
  std::string record_failure{};
};

class SupervisorApp {
 public:
  SupervisorApp(const config::LoadedConfig& config, SupervisorOptions options);
  ~SupervisorApp();
  SupervisorApp(const SupervisorApp&) = delete;
  SupervisorApp& operator=(const SupervisorApp&) = delete;

  // Runs until `stop` is set. Throws on a socket or key error at start.
  void run(const std::atomic<bool>& stop);
  // The main loop's heartbeat for the systemd watchdog: its iterations so far (0 until its
  // endpoints are bound and it runs). Any thread.
  [[nodiscard]] std::uint64_t loop_iterations() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// main() of teleop-supervisor: `teleop-supervisor CONFIG [--set PATH=VALUE]... [--no-record]
// [--record-dir DIR]`. Runs until SIGINT/SIGTERM.
int run_supervisor_main(int argc, char** argv);

}  // namespace teleop::supervisor
