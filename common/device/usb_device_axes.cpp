#include "common/device/usb_device_axes.hpp"

#include <cmath>
#include <numbers>
#include <optional>
#include <utility>

namespace teleop::device {

namespace {

std::array<double, 4> column_major(const Eigen::Matrix2d& m) noexcept {
  return {m(0, 0), m(1, 0), m(0, 1), m(1, 1)};
}

bool positive_finite(double v) noexcept { return std::isfinite(v) && v > 0.0; }

}  // namespace

UsbDeviceAxes::UsbDeviceAxes(UsbDeviceAxesConfig config)
    : UsbDeviceAxes(std::move(config), open_usb_transport) {}

UsbDeviceAxes::UsbDeviceAxes(UsbDeviceAxesConfig config, TransportFactory open_transport)
    : config_(std::move(config)),
      link_(config_.link, std::move(open_transport), usb::kProtocolVersion2,
            static_cast<std::size_t>(config_.axes), "usb device axes", *this) {}

UsbDeviceAxes::~UsbDeviceAxes() { (void)link_.deactivate(); }

std::string UsbDeviceAxes::invalid_field() const {
  const int n = config_.axes;
  if (n < 1 || n > static_cast<int>(usb::kMaxChannels)) return "axes must be in [1, 6]";
  const auto gains = static_cast<int>(config_.actuators.size());
  if (gains != 0 && gains != n) return "actuators must be empty or have one entry per axis (n)";
  for (int i = 0; i < gains; ++i) {
    const UsbActuatorGains& g = config_.actuators[static_cast<std::size_t>(i)];
    const std::string at = "actuators[" + std::to_string(i) + "].";
    if (!positive_finite(g.torque_constant_per_A)) {
      return at + "torque_constant_per_A must be positive and finite";
    }
    if (!positive_finite(g.amplifier_A_per_count)) {
      return at + "amplifier_A_per_count must be positive and finite";
    }
  }
  if (config_.kinematics != DeviceKinematics::kFiveBar) return "";
  if (n < 2) return "kinematics: five_bar needs at least 2 axes (channels 0 and 1 are its joints)";
  if (const char* problem = kinematics::check(config_.five_bar); *problem != '\0') {
    return std::string("five_bar: ") + problem;
  }
  if (!config_.five_bar_home_joint_rad.allFinite() ||
      !kinematics::forward(config_.five_bar, config_.five_bar_home_joint_rad).has_value()) {
    return "five_bar_home_joint_rad: the linkage does not assemble there";
  }
  return "";
}

Status UsbDeviceAxes::configure() {
  link_.close();
  if (const std::string bad = invalid_field(); !bad.empty()) {
    error_ = "usb device axes: " + bad;
    return {StatusCode::kInvalidArgument, error_.c_str()};
  }
  five_bar_ = config_.kinematics == DeviceKinematics::kFiveBar;
  home_end_m_.setZero();
  home_jacobian_ = {};
  if (five_bar_) {
    const std::optional<kinematics::FiveBarPose> home =
        kinematics::forward(config_.five_bar, config_.five_bar_home_joint_rad);
    home_end_m_ = home->end_m;
    home_jacobian_ = column_major(home->jacobian_m_per_rad);
  }
  const usb::Scaling& scaling = config_.link.scaling;
  radians_per_count_ = 2.0 * std::numbers::pi /
                       (static_cast<double>(scaling.counts_per_rev) * scaling.transmission_ratio);
  for (std::size_t i = 0; i < usb::kMaxChannels; ++i) {
    actuator_scaling_[i] = scaling;
    if (i < config_.actuators.size()) {
      const UsbActuatorGains& g = config_.actuators[i];
      actuator_scaling_[i].actuator_full_scale_N =
          g.torque_constant_per_A * g.amplifier_A_per_count * usb::kRawFullScale;
    }
  }
  return link_.configure();
}

Status UsbDeviceAxes::activate() {
  if (link_.configured() && !link_.active()) {
    Reading stale;
    while (samples_.read(stale)) {
    }
    latest_ = {};
    latest_.jacobian = home_jacobian_;
    io_reading_ = latest_;
    have_sample_ = false;
    command_rejected_ = false;
  }
  return link_.activate();
}

Status UsbDeviceAxes::deactivate() { return link_.deactivate(); }

void UsbDeviceAxes::fill(SampleAxes& sample) const noexcept {
  const int n = config_.axes;
  sample.sequence = latest_.sequence;
  sample.time_s = latest_.time_s;
  sample.axes = n;
  sample.position_m.setZero(n);  // fixed capacity (kMaxAxes): no allocation
  sample.force_N.setZero(n);
  for (int i = 0; i < n; ++i) {
    const auto c = static_cast<std::size_t>(i);
    sample.position_m(i) = latest_.position_m[c];
    sample.force_N(i) = latest_.force_N[c];
  }
  sample.flags = latest_.flags;
}

Status UsbDeviceAxes::read(SampleAxes& sample) noexcept {
  if (!link_.active()) return {StatusCode::kNotActive, "device not active"};
  Reading fresh;
  if (samples_.read(fresh)) {
    latest_ = fresh;
    if (command_rejected_) latest_.flags |= SampleFlags::kCommandRejected;
    command_rejected_ = false;
    have_sample_ = true;
  }
  if (const char* mismatch = link_.mismatch(); mismatch != nullptr) {
    fill(sample);
    sample.flags |= SampleFlags::kFault;
    return {StatusCode::kFault, mismatch};
  }
  if (!have_sample_) {
    return {StatusCode::kUnavailable,
            "usb device axes: no report acknowledging this activation yet"};
  }
  fill(sample);
  if (link_.link_lost()) {
    sample.flags |= SampleFlags::kFault;
    return {StatusCode::kFault, "usb device axes: no report within report_timeout (link lost)"};
  }
  return Status::Ok();
}

Status UsbDeviceAxes::write(const CommandAxes& command) noexcept {
  if (!link_.active()) return {StatusCode::kNotActive, "device not active"};
  const int n = config_.axes;
  if (command.force_N.size() != n) {
    link_.refuse(UsbHostLink::Refusal::kWrongAxes);
    command_rejected_ = true;
    return {StatusCode::kInvalidArgument, "force command has the wrong number of axes"};
  }
  // Joint efforts tau = J^T F: the five-bar's Jacobian on channels 0-1, the identity elsewhere.
  std::array<double, usb::kMaxChannels> effort{};
  for (int i = 0; i < n; ++i) effort[static_cast<std::size_t>(i)] = command.force_N(i);
  if (five_bar_) {
    const std::array<double, 4>& j = latest_.jacobian;  // column-major: J(r, c) = j[2c + r]
    effort[0] = j[0] * command.force_N(0) + j[1] * command.force_N(1);
    effort[1] = j[2] * command.force_N(0) + j[3] * command.force_N(1);
  }
  UsbDacCommand dacs;
  for (std::size_t c = 0; c < static_cast<std::size_t>(n); ++c) {
    const usb::DacValue value = usb::force_to_dac(effort[c], actuator_scaling_[c]);
    if (value.error != usb::PacketError::kNone) {
      link_.refuse(UsbHostLink::Refusal::kNonFinite);
      command_rejected_ = true;
      return {StatusCode::kInvalidArgument, "non-finite force command refused"};
    }
    dacs.dac[c] = value.dac;
  }
  link_.submit(dacs);
  return Status::Ok();
}

void UsbDeviceAxes::on_report(std::uint64_t sample_number, const usb::ReportPacketV2& r) noexcept {
  const usb::Scaling& scaling = config_.link.scaling;
  Reading& p = io_reading_;
  p.sequence = sample_number;
  p.time_s = static_cast<double>(r.device_time_us) * 1e-6;
  p.flags = usb_sample_flags(r.flags);
  std::size_t first_cartesian = 0;
  if (five_bar_) {
    first_cartesian = 2;
    const Eigen::Vector2d q =
        config_.five_bar_home_joint_rad +
        radians_per_count_ * Eigen::Vector2d(static_cast<double>(r.encoder_counts[0]),
                                             static_cast<double>(r.encoder_counts[1]));
    const std::optional<kinematics::FiveBarPose> pose = kinematics::forward(config_.five_bar, q);
    if (pose) {
      p.position_m[0] = pose->end_m(0) - home_end_m_(0);
      p.position_m[1] = pose->end_m(1) - home_end_m_(1);
      p.jacobian = column_major(pose->jacobian_m_per_rad);
    } else {
      // The linkage cannot be at these angles: the last reading is held and flagged.
      p.flags |= SampleFlags::kFault;
    }
  }
  const auto n = static_cast<std::size_t>(config_.axes);
  for (std::size_t c = first_cartesian; c < n; ++c) {
    p.position_m[c] = usb::counts_to_position_m(r.encoder_counts[c], scaling);
  }
  for (std::size_t c = 0; c < n; ++c)
    p.force_N[c] = usb::adc_to_force_N(r.load_cell_adc[c], scaling);
  samples_.write(p);
}

std::unique_ptr<HapticDeviceAxes> make_usb_device_axes(const UsbDeviceAxesConfig& config) {
  return std::make_unique<UsbDeviceAxes>(config);
}

}  // namespace teleop::device
