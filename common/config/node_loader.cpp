#include "common/config/node_loader.hpp"

#include <cmath>
#include <string>

#include "common/config/control_fingerprint.hpp"
#include "common/config/parameter_space.hpp"
#include "common/config/scene_loader.hpp"

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

NodeEndpoints default_endpoints(Role role) {
  const bool master = role == Role::kMaster;
  NodeEndpoints e;
  // The defaults of the parameter space (which checks them for clashes).
  e.state = master ? kDefaultMasterState : kDefaultSlaveState;
  e.peer_state = master ? kDefaultSlaveState : kDefaultMasterState;
  e.command = master ? kDefaultMasterCommand : kDefaultSlaveCommand;
  e.telemetry = master ? kDefaultMasterTelemetry : kDefaultSlaveTelemetry;
  return e;
}

namespace {

NodeSetup one_node_setup(const LoadedConfig& config, Role role) {
  const bool master = role == Role::kMaster;
  const std::string side = master ? "master" : "slave";
  const v1::SystemConfig& c = config.config;

  // The simulated devices and the law of the scene: the same code path as `teleopctl simulate`,
  // so a live run and a lockstep run of one file agree. Without a scene, a scene with no push in
  // free space; a band of humans holds the handle as the band's middle at its lowest force.
  LoadedConfig scene_config = config;
  v1::Scene& scene = *scene_config.config.mutable_scene();
  if (!scene.has_duration_s()) scene.set_duration_s(1.0);
  // The sides' simulated stand-ins (a USB side's simulated device is simply unused).
  scene_config.config.mutable_master()->mutable_device()->set_kind(v1::SIM);
  scene_config.config.mutable_slave()->mutable_device()->set_kind(v1::SIM);
  const TeleopParams analysed = to_teleop_params(config);
  if (analysed.human.kind == HumanKind::kBand && !scene.has_malicious_user()) {
    const HumanBand& band = analysed.human.band;
    const double f = band.force_levels_N.empty() ? 0.0 : band.force_levels_N.front();
    auto mid = [f](const ParameterBand& b) { return 0.5 * (b.lower.at(f) + b.upper.at(f)); };
    v1::HumanImpedance fixed;
    fixed.set_mass_kg(mid(band.mass_kg));
    fixed.set_damping_ns_per_m(mid(band.damping_Ns_per_m));
    fixed.set_stiffness_n_per_m(mid(band.stiffness_N_per_m));
    *scene_config.config.mutable_human()->mutable_fixed() = fixed;
  }
  if (scene.has_force_device()) {
    throw ConfigError(config.source_name +
                      ": scene.force_device: the nodes run the bilateral paddles; a force-device "
                      "scene is for `teleopctl simulate`");
  }
  const scene::SceneSetup s = to_scene_setup(scene_config);

  NodeSetup out;
  const double rate_hz = s.teleop.sample_rate_hz;
  // A node's loop: 1 Hz to 100 kHz (the analyser's range; its period in whole nanoseconds).
  if (!(rate_hz >= 1.0 && rate_hz <= 100000.0)) {
    throw ConfigError(config.source_name +
                      ": sample_rate_hz: a node runs at 1 Hz to 100 kHz, got " +
                      std::to_string(rate_hz));
  }
  out.settings.role = role;
  out.settings.period =
      std::chrono::nanoseconds(static_cast<long long>(std::llround(1e9 / rate_hz)));
  out.settings.law = s.law;
  out.sim = master ? s.master : s.slave;
  out.sim.period = out.settings.period;
  out.sim.hold_scene_until_engaged = true;
  if (s.ideal) out.sim.quantize_position = false;

  Problems p(config);
  const v1::Link& link = c.link();
  const double timeout_ms = value_or_default(p, "link.peer_timeout_ms", link.has_peer_timeout_ms(),
                                             link.peer_timeout_ms(), 30.0, false);
  const double safe_ms = value_or_default(p, "link.safe_ramp_ms", link.has_safe_ramp_ms(),
                                          link.safe_ramp_ms(), 10.0, true);
  const double engage_ms = value_or_default(p, "link.engage_ramp_ms", link.has_engage_ramp_ms(),
                                            link.engage_ramp_ms(), 200.0, true);
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
  out.settings.machine.peer_timeout = from_ms(timeout_ms);
  out.settings.machine.engage_ramp = from_ms(engage_ms);
  out.settings.safe_ramp = from_ms(safe_ms);
  node::AlignmentParams& a = out.settings.alignment;
  a.tolerance_m =
      value_or_default(p, "link.alignment_tolerance_m", link.has_alignment_tolerance_m(),
                       link.alignment_tolerance_m(), a.tolerance_m, false);
  a.centring_stiffness_N_per_m =
      value_or_default(p, "link.centring_stiffness_N_per_m", link.has_centring_stiffness_n_per_m(),
                       link.centring_stiffness_n_per_m(), a.centring_stiffness_N_per_m, true);
  a.centring_damping_Ns_per_m =
      value_or_default(p, "link.centring_damping_Ns_per_m", link.has_centring_damping_ns_per_m(),
                       link.centring_damping_ns_per_m(), a.centring_damping_Ns_per_m, true);
  a.centring_max_force_N =
      value_or_default(p, "link.centring_max_force_N", link.has_centring_max_force_n(),
                       link.centring_max_force_n(), a.centring_max_force_N, true);
  // A safe ramp longer than the whole link budget would leave force on a dead link.
  if (safe_ms > 1000.0) p.add("link.safe_ramp_ms", "must be <= 1000");

  const v1::Side& own = master ? c.master() : c.slave();
  const v1::Side& other = master ? c.slave() : c.master();
  out.device_kind =
      own.device().kind() == v1::USB ? device::DeviceKind::kUsb : device::DeviceKind::kSim;

  const NodeEndpoints defaults = default_endpoints(role);
  const v1::Node& node = own.node();
  out.endpoints.state = node.state_endpoint().empty() ? defaults.state : node.state_endpoint();
  out.endpoints.peer_state =
      !node.peer_state_endpoint().empty()
          ? node.peer_state_endpoint()
          : (other.node().state_endpoint().empty() ? defaults.peer_state
                                                   : other.node().state_endpoint());
  out.endpoints.command =
      node.command_endpoint().empty() ? defaults.command : node.command_endpoint();
  out.endpoints.telemetry =
      node.telemetry_endpoint().empty() ? defaults.telemetry : node.telemetry_endpoint();
  if (node.has_telemetry_rate_hz()) {
    const double r = node.telemetry_rate_hz();
    if (!(r > 0.0 && r <= 1000.0)) {
      p.add(side + ".node.telemetry_rate_hz", "must be in (0, 1000], got " + std::to_string(r));
    }
    out.telemetry_rate_hz = r;
  }

  const v1::RealTime& rt = node.rt();
  out.rt.fifo_priority = rt.has_fifo_priority() ? rt.fifo_priority() : 80;
  if (out.rt.fifo_priority < 0 || out.rt.fifo_priority > 99) {
    p.add(side + ".node.rt.fifo_priority",
          "must be in [0, 99], got " + std::to_string(out.rt.fifo_priority));
  }
  out.rt.lock_memory = rt.has_lock_memory() ? rt.lock_memory() : true;
  out.rt.cpu = rt.has_cpu() ? rt.cpu() : -1;
  if (rt.has_cpu() && rt.cpu() < 0) {
    p.add(side + ".node.rt.cpu", "must be >= 0, got " + std::to_string(rt.cpu()));
  }
  out.rt.required = rt.required();
  out.cpu_dma_latency_us = rt.has_cpu_dma_latency_us() ? rt.cpu_dma_latency_us() : 10;
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

  const v1::Security& sec = c.security();
  out.keys.insecure = sec.insecure();
  out.keys.secret_key_file = node.secret_key_file();
  out.keys.own_public_key = master ? sec.master_public_key() : sec.slave_public_key();
  out.keys.peer_public_key = master ? sec.slave_public_key() : sec.master_public_key();
  auto check_key = [&](const std::string& path, const std::string& key) {
    if (!key.empty() && !is_z85_key(key)) {
      p.add(path, "must be a 40-character Z85 CURVE public key (teleopctl keygen), got " +
                      std::to_string(key.size()) + " characters");
    }
  };
  check_key("security.master_public_key", sec.master_public_key());
  check_key("security.slave_public_key", sec.slave_public_key());
  if (!out.keys.peer_public_key.empty()) {
    out.keys.allowed_client_keys.push_back(out.keys.peer_public_key);
  }
  for (int i = 0; i < sec.client_public_keys_size(); ++i) {
    check_key("security.client_public_keys[" + std::to_string(i) + "]", sec.client_public_keys(i));
    out.keys.allowed_client_keys.push_back(sec.client_public_keys(i));
  }
  check_key("security.supervisor_public_key", sec.supervisor_public_key());
  out.keys.supervisor_public_key = sec.supervisor_public_key();
  for (int i = 0; i < sec.read_only_client_public_keys_size(); ++i) {
    check_key("security.read_only_client_public_keys[" + std::to_string(i) + "]",
              sec.read_only_client_public_keys(i));
    out.keys.read_only_client_keys.push_back(sec.read_only_client_public_keys(i));
  }
  out.keys.allow_unauthenticated_retune = sec.allow_unauthenticated_retune();
  p.throw_if_any();
  return out;
}

}  // namespace

NodeSetup to_node_setup(const LoadedConfig& config, Role role) {
  if (role != Role::kMaster && role != Role::kSlave) {
    throw ConfigError("node role must be master or slave");
  }
  // Both sides' sections are checked by either node: one file, one verdict.
  (void)one_node_setup(config, role == Role::kMaster ? Role::kSlave : Role::kMaster);
  NodeSetup out = one_node_setup(config, role);
  // README "Before engage": what the peer and the supervisor compare before coupling.
  out.settings.config_fingerprint = fingerprint(control_fields(
      to_teleop_params(config), out.settings, config.config.experiment().allow_unstable()));
  return out;
}

}  // namespace teleop::config
