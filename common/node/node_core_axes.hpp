// The RT half of a node for n task-space axes (issue 18 "Devices"; docs/nodes.md "n task-space
// axes"): NodeCore (node_core.hpp) on a HapticDeviceAxes and the n-axis laws (law_axes.hpp).
// One call of step(now) per cycle: read the device's latest sample -> take the newest peer
// state -> the same NodeStateMachine -> control law -> limits -> command -> push own state
// (n axes, NodeStateRecord::set_axis) and a fixed-size telemetry record (CycleRecordAxes).
//
// What each mode commands, as NodeCore with vectors:
//  - disarmed, armed, fault: 0 N on every axis.
//  - aligning: the slave holds its position (its law with no master); the master feels a weak
//    centring spring with damping toward x_s / alpha, F = -k (x_m - x_s / alpha) - b v_m, scaled
//    down as a whole (direction kept) when its norm exceeds centring_max_force_N. Both wait until
//    the norm of alpha x_m - x_s is within the alignment tolerance and the peer is aligning or
//    engaged.
//  - engaged (and the master's clutched): the n-axis three-channel law, reset at engagement
//    from aligning; the master blends from the centring force to -F_am over engage_ramp.
//  - safe: each axis of the master's force ramps linearly from its last value to 0 over
//    safe_ramp; the slave holds its position with its own gains (spring and damping, no master).
// The stall and peer-timeout checks are NodeCore's (an own wake-up later than the peer timeout
// or a burst of overruns ends any coupling in safe before a command is written).
//
// Peers: a state whose `axes` differs from this node's never reaches the law or the state
// machine: it is counted (peer_wrong_axes()), does not refresh the peer's age (so a coupled node
// times out into safe), and while it is the newest state received arm and engage are refused.
//
// The node process (runtime/node_app.hpp) runs it for a configuration with axes > 1, with the
// same threads as NodeCore: state_published, state_out, peer_in, commands, telemetry_out and
// the loop statistics (stats_out, every NodeCore::kStatsEvery cycles) as NodeCore's.
// Guarded parameter changes (docs/nodes.md "n task-space axes"): post_retune as NodeCore's --
// the change waits for its master sequence, then every gain-matrix element and every plane's
// stiffness ramps linearly from the value in force over the change's ramp (normals and offsets
// stay); active_out carries what the law runs. Arm and engage are refused while the peer
// reports another change than this node's.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "common/control/law_axes.hpp"
#include "common/control/law_axes_params.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/core/defaults.hpp"
#include "common/core/rt_safe.hpp"
#include "common/core/teleop_axes.hpp"
#include "common/device/haptic_device_axes.hpp"
#include "common/node/cycle_checks.hpp"
#include "common/node/node_core.hpp"
#include "common/node/node_state_machine.hpp"
#include "common/rt/latest_value.hpp"
#include "common/rt/loop_timing.hpp"
#include "common/rt/spsc_queue.hpp"
#include "common/rt/windowed_histogram.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::node {

struct NodeAxesSettings {
  transport::Role role{transport::Role::kMaster};
  std::chrono::nanoseconds period{std::chrono::milliseconds{1}};
  control::LawAxesParams law{};  // law.axes must equal the device's axes()
  StateMachineParams machine{};
  std::chrono::nanoseconds safe_ramp{defaults::kSafeRamp};
  AlignmentParams alignment{};  // tolerance on |alpha x_m - x_s|, clamp on |F|
  std::uint64_t session_id{1};
  std::uint64_t config_fingerprint{0};  // as NodeSettings
  bool permits_coupling{true};
  std::string coupling_refusal{};
};

// A guarded change's gains as plain numbers, so that it crosses to the RT thread by copy: the
// seven matrices kpm, kps, kdm, kds, kvm, kvs, kfm (kGainOrder), each row-major with n x n
// entries used.
inline constexpr std::size_t kGainMatrices = 7;
using GainValuesAxes = std::array<std::array<double, kMaxAxes * kMaxAxes>, kGainMatrices>;
// One stiffness per fixture plane of a side, in the configuration's plane order.
using PlaneStiffnessesAxes = std::array<double, kMaxPlanesPerSide>;

// The matrices of `gains` (n x n each) as plain numbers, and back (RT-safe: fixed capacity).
[[nodiscard]] GainValuesAxes gain_values(const control::LawGainsAxes& gains, int n) noexcept;
TELEOP_RT void to_law_gains(const GainValuesAxes& values, int n,
                            control::LawGainsAxes& out) noexcept;

// A guarded n-axis change (NodeCore's Retune with gain matrices and plane stiffnesses),
// validated by the caller (config::check_parameter_update_axes).
struct RetuneAxes {
  std::uint64_t id{0};
  GainValuesAxes gains{};
  PlaneStiffnessesAxes master_planes_N_per_m{};
  PlaneStiffnessesAxes slave_planes_N_per_m{};
  std::uint64_t apply_at_master_sequence{0};
  std::chrono::nanoseconds ramp{0};
};

