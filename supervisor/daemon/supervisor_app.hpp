// teleop-supervisor: the sockets (the nodes' telemetry, the report publisher, the request
// endpoint, the node command clients) and the main loop around SupervisorCore
// (supervisor/core/supervisor_core.hpp), which decides everything the supervisor does.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "supervisor/core/supervisor_core.hpp"

namespace teleop::supervisor {

class SupervisorApp {
 public:
  // The system validated once (common/config/system_compiler.hpp).
  SupervisorApp(config::CompiledSystem system, SupervisorOptions options);
  // compile_system(config), then as above; a file of several axes (axes: n > 1) is supervised
  // as n axes (supervisor/core/axes_supervision.hpp).
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
