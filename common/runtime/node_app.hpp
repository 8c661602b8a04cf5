// A node process (teleop-master, teleop-slave): the RT loop around NodeCore and the threads that
// keep sockets, protobuf and logging off it (docs/architecture.md §4.2; issue 4):
//  - loop:      PeriodicLoop at sample_rate_hz running NodeCore::step (RT settings applied);
//  - sender (run_state_sender): woken by the loop each cycle, encodes the newest own state and
//    publishes it;
//  - receiver (run_peer_receiver): takes the newest peer state (conflated), drops and counts
//    bad ones, hands the good ones to the loop with their arrival time;
//  - commands (run_command_server): the command endpoint (arm, engage, ..., e-stop, status);
//    replies once the loop has applied the command;
//  - telemetry (run_telemetry_publisher): every cycle's record, batched at telemetry_rate_hz,
//    with loop and link stats.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "common/config/node_loader.hpp"
#include "common/device/haptic_device.hpp"
#include "common/device/haptic_device_axes.hpp"
#include "common/device/usb_device_axes.hpp"
#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"
#include "common/rt/periodic_loop.hpp"

namespace teleop::v1 {
class NodeCommand;
class NodeCommandReply;
}  // namespace teleop::v1

namespace teleop::runtime {

struct NodeAppOptions {
  // Called on the RT thread after every step (tests count the loop's allocations with it).
  std::function<void()> after_step{};
};

// One axis (setup.axes == 1) runs NodeCore on a HapticDevice; several (setup.axes > 1,
// config::to_node_axes_setup) run NodeCoreAxes on a HapticDeviceAxes with the same threads
// (each thread's body is a template over the core; docs/nodes.md "n axes live").
class NodeApp {
 public:
  // Takes a configured, activated device. Throws on bad settings.
  NodeApp(config::NodeSetup setup, std::unique_ptr<device::HapticDevice> device,
          NodeAppOptions options = {});
  // n axes: setup.axes_settings (role, period, session and fingerprint taken from
  // setup.settings) on a configured, activated device of setup.axes axes.
  NodeApp(config::NodeSetup setup, std::unique_ptr<device::HapticDeviceAxes> device,
          NodeAppOptions options = {});
  ~NodeApp();
  NodeApp(const NodeApp&) = delete;
  NodeApp& operator=(const NodeApp&) = delete;

  // Binds and connects every socket, starts the threads and the loop. Throws (naming the
  // endpoint or the refused RT setting) when it cannot.
  void start();
  // Stops the loop first (the device goes to 0 N), then the threads. Idempotent.
  void stop();

  // The one-axis core (setup.axes == 1 only).
  [[nodiscard]] node::NodeCore& core() noexcept { return *core_; }
  // The n-axis core (nullptr with one axis).
  [[nodiscard]] node::NodeCoreAxes* axes_core() noexcept { return axes_core_.get(); }
  [[nodiscard]] int axes() const noexcept { return axes_core_ ? axes_core_->axes() : 1; }
  [[nodiscard]] const config::NodeSetup& setup() const noexcept { return setup_; }
  [[nodiscard]] std::uint64_t session_id() const noexcept { return setup_.settings.session_id; }
  // RT settings the kernel refused (after start()).
  [[nodiscard]] const std::vector<std::string>& refused() const noexcept { return refused_; }
  // The RT loop's heartbeat: its cycles so far (modulo 2^32), read by the systemd watchdog
  // thread. One atomic load.
  [[nodiscard]] std::uint64_t loop_cycles() const noexcept {
    return (core_ ? core_->state_published() : axes_core_->state_published())
        .load(std::memory_order_acquire);
  }
  // Set when a SHUTDOWN command arrived.
  [[nodiscard]] bool shutdown_requested() const noexcept { return shutdown_.load(); }

 private:
  struct Impl;
  // start(), step by step, on the caller's thread.
  void set_up_link_security();
  void set_link_thread_priority();
  void open_endpoints();
  void hold_cpu_dma_latency();
  void start_link_threads();
  void start_loop();
  // The link threads: each function is the whole body of the thread it names (started by
  // start_link_threads(), run again if it throws, ended by stop()).
  void run_state_sender();         // thread "sender"
  void run_peer_receiver();        // thread "receiver"
  void run_command_server();       // thread "commands"
  void run_telemetry_publisher();  // thread "telemetry"
  // On the sender's and the receiver's thread: the priority set_link_thread_priority() chose.
  void apply_link_thread_priority() const;
  // The thread bodies for either core (node_app.cpp).
  template <class Core>
  void send_states(Core& core);
  template <class Core>
  void receive_states(Core& core);
  template <class Core>
  void serve_commands(Core& core);
  template <class Core>
  void publish_telemetry(Core& core);
  // On the command server's thread: the answer to a well-formed, authorised command.
  template <class Core>
  void answer_command(Core& core, const v1::NodeCommand& cmd, v1::NodeCommandReply& reply);
  config::NodeSetup setup_;
  std::unique_ptr<device::HapticDevice> device_;
  std::unique_ptr<device::HapticDeviceAxes> axes_device_;
  NodeAppOptions options_;
  std::unique_ptr<node::NodeCore> core_;
  std::unique_ptr<node::NodeCoreAxes> axes_core_;
  std::unique_ptr<Impl> impl_;
  std::vector<std::string> refused_{};
  std::atomic<bool> shutdown_{false};
};

// The n-axis device a setup names (docs/nodes.md "n axes live"), configured and activated:
// a SimDeviceAxes (device_kind kSim) or a UsbDeviceAxes over open_usb (kUsb; the node: libusb,
// the tests: the emulator's in-memory link). Throws std::runtime_error "device: ..." with the
// device's own message when it cannot configure or activate.
[[nodiscard]] std::unique_ptr<device::HapticDeviceAxes> open_axes_device(
    const config::NodeSetup& setup,
    const device::UsbDeviceAxes::TransportFactory& open_usb = device::open_usb_transport);

// main() of teleop-master / teleop-slave: `NAME CONFIG [--set PATH=VALUE]...`. Runs until
// SIGINT/SIGTERM or a SHUTDOWN command; returns the exit code (1: configuration, device or
// endpoint error, with the reason on stderr).
int run_node_main(transport::Role role, int argc, char** argv);

// A random non-zero 64-bit session id (getrandom).
[[nodiscard]] std::uint64_t random_session_id();

}  // namespace teleop::runtime