// What the law runs now (ActiveLaw with n axes); the counts say which entries are used.
struct ActiveLawAxes {
  std::uint64_t change_id{0};
  std::uint64_t applied_at_master_sequence{0};
  int axes{0};
  int master_planes{0};
  int slave_planes{0};
  GainValuesAxes gains{};
  PlaneStiffnessesAxes master_planes_N_per_m{};
  PlaneStiffnessesAxes slave_planes_N_per_m{};
  double ramp_progress{1.0};
};

// One cycle for telemetry (CycleRecord with per-axis arrays, entries from `axes` on zero);
// fixed size.
struct CycleRecordAxes {
  std::uint64_t sequence{0};
  std::int64_t sample_time_ns{0};  // the cycle's deadline
  std::int64_t clock_ns{0};        // the clock read on waking (ages and ramps run on it)
  Mode mode{Mode::kDisarmed};
  const char* reason{""};  // static string
  int axes{0};
  std::array<double, kMaxAxes> position_m{};
  std::array<double, kMaxAxes> velocity_m_per_s{};
  std::array<double, kMaxAxes> force_N{};    // measured
  std::array<double, kMaxAxes> command_N{};  // written to the device
  std::array<double, kMaxAxes> peer_position_m{};
  std::uint64_t peer_sequence{0};
  std::int64_t peer_age_ns{0};
  double coupling_weight{0.0};
  std::uint32_t flags{0};  // SampleFlags | LawFlagBits
  unsigned saturated_axes{0};
  unsigned rate_limited_axes{0};
  std::int64_t wakeup_latency_ns{0};
  std::int64_t round_trip_ns{0};
  std::uint64_t master_sequence{0};
  std::uint64_t parameter_change_id{0};  // the guarded change the law runs (0: as built)
  // |alpha x_m - x_s| from both raw positions (0 before a peer state).
  double alignment_error_m{0.0};
  double fixture_penetration_m{0.0};  // the deepest of the own law's planes, else 0
};

class NodeCoreAxes {
 public:
  static constexpr std::size_t kTelemetryCapacity = 4096;

  // The device must be configured and activated. Throws std::invalid_argument naming the field
  // (bad law parameters, law.axes != device.axes(), role, period).
  NodeCoreAxes(const NodeAxesSettings& settings, device::HapticDeviceAxes& device);
  ~NodeCoreAxes();
  NodeCoreAxes(const NodeCoreAxes&) = delete;
  NodeCoreAxes& operator=(const NodeCoreAxes&) = delete;

  // One cycle at `now`, as NodeCore::step. RT-safe: no allocation, lock, I/O or throw.
  TELEOP_RT void step(std::chrono::nanoseconds now,
                      const rt::LoopTiming* timing = nullptr) noexcept;
  TELEOP_RT void step(std::chrono::nanoseconds now, std::chrono::nanoseconds clock,
                      const rt::LoopTiming* timing = nullptr) noexcept;

