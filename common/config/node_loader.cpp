#include "common/config/node_loader.hpp"

#include <charconv>
#include <cmath>
#include <string>

#include "common/config/axes_config.hpp"
#include "common/config/axes_scene_loader.hpp"
#include "common/config/config_internal.hpp"
#include "common/config/control_fingerprint.hpp"
#include "common/config/parameter_space.hpp"
#include "common/config/system_compiler.hpp"
#include "common/control/law_axes_params.hpp"
#include "common/core/defaults.hpp"

namespace teleop::config {
namespace {

namespace v1 = teleop::v1;
using transport::Role;

class Problems {
 public:
  explicit Problems(const LoadedConfig& config) : config_(config) {}
  void add(const std::string& path, const std::string& what) {
    text_ += "\n  " + field_origin(config_, path) + ": " + path + ": " + what;
  }
  void throw_if_any() const {
    if (!text_.empty()) throw ConfigError(config_.source_name + ": invalid node settings:" + text_);
  }

 private:
  const LoadedConfig& config_;
  std::string text_{};
};

std::chrono::nanoseconds from_ms(double ms) {
  return std::chrono::nanoseconds(static_cast<long long>(std::llround(ms * 1e6)));
}

double ms(std::chrono::milliseconds d) { return static_cast<double>(d.count()); }

double value_or_default(Problems& p, const std::string& path, bool has, double value,
                        double fallback, bool allow_zero) {
  if (!has) return fallback;
  if (!(allow_zero ? value >= 0.0 : value > 0.0)) {
    p.add(path, std::string("must be ") + (allow_zero ? ">= 0" : "> 0") + ", got " +
                    std::to_string(value));
  }
  return value;
}

bool is_z85_key(const std::string& key) { return key.size() == 40; }

}  // namespace

device::UsbDeviceConfig usb_device_config(const UsbIds& ids) {
  device::UsbDeviceConfig usb;
  usb.vendor_id = static_cast<std::uint16_t>(ids.vendor_id);
  usb.product_id = static_cast<std::uint16_t>(ids.product_id);
  usb.watchdog = std::chrono::milliseconds(static_cast<long>(std::lround(ids.watchdog_ms)));
  return usb;
}

NodeEndpoints default_endpoints(Role role) {
  const bool master = role == Role::kMaster;
  NodeEndpoints e;
  // The shipped defaults (defaults.hpp; the parameter space checks them for clashes).
  e.state = master ? defaults::kMasterStateEndpoint : defaults::kSlaveStateEndpoint;
  e.peer_state = master ? defaults::kSlaveStateEndpoint : defaults::kMasterStateEndpoint;
  e.command = master ? defaults::kMasterCommandEndpoint : defaults::kSlaveCommandEndpoint;
  e.telemetry = master ? defaults::kMasterTelemetryEndpoint : defaults::kSlaveTelemetryEndpoint;
  return e;
}

namespace {

// The link's timing and the alignment (link.*), defaults filled in.
void link_settings(Problems& p, const v1::Link& link, double rate_hz, node::NodeSettings& out) {
  const double timeout_ms =
      value_or_default(p, "link.peer_timeout_ms", link.has_peer_timeout_ms(),
                       link.peer_timeout_ms(), ms(defaults::kPeerTimeout), false);
  const double safe_ms = value_or_default(p, "link.safe_ramp_ms", link.has_safe_ramp_ms(),
                                          link.safe_ramp_ms(), ms(defaults::kSafeRamp), true);
  const double engage_ms = value_or_default(p, "link.engage_ramp_ms", link.has_engage_ramp_ms(),
                                            link.engage_ramp_ms(), ms(defaults::kEngageRamp), true);
  // Times a node can hold in integer nanoseconds and a loop can keep: a peer timeout of at
  // least one period and at most a minute; ramps of at most a minute.
  const double period_ms = 1e3 / rate_hz;
  if (link.has_peer_timeout_ms() && timeout_ms > 0.0 &&
      !(timeout_ms >= period_ms && timeout_ms <= 60000.0)) {
    p.add("link.peer_timeout_ms", "must be in [one period (" + std::to_string(period_ms) +
                                      " ms), 60000], got " + std::to_string(timeout_ms));
  }
  if (engage_ms > 60000.0) {
    p.add("link.engage_ramp_ms", "must be <= 60000, got " + std::to_string(engage_ms));
  }
  out.machine.peer_timeout = from_ms(timeout_ms);
  out.machine.engage_ramp = from_ms(engage_ms);
  out.safe_ramp = from_ms(safe_ms);
  node::AlignmentParams& a = out.alignment;
  a.tolerance_m =
      value_or_default(p, "link.alignment_tolerance_m", link.has_alignment_tolerance_m(),
                       link.alignment_tolerance_m(), defaults::kAlignmentTolerance_m, false);
  a.centring_stiffness_N_per_m = value_or_default(
      p, "link.centring_stiffness_N_per_m", link.has_centring_stiffness_n_per_m(),
      link.centring_stiffness_n_per_m(), defaults::kCentringStiffness_N_per_m, true);
  a.centring_damping_Ns_per_m =
      value_or_default(p, "link.centring_damping_Ns_per_m", link.has_centring_damping_ns_per_m(),
                       link.centring_damping_ns_per_m(), defaults::kCentringDamping_Ns_per_m, true);
  a.centring_max_force_N =
      value_or_default(p, "link.centring_max_force_N", link.has_centring_max_force_n(),
                       link.centring_max_force_n(), defaults::kCentringMaxForce_N, true);
  // A safe ramp longer than the whole link budget would leave force on a dead link.
  if (safe_ms > 1000.0) p.add("link.safe_ramp_ms", "must be <= 1000");
}

NodeEndpoints node_endpoints(const v1::Side& own, const v1::Side& other, Role role) {
  const NodeEndpoints defaults = default_endpoints(role);
  const v1::Node& node = own.node();
  NodeEndpoints out;
  out.state = node.state_endpoint().empty() ? defaults.state : node.state_endpoint();
  out.peer_state = !node.peer_state_endpoint().empty()
                       ? node.peer_state_endpoint()
                       : (other.node().state_endpoint().empty() ? defaults.peer_state
                                                                : other.node().state_endpoint());
  out.command = node.command_endpoint().empty() ? defaults.command : node.command_endpoint();
  out.telemetry =
      node.telemetry_endpoint().empty() ? defaults.telemetry : node.telemetry_endpoint();
  return out;
}

// The node process's own settings: telemetry rate, real-time settings, USB ids.
void process_settings(Problems& p, const std::string& side, const v1::Node& node, NodeSetup& out) {
  if (node.has_telemetry_rate_hz()) {
    const double r = node.telemetry_rate_hz();
    if (!(r > 0.0 && r <= 1000.0)) {
      p.add(side + ".node.telemetry_rate_hz", "must be in (0, 1000], got " + std::to_string(r));
    }
    out.telemetry_rate_hz = r;
  }

  const v1::RealTime& rt = node.rt();
  out.rt.fifo_priority = rt.has_fifo_priority() ? rt.fifo_priority() : defaults::kFifoPriority;
  if (out.rt.fifo_priority < 0 || out.rt.fifo_priority > 99) {
    p.add(side + ".node.rt.fifo_priority",
          "must be in [0, 99], got " + std::to_string(out.rt.fifo_priority));
  }
  out.rt.lock_memory = rt.has_lock_memory() ? rt.lock_memory() : defaults::kLockMemory;
  out.rt.cpu = rt.has_cpu() ? rt.cpu() : -1;
  if (rt.has_cpu() && rt.cpu() < 0) {
    p.add(side + ".node.rt.cpu", "must be >= 0, got " + std::to_string(rt.cpu()));
  }
  out.rt.required = rt.required();
  out.cpu_dma_latency_us =
      rt.has_cpu_dma_latency_us() ? rt.cpu_dma_latency_us() : defaults::kCpuDmaLatency_us;
  if (out.cpu_dma_latency_us < -1) {
    p.add(side + ".node.rt.cpu_dma_latency_us",
          "must be >= 0 (or -1: leave alone), got " + std::to_string(out.cpu_dma_latency_us));
  }

  if (node.has_usb()) {
    if (node.usb().has_vendor_id()) out.usb.vendor_id = node.usb().vendor_id();
    if (node.usb().has_product_id()) out.usb.product_id = node.usb().product_id();
    if (node.usb().has_watchdog_ms()) out.usb.watchdog_ms = node.usb().watchdog_ms();
    if (out.usb.vendor_id > 0xFFFF) p.add(side + ".node.usb.vendor_id", "must fit 16 bits");
    if (out.usb.product_id > 0xFFFF) p.add(side + ".node.usb.product_id", "must fit 16 bits");
    if (!(out.usb.watchdog_ms >= 1.0 && out.usb.watchdog_ms <= 1000.0)) {
      p.add(side + ".node.usb.watchdog_ms", "must be in [1, 1000]");
    }
  }
}

NodeKeys node_keys(Problems& p, const v1::Security& sec, const v1::Node& node, bool master) {
  NodeKeys keys;
  keys.insecure = sec.insecure();
  keys.secret_key_file = node.secret_key_file();
  keys.own_public_key = master ? sec.master_public_key() : sec.slave_public_key();
  keys.peer_public_key = master ? sec.slave_public_key() : sec.master_public_key();
  auto check_key = [&](const std::string& path, const std::string& key) {
    if (!key.empty() && !is_z85_key(key)) {
      p.add(path, "must be a 40-character Z85 CURVE public key (teleopctl keygen), got " +
                      std::to_string(key.size()) + " characters");
    }
  };
  check_key("security.master_public_key", sec.master_public_key());
  check_key("security.slave_public_key", sec.slave_public_key());
  if (!keys.peer_public_key.empty()) keys.allowed_client_keys.push_back(keys.peer_public_key);
  for (int i = 0; i < sec.client_public_keys_size(); ++i) {
    check_key("security.client_public_keys[" + std::to_string(i) + "]", sec.client_public_keys(i));
    keys.allowed_client_keys.push_back(sec.client_public_keys(i));
  }
  check_key("security.supervisor_public_key", sec.supervisor_public_key());
  keys.supervisor_public_key = sec.supervisor_public_key();
  for (int i = 0; i < sec.read_only_client_public_keys_size(); ++i) {
    check_key("security.read_only_client_public_keys[" + std::to_string(i) + "]",
              sec.read_only_client_public_keys(i));
    keys.read_only_client_keys.push_back(sec.read_only_client_public_keys(i));
  }
  keys.allow_unauthenticated_retune = sec.allow_unauthenticated_retune();
  return keys;
}

}  // namespace

NodeSetup node_setup_of_validated(const LoadedConfig& config, const TeleopParams& teleop,
                                  const SimulatedSides& sides, Role role) {
  const bool master = role == Role::kMaster;
  const v1::SystemConfig& c = config.config;

  NodeSetup out;
  const double rate_hz = teleop.sample_rate_hz;
  // A node's loop: 1 Hz to 100 kHz (the analyser's range; its period in whole nanoseconds).
  if (!(rate_hz >= 1.0 && rate_hz <= 100000.0)) {
    throw ConfigError(config.source_name +
                      ": sample_rate_hz: a node runs at 1 Hz to 100 kHz, got " +
                      std::to_string(rate_hz));
  }
  out.settings.role = role;
  out.settings.period =
      std::chrono::nanoseconds(static_cast<long long>(std::llround(1e9 / rate_hz)));
  out.settings.law = sides.law;
  out.sim = master ? sides.master : sides.slave;
  out.sim.period = out.settings.period;
  out.sim.hold_scene_until_engaged = true;

  Problems p(config);
  link_settings(p, c.link(), rate_hz, out.settings);
  const v1::Side& own = master ? c.master() : c.slave();
  const v1::Side& other = master ? c.slave() : c.master();
  out.device_kind =
      own.device().kind() == v1::USB ? device::DeviceKind::kUsb : device::DeviceKind::kSim;
  out.endpoints = node_endpoints(own, other, role);
  process_settings(p, master ? "master" : "slave", own.node(), out);
  out.keys = node_keys(p, c.security(), own.node(), master);
  p.throw_if_any();
  // docs/nodes.md "Before engage": what the peer and the supervisor compare before coupling.
  out.settings.config_fingerprint =
      fingerprint(control_fields(teleop, out.settings, c.experiment().allow_unstable()));
  return out;
}

NodeSetup to_node_setup(const LoadedConfig& config, Role role) {
  if (role != Role::kMaster && role != Role::kSlave) {
    throw ConfigError("node role must be master or slave");
  }
  // Several axes: the n-axis setup, so every tool that asks for a node's endpoints (launch,
  // console, status, bridge) gets them from the same function for any n.
  if (configured_axes(config.config) > 1) return to_node_axes_setup(config, role);
  return compile_system(config).node(role);
}

namespace {

// --- axes > 1 --------------------------------------------------------------------------------

// A double in the shortest text that reads back to it (control_fingerprint.hpp's canonical
// form; -0 as 0).
std::string canonical(double v) {
  if (v == 0.0) v = 0.0;
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

class AxesFields {
 public:
  void add(const std::string& path, double v) { fields_.push_back({path, canonical(v)}); }
  void add(const std::string& path, const Eigen::MatrixXd& m) {
    add(path + ".rows", static_cast<double>(m.rows()));
    add(path + ".cols", static_cast<double>(m.cols()));
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      for (Eigen::Index j = 0; j < m.cols(); ++j) {
        add(path + "[" + std::to_string(i) + "][" + std::to_string(j) + "]", m(i, j));
      }
    }
  }
  void add(const std::string& path, const std::vector<PlaneFixtureParams>& planes) {
    add(path + ".count", static_cast<double>(planes.size()));
    for (std::size_t k = 0; k < planes.size(); ++k) {
      const std::string q = path + "[" + std::to_string(k) + "]";
      add(q + ".normal", Eigen::MatrixXd(planes[k].normal));
      add(q + ".offset_m", planes[k].offset_m);
      add(q + ".stiffness_N_per_m", planes[k].stiffness_N_per_m);
    }
  }
  void add(const std::string& path, const ParameterBand& b) {
    add(path + ".lower.intercept", b.lower.intercept);
    add(path + ".lower.slope_per_N", b.lower.slope_per_N);
    add(path + ".upper.intercept", b.upper.intercept);
    add(path + ".upper.slope_per_N", b.upper.slope_per_N);
  }
  [[nodiscard]] const std::vector<ControlField>& fields() const { return fields_; }

 private:
  std::vector<ControlField> fields_{};
};

void add_human_fields(AxesFields& f, const HumanModelAxes& h) {
  f.add("human.kind", static_cast<double>(static_cast<int>(h.kind)));
  if (h.kind == HumanKind::kFixed) {
    f.add("human.fixed.mass_kg", h.fixed.mass_kg);
    f.add("human.fixed.damping_Ns_per_m", h.fixed.damping_Ns_per_m);
    f.add("human.fixed.stiffness_N_per_m", h.fixed.stiffness_N_per_m);
  }
  for (std::size_t i = 0; i < h.band_per_axis.size(); ++i) {
    const HumanBand& b = h.band_per_axis[i];
    const std::string q = "human.band_per_axis[" + std::to_string(i) + "]";
    for (std::size_t k = 0; k < b.force_levels_N.size(); ++k) {
      f.add(q + ".force_levels_N[" + std::to_string(k) + "]", b.force_levels_N[k]);
    }
    f.add(q + ".points_per_axis", b.points_per_axis);
    f.add(q + ".mass_kg", b.mass_kg);
    f.add(q + ".damping_Ns_per_m", b.damping_Ns_per_m);
    f.add(q + ".stiffness_N_per_m", b.stiffness_N_per_m);
  }
}

// The n-axis control-relevant values (control_fingerprint.hpp's set, as matrices and planes):
// both nodes of one file compute the same, a change of any of them another.
std::vector<ControlField> axes_control_fields(const AxesConfig& a, const node::NodeSettings& s,
                                              bool allow_unstable) {
  const TeleopAxesParams& t = a.teleop;
  AxesFields f;
  f.add("axes", t.axes);
  f.add("sample_rate_hz", t.sample_rate_hz);
  f.add("master.device.mass_kg", t.master_device.mass_kg);
  f.add("master.device.damping_Ns_per_m", Eigen::MatrixXd(t.master_device.damping_Ns_per_m));
  f.add("slave.device.mass_kg", t.slave_device.mass_kg);
  f.add("slave.device.damping_Ns_per_m", Eigen::MatrixXd(t.slave_device.damping_Ns_per_m));
  f.add("master.kinematics", static_cast<double>(static_cast<int>(a.master_kinematics.kind)));
  f.add("slave.kinematics", static_cast<double>(static_cast<int>(a.slave_kinematics.kind)));
  f.add("master.fixture.plane", t.master_planes);
  f.add("slave.fixture.plane", t.slave_planes);
  f.add("gains.kpm", t.gains.kpm);
  f.add("gains.kps", t.gains.kps);
  f.add("gains.kdm", t.gains.kdm);
  f.add("gains.kds", t.gains.kds);
  f.add("gains.kvm", t.gains.kvm);
  f.add("gains.kvs", t.gains.kvs);
  f.add("gains.kfm", t.gains.kfm);
  f.add("scaling.position", t.scaling.position);
  f.add("scaling.force", t.scaling.force);
  f.add("velocity_filter.cutoff_hz", t.velocity_cutoff_hz);
  f.add("round_trip_delay_samples", t.round_trip_delay_samples);
  add_human_fields(f, t.human);
  f.add("analysis.required_damping_ratio", t.analysis.required_damping_ratio);
  f.add("analysis.stiffness_tolerance_N_per_m", t.analysis.stiffness_tolerance_N_per_m);
  f.add("link.peer_timeout_ns", static_cast<double>(s.machine.peer_timeout.count()));
  f.add("link.engage_ramp_ns", static_cast<double>(s.machine.engage_ramp.count()));
  f.add("link.safe_ramp_ns", static_cast<double>(s.safe_ramp.count()));
  f.add("link.alignment_tolerance_m", s.alignment.tolerance_m);
  f.add("link.centring_stiffness_N_per_m", s.alignment.centring_stiffness_N_per_m);
  f.add("link.centring_damping_Ns_per_m", s.alignment.centring_damping_Ns_per_m);
  f.add("link.centring_max_force_N", s.alignment.centring_max_force_N);
  f.add("experiment.allow_unstable", allow_unstable ? 1.0 : 0.0);
  return f.fields();
}

// The human a node's simulated master holds without a scene: human.fixed, or each axis's band
// middle at its lowest force level (as the one-axis node's, simulated_sides.cpp).
HumanImpedanceAxes holding_human(const HumanModelAxes& h, int n) {
  if (h.kind == HumanKind::kFixed) return h.fixed;
  HumanImpedanceAxes out;
  if (h.kind != HumanKind::kBand || static_cast<int>(h.band_per_axis.size()) != n) return out;
  out.mass_kg = Eigen::MatrixXd::Zero(n, n);
  out.damping_Ns_per_m = Eigen::MatrixXd::Zero(n, n);
  out.stiffness_N_per_m = Eigen::MatrixXd::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    const HumanBand& b = h.band_per_axis[static_cast<std::size_t>(i)];
    const double f = b.force_levels_N.empty() ? 0.0 : b.force_levels_N.front();
    auto mid = [f](const ParameterBand& p) { return 0.5 * (p.lower.at(f) + p.upper.at(f)); };
    out.mass_kg(i, i) = mid(b.mass_kg);
    out.damping_Ns_per_m(i, i) = mid(b.damping_Ns_per_m);
    out.stiffness_N_per_m(i, i) = mid(b.stiffness_N_per_m);
  }
  return out;
}

// One side's simulated device with the lockstep simulator's ideal sensors (lockstep_axes.hpp).
device::SimDeviceAxesConfig ideal_device(const DeviceAxesParams& d, const KinematicsConfig& k,
                                         std::chrono::nanoseconds period) {
  device::SimDeviceAxesConfig c;
  c.period = period;
  c.plant.device = d;
  c.kinematics = k.kind == KinematicsConfig::Kind::kFiveBar ? device::DeviceKinematics::kFiveBar
                                                            : device::DeviceKinematics::kCartesian;
  c.five_bar = k.five_bar;
  c.five_bar_home_m = k.home_end_m;
  c.quantize_position = false;
  c.load_cell.noise_std_N = 0.0;
  c.load_cell.bias_N = 0.0;
  c.load_cell.range_N = 1e12;
  c.amplifier.max_force_N = 1e12;
  c.hold_scene_until_engaged = true;
  return c;
}

// One side's USB device (version 2, n channels): node.usb's link, the side's kinematics and
// actuators.
device::UsbDeviceAxesConfig usb_device(const UsbIds& ids, int n, const KinematicsConfig& k,
                                       const std::vector<ActuatorGains>& actuators) {
  device::UsbDeviceAxesConfig c;
  c.link = usb_device_config(ids);
  c.axes = n;
  c.kinematics = k.kind == KinematicsConfig::Kind::kFiveBar ? device::DeviceKinematics::kFiveBar
                                                            : device::DeviceKinematics::kCartesian;
  c.five_bar = k.five_bar;
  c.five_bar_home_joint_rad = k.home_joint_rad;
  for (const ActuatorGains& g : actuators) {
    c.actuators.push_back({g.torque_constant_per_A, g.amplifier_A_per_count});
  }
  return c;
}

// The master's human and the slave's environment: the scene's (as `teleopctl simulate`), else
// a still hand and free space.
void fill_axes_scene(const LoadedConfig& config, const AxesConfig& axes, Role role,
                     device::SimDeviceAxesConfig& dev) {
  const int n = axes.teleop.axes;
  const bool scene = config.config.has_scene();
  scene::AxesSceneSetup setup;
  if (scene) setup = to_axes_scene_setup(config);  // names the scene's problems
  if (role == Role::kMaster) {
    device::SimHumanAxes h;
    h.impedance = holding_human(axes.teleop.human, n);
    h.direction = scene ? setup.push_direction : Eigen::VectorXd::Unit(n, 0);
    h.profile = scene ? setup.push_profile : sim::ForceProfile::constant(0.0);
    dev.human = h;
  } else if (scene) {
    dev.plant.planes = setup.slave_environment;
  }
}

}  // namespace

