// A node's part of the one SystemConfig (issue 4 "Launch"): its law and timing, its device,
// endpoints, keys and real-time settings. The supervisor reads the same file.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/control_fingerprint.hpp"
#include "common/core/defaults.hpp"
#include "common/device/haptic_device.hpp"
#include "common/device/sim_device.hpp"
#include "common/device/sim_device_axes.hpp"
#include "common/device/usb_device_axes.hpp"
#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"
#include "common/rt/periodic_loop.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::config {

struct NodeEndpoints {
  std::string state{};       // this node's NodeState publisher (binds)
  std::string peer_state{};  // the peer's (connects)
  std::string command{};
  std::string telemetry{};
};

struct NodeKeys {
  bool insecure{false};
  std::string secret_key_file{};  // this node's; empty: none given
  std::string own_public_key{};   // security.<role>_public_key, checked against the secret key
  std::string peer_public_key{};  // the peer's, to connect to its publisher
  std::vector<std::string> allowed_client_keys{};  // the peer's plus security.client_public_keys
  // Who may do what on the command endpoint (runtime/command_authority.hpp): the supervisor's
  // key alone may RETUNE; read-only keys may only e-stop and ask for status.
  std::string supervisor_public_key{};               // security.supervisor_public_key
  std::vector<std::string> read_only_client_keys{};  // security.read_only_client_public_keys
  bool allow_unauthenticated_retune{false};          // security.allow_unauthenticated_retune
};

struct UsbIds {
  std::uint32_t vendor_id{defaults::kUsbVendorId};
  std::uint32_t product_id{defaults::kUsbProductId};
  double watchdog_ms{static_cast<double>(defaults::kUsbWatchdog.count())};
};

struct NodeSetup {
  node::NodeSettings settings{};  // session_id left for the process to draw
  device::DeviceKind device_kind{device::DeviceKind::kSim};
  device::SimDeviceConfig sim{};  // the simulated device, with its human or environment
  UsbIds usb{};
  NodeEndpoints endpoints{};
  NodeKeys keys{};
  // The loop thread's real-time settings as a configuration asks by default (a bare
  // rt::RtSettings{} leaves the scheduler and memory alone).
  rt::RtSettings rt{defaults::kFifoPriority, defaults::kLockMemory, -1, false};
  int cpu_dma_latency_us{defaults::kCpuDmaLatency_us};  // -1: leave alone
  double telemetry_rate_hz{defaults::kTelemetryRate_hz};
  // The node's own check of its configuration at start (control_fingerprint.hpp), filled by
  // the node process; reported in telemetry.
  std::optional<ConfigurationCheck> check{};
  // SystemConfig.axes. With axes > 1 (to_node_axes_setup) the node runs NodeCoreAxes on a
  // SimDeviceAxes (device_kind kSim) or a UsbDeviceAxes (kUsb): axes_settings holds its law,
  // sim_axes or usb_axes its device; `settings` keeps the role, period, link timing, alignment,
  // session and fingerprint (the same values as axes_settings) and its one-axis law and `sim`
  // are unused.
  int axes{1};
  node::NodeAxesSettings axes_settings{};
  device::SimDeviceAxesConfig sim_axes{};
  device::UsbDeviceAxesConfig usb_axes{};
};

// The USB link's settings of node.usb (ids and watchdog; the paddle's scaling), for either
// device.
[[nodiscard]] device::UsbDeviceConfig usb_device_config(const UsbIds& ids);

// Default endpoints (loopback): master state 5560, slave state 5561, commands 5562/5563,
// telemetry 5564/5565.
[[nodiscard]] NodeEndpoints default_endpoints(transport::Role role);

// One node's part of compile_system(config) (system_compiler.hpp), which validates the whole
// file once: `compile_system(config).node(role)`. For tools that need one node's endpoints; a
// process that runs the system takes it from compile_system. With axes > 1 it is
// to_node_axes_setup (below). Throws ConfigError naming the field.
[[nodiscard]] NodeSetup to_node_setup(const LoadedConfig& config, transport::Role role);

// A node's setup for a configuration with axes > 1 (docs/nodes.md "n axes live"): the n-axis
// law from_teleop_axes_params(to_axes_config(config)) and a simulated SimDeviceAxes built as
// `teleopctl simulate` builds its sides for n > 1 (to_axes_scene_setup: ideal sensors, the
// devices' mass, damping and friction, the master's fixed human pushing with scene.human_force
// along scene.human_force_direction, the slave in scene.environment_plane), held until the
// node engages. Without a scene the human holds the handle without pushing (human.fixed, or
// each axis's band middle at its lowest force level) and the slave is in free space. Link,
// endpoints, keys, RT and process settings as to_node_setup; the fingerprint covers the n-axis
// control fields. A side whose device.kind is USB gets usb_axes instead (device_kind kUsb):
// version 2 with n channels, its kinematics (the five-bar's home_joint_rad at encoder count 0)
// and actuators (torque_constant_N_m_per_A or force_constant_N_per_A, amplifier_A_per_count),
// node.usb's ids and watchdog. Throws ConfigError naming the field.
[[nodiscard]] NodeSetup to_node_axes_setup(const LoadedConfig& config, transport::Role role);

// The configuration fingerprint both nodes of an n-axis file compute (to_node_axes_setup's
// settings.config_fingerprint: the n-axis control fields and the link timing), without their
// devices, endpoints or keys: what the supervisor compares each node's with. Throws ConfigError
// naming the field.
[[nodiscard]] std::uint64_t axes_control_fingerprint(const LoadedConfig& config);

}  // namespace teleop::config