  [[nodiscard]] rt::LatestValue<PeerSample>& peer_in() noexcept { return peer_in_; }
  [[nodiscard]] bool post_command(Command command) noexcept;
  [[nodiscard]] std::uint64_t commands_posted() const noexcept {
    return commands_posted_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t commands_applied() const noexcept {
    return commands_applied_.load(std::memory_order_acquire);
  }
  [[nodiscard]] rt::LatestValue<transport::NodeStateRecord>& state_out() noexcept {
    return state_out_;
  }
  // Bumped (and notified) once per cycle after state_out is written (the sender's wake-up and
  // the node's heartbeat).
  [[nodiscard]] std::atomic<std::uint32_t>& state_published() noexcept { return published_; }
  [[nodiscard]] rt::LatestValue<LoopSnapshot>& stats_out() noexcept { return stats_out_; }
  // A guarded change, validated by the caller; the newest posted replaces one still waiting
  // for its master sequence. Any one thread.
  void post_retune(const RetuneAxes& r) noexcept { retune_in_.write(r); }
  // What the law runs (written at construction and every cycle of a ramp).
  [[nodiscard]] rt::LatestValue<ActiveLawAxes>& active_out() noexcept { return active_out_; }
  // The newest accepted peer state's fingerprint and parameter change (0: none yet), and this
  // node's parameter change. Any thread.
  [[nodiscard]] std::uint64_t peer_fingerprint() const noexcept {
    return peer_fingerprint_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t peer_change_id() const noexcept {
    return peer_change_id_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t active_change_id() const noexcept {
    return active_change_id_.load(std::memory_order_acquire);
  }
  [[nodiscard]] rt::SpscQueue<CycleRecordAxes, kTelemetryCapacity>& telemetry_out() noexcept {
    return telemetry_out_;
  }
  [[nodiscard]] Mode mode() const noexcept { return mode_.load(std::memory_order_acquire); }
  [[nodiscard]] const char* mode_reason() const noexcept {
    return reason_.load(std::memory_order_acquire);
  }
  [[nodiscard]] int axes() const noexcept { return settings_.law.axes; }
  [[nodiscard]] const NodeAxesSettings& settings() const noexcept { return settings_; }
  // Peer states dropped for another number of axes (any thread).
  [[nodiscard]] std::uint64_t peer_wrong_axes() const noexcept {
    return peer_wrong_axes_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t coupling_refusals() const noexcept {
    return coupling_refusals_.load(std::memory_order_acquire);
  }
  [[nodiscard]] const char* last_coupling_refusal() const noexcept {
    return last_refusal_.load(std::memory_order_acquire);
  }

  // The role's law and what it commands (node_core_axes.cpp); public for the implementation.
  class Side;

 private:
  using Vec = control::AxisVector;

  TELEOP_RT void receive_peer(std::chrono::nanoseconds now) noexcept;
  TELEOP_RT void apply_retune(std::chrono::nanoseconds now, std::uint64_t master_sequence) noexcept;
  TELEOP_RT [[nodiscard]] Command next_command() noexcept;
  TELEOP_RT [[nodiscard]] CycleOutputs decide(std::chrono::nanoseconds now, Command command,
                                              std::int64_t peer_age_ns, double gap_m,
                                              bool device_fault, const char* own_stall) noexcept;
  TELEOP_RT void enter(const EntryActions& actions, std::chrono::nanoseconds clock) noexcept;
  struct Entry final : EntryHandler {
    NodeCoreAxes* core{nullptr};
    std::chrono::nanoseconds clock{0};
    TELEOP_RT void on_enter(Mode from, Mode to, const EntryActions& actions) noexcept override;
  };
  TELEOP_RT void publish_state(std::chrono::nanoseconds now, Mode mode, const Vec& velocity,
                               const Vec& measured_force_N, std::int64_t peer_age_ns,
                               std::uint32_t flags, double& penetration_m) noexcept;
  TELEOP_RT void publish_stats(const rt::LoopTiming* timing, std::int64_t peer_age_ns) noexcept;
  TELEOP_RT [[nodiscard]] const char* coupling_refusal() const noexcept;
  TELEOP_RT [[nodiscard]] Vec peer_positions() const noexcept;

  NodeAxesSettings settings_;
  device::HapticDeviceAxes& device_;
  NodeStateMachine machine_;
  Entry entry_{};
  std::unique_ptr<Side> side_;
  std::array<control::VelocityEstimator, kMaxAxes> velocity_;
  transport::RoundTripEstimator round_trip_{};
  rt::WindowedHistogram round_trip_window_{};  // as NodeCore's

  rt::LatestValue<PeerSample> peer_in_{};
  rt::SpscQueue<Command, 64> commands_in_{};
  std::atomic<std::uint64_t> commands_posted_{0};
  std::atomic<std::uint64_t> commands_applied_{0};
  rt::LatestValue<transport::NodeStateRecord> state_out_{};
  std::atomic<std::uint32_t> published_{0};
  rt::LatestValue<LoopSnapshot> stats_out_{};
  std::atomic<std::uint64_t> peer_fingerprint_{0};
  std::atomic<std::uint64_t> peer_change_id_{0};
  std::atomic<std::uint64_t> active_change_id_{0};
  rt::LatestValue<RetuneAxes> retune_in_{};
  rt::LatestValue<ActiveLawAxes> active_out_{};
  rt::SpscQueue<CycleRecordAxes, kTelemetryCapacity> telemetry_out_{};
  std::atomic<Mode> mode_{Mode::kDisarmed};
  std::atomic<const char*> reason_{"start"};
  std::atomic<std::uint64_t> peer_wrong_axes_{0};
  std::atomic<std::uint64_t> coupling_refusals_{0};
  std::atomic<const char*> last_refusal_{""};

  // RT-thread state.
  std::uint64_t sequence_{0};
  StallCheck stall_{};
  bool have_peer_{false};
  bool newest_wrong_axes_{false};  // the newest state received had another axis count
  PeerSample peer_{};
  std::uint64_t peer_restarts_{0};
  bool peer_restarted_{false};
  std::int64_t round_trip_ns_{0};
  std::chrono::nanoseconds safe_since_{0};
  Vec own_m_{};  // this cycle's position (entry actions reset the law there)
  Vec last_command_N_{};
  Vec safe_from_N_{};
  // Guarded changes (as NodeCore's).
  bool retune_pending_{false};
  RetuneAxes pending_{};
  bool ramping_{false};
  ActiveLawAxes active_{};
  ActiveLawAxes ramp_from_{};
  RetuneAxes ramp_to_{};
  std::chrono::nanoseconds ramp_start_{0};
  std::chrono::nanoseconds ramp_length_{0};
};

}  // namespace teleop::node