namespace {

// The n-axis file's node rate, checked (1 Hz to 100 kHz).
double axes_node_rate_hz(const LoadedConfig& config, const AxesConfig& axes) {
  const double rate_hz = axes.teleop.sample_rate_hz;
  if (!(rate_hz >= 1.0 && rate_hz <= 100000.0)) {
    throw ConfigError(config.source_name +
                      ": sample_rate_hz: a node runs at 1 Hz to 100 kHz, got " +
                      std::to_string(rate_hz));
  }
  return rate_hz;
}

}  // namespace

std::uint64_t axes_control_fingerprint(const LoadedConfig& config) {
  const AxesConfig axes = to_axes_config(config);
  const double rate_hz = axes_node_rate_hz(config, axes);
  node::NodeSettings settings;
  Problems p(config);
  link_settings(p, config.config.link(), rate_hz, settings);
  p.throw_if_any();
  return fingerprint(
      axes_control_fields(axes, settings, config.config.experiment().allow_unstable()));
}

NodeSetup to_node_axes_setup(const LoadedConfig& config, Role role) {
  if (role != Role::kMaster && role != Role::kSlave) {
    throw ConfigError("node role must be master or slave");
  }
  const AxesConfig axes = to_axes_config(config);  // validates, names every field
  const bool master = role == Role::kMaster;
  const v1::SystemConfig& c = config.config;
  const double rate_hz = axes_node_rate_hz(config, axes);
  NodeSetup out;
  out.axes = axes.teleop.axes;
  out.settings.role = role;
  out.settings.period =
      std::chrono::nanoseconds(static_cast<long long>(std::llround(1e9 / rate_hz)));
  Problems p(config);
  link_settings(p, c.link(), rate_hz, out.settings);
  const v1::Side& own = master ? c.master() : c.slave();
  const v1::Side& other = master ? c.slave() : c.master();
  out.device_kind =
      own.device().kind() == v1::USB ? device::DeviceKind::kUsb : device::DeviceKind::kSim;
  out.endpoints = node_endpoints(own, other, role);
  process_settings(p, master ? "master" : "slave", own.node(), out);
  out.keys = node_keys(p, c.security(), own.node(), master);
  p.throw_if_any();
  out.settings.config_fingerprint =
      fingerprint(axes_control_fields(axes, out.settings, c.experiment().allow_unstable()));

  node::NodeAxesSettings& a = out.axes_settings;
  try {
    a.law = control::from_teleop_axes_params(axes.teleop);
  } catch (const std::invalid_argument& e) {
    throw ConfigError(config.source_name + ": " + e.what());
  }
  a.role = role;
  a.period = out.settings.period;
  a.machine = out.settings.machine;
  a.safe_ramp = out.settings.safe_ramp;
  a.alignment = out.settings.alignment;
  a.config_fingerprint = out.settings.config_fingerprint;
  out.sim_axes =
      ideal_device(master ? axes.teleop.master_device : axes.teleop.slave_device,
                   master ? axes.master_kinematics : axes.slave_kinematics, out.settings.period);
  fill_axes_scene(config, axes, role, out.sim_axes);
  if (out.device_kind == device::DeviceKind::kUsb) {
    out.usb_axes =
        usb_device(out.usb, out.axes, master ? axes.master_kinematics : axes.slave_kinematics,
                   master ? axes.master_actuators : axes.slave_actuators);
  }
  return out;
}

}  // namespace teleop::config
