// The RT half of a node (docs/architecture.md §1.1, §4; issue 4 "Loop"): one call of step(now) per
// cycle does read the device's latest sample -> take the newest peer state -> state machine ->
// control law -> limits -> command -> push own state and a fixed-size telemetry record. It touches
// only the device and lock-free buffers: the link, command and telemetry threads (node_app) do the
// sockets, protobuf and logging. Tests call step() with a fake clock.
//
// What each mode commands:
//  - disarmed, armed, fault: 0 N.
//  - aligning: the slave holds its position (its law with no master: spring and damping to where
//    it is); the master feels a weak centring spring with damping toward the slave's position
//    (x_s / alpha), clamped to centring_max_force_N. Both wait until |alpha x_m - x_s| is within
//    the alignment tolerance and the peer is aligning or engaged.
//  - engaged (and the master's clutched): the three-channel law, reset at engagement from
//    aligning. The master blends from the centring force to the law's force over engage_ramp;
//    the slave's law fades its velocity reference and any start-up mismatch in over the same
//    time. Clutch and unclutch keep the law (and the ramp where it was): on release the
//    master's law absorbs the offset the operator indexed (master_law.hpp), so the coupling
//    resumes with no error and neither side is pulled back.
//
// Time: `now` (the deadline) stamps the cycle; ages and stalls are measured against the clock
// read on waking (LoopTiming::last_woke(), `now` without a loop). A wake-up more than the peer
// timeout after the previous cycle's, or a burst of overruns (the time lost beyond one period
// per cycle, less half of each cycle's length, accumulating past the peer timeout: the loop
// ran less than half its cycles for that long), ends any coupling in safe before a command
// is written: the peer state and the device command are that old.
//  - safe: the master's force ramps linearly from its last value to 0 over safe_ramp; the slave
//    holds its position with its own gains (spring and damping, no master).
// The peer counts only while coupled on both sides: a master that is engaged while the slave
// is still aligning is not yet coupled (its law sees no valid slave), and vice versa.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "common/control/law_params.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/core/defaults.hpp"
#include "common/core/rt_safe.hpp"
#include "common/device/haptic_device.hpp"
#include "common/node/cycle_checks.hpp"
#include "common/node/node_side.hpp"
#include "common/node/node_state_machine.hpp"
#include "common/rt/latest_value.hpp"
#include "common/rt/loop_timing.hpp"
#include "common/rt/spsc_queue.hpp"
#include "common/rt/windowed_histogram.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::node {

struct AlignmentParams {
  double tolerance_m{defaults::kAlignmentTolerance_m};
  double centring_stiffness_N_per_m{defaults::kCentringStiffness_N_per_m};
  double centring_damping_Ns_per_m{defaults::kCentringDamping_Ns_per_m};
  double centring_max_force_N{defaults::kCentringMaxForce_N};
};

struct NodeSettings {
  transport::Role role{transport::Role::kMaster};
  std::chrono::nanoseconds period{std::chrono::milliseconds{1}};
  control::LawParams law{};
  StateMachineParams machine{};
  std::chrono::nanoseconds safe_ramp{defaults::kSafeRamp};
  AlignmentParams alignment{};
  std::uint64_t session_id{1};
  // docs/nodes.md "Before engage": the fingerprint of this node's control-relevant configuration
  // (config::control_fingerprint; sent to the peer every cycle), and the node's own check of
  // its configuration at start. Arm and engage are refused while the peer's fingerprint or
  // parameter change differs, the peer sent none yet, or `permits_coupling` is false (then
  // with `coupling_refusal` as the reason, naming the verdict and the damping ratio).
  std::uint64_t config_fingerprint{0};
  bool permits_coupling{true};
  std::string coupling_refusal{};
};

// A peer state as the link thread accepted it, with its arrival on the monotonic clock.
struct PeerSample {
  transport::NodeStateRecord state{};
  std::int64_t arrival_ns{0};
};

// Law flag bits of CycleRecord::flags (above the device's SampleFlags bits).
struct LawFlagBits {
  static constexpr std::uint32_t kSaturated = 1U << 8;
  static constexpr std::uint32_t kRateLimited = 1U << 9;
  static constexpr std::uint32_t kReferenceLimited = 1U << 10;
  static constexpr std::uint32_t kLimitViolation = 1U << 11;
  static constexpr std::uint32_t kInputFault = 1U << 12;
};

// A guarded parameter change: applied when the master's sequence reaches apply_at, every value
// ramped linearly from the one in force over `ramp`.
struct Retune {
  std::uint64_t id{0};
  Gains gains{};
  FixtureParams master_fixture{};
  FixtureParams slave_fixture{};
  std::uint64_t apply_at_master_sequence{0};
  std::chrono::nanoseconds ramp{0};
};

// What the law runs now.
struct ActiveLaw {
  std::uint64_t change_id{0};
  std::uint64_t applied_at_master_sequence{0};
  Gains gains{};
  FixtureParams master_fixture{};
  FixtureParams slave_fixture{};
  double ramp_progress{1.0};
};

// One cycle for telemetry (mirrors teleop.v1.CycleRecord); fixed size.
struct CycleRecord {
  std::uint64_t sequence{0};
  std::int64_t sample_time_ns{0};
  Mode mode{Mode::kDisarmed};
  const char* reason{""};  // static string
  double position_m{0.0};
  double velocity_m_per_s{0.0};
  double force_N{0.0};
  double command_N{0.0};
  std::uint64_t peer_sequence{0};
  double peer_position_m{0.0};
  std::int64_t peer_age_ns{0};
  double coupling_weight{0.0};
  std::uint32_t flags{0};
  std::int64_t wakeup_latency_ns{0};
  std::int64_t round_trip_ns{0};
  std::uint64_t master_sequence{0};
  std::uint64_t parameter_change_id{0};
  // alpha x_m - x_s from both raw positions (slave coordinates; 0 before a peer state): what
  // aligning brings within the tolerance, shown while aligning.
  double alignment_error_m{0.0};
};

// Loop and link statistics the RT thread publishes every kStatsEvery cycles.
struct LoopSnapshot {
  std::uint64_t cycles{0};
  std::uint64_t overruns{0};
  std::int64_t wakeup_p50_ns{0};
  std::int64_t wakeup_p99_ns{0};
  std::int64_t wakeup_p999_ns{0};
  std::int64_t wakeup_max_ns{0};
  std::int64_t compute_p50_ns{0};
  std::int64_t compute_p99_ns{0};
  std::int64_t compute_max_ns{0};
  std::int64_t round_trip_ns{0};
  std::int64_t round_trip_p50_ns{0};
  std::int64_t round_trip_p99_ns{0};
  std::uint64_t peer_restarts{0};
  std::uint64_t peer_session_id{0};
  std::int64_t peer_age_ns{0};
};

class NodeCore {
 public:
  static constexpr std::size_t kTelemetryCapacity = 4096;
  static constexpr std::uint64_t kStatsEvery = 50;

  // The device must be configured and activated. Throws std::invalid_argument (bad law params).
  NodeCore(const NodeSettings& settings, device::HapticDevice& device);

  // One cycle at `now` (its deadline on the monotonic clock). `timing`: the loop's statistics,
  // when run by a PeriodicLoop (read on this thread); its last_woke() is the clock of the
  // cycle. RT-safe: no allocation, lock, I/O or throw.
  TELEOP_RT void step(std::chrono::nanoseconds now,
                      const rt::LoopTiming* timing = nullptr) noexcept;
  // The same with the clock read at the cycle given (tests: a late wake-up).
  TELEOP_RT void step(std::chrono::nanoseconds now, std::chrono::nanoseconds clock,
                      const rt::LoopTiming* timing = nullptr) noexcept;

  // Link thread -> RT: the newest accepted peer state.
  [[nodiscard]] rt::LatestValue<PeerSample>& peer_in() noexcept { return peer_in_; }
  // Command thread -> RT: one command per cycle is applied, in order. Returns false when full.
  [[nodiscard]] bool post_command(Command command) noexcept;
  // Commands applied so far (the command thread waits for its ticket before replying).
  [[nodiscard]] std::uint64_t commands_posted() const noexcept {
    return commands_posted_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t commands_applied() const noexcept {
    return commands_applied_.load(std::memory_order_acquire);
  }
  // RT -> sender thread: own state to send, and a counter bumped (and notified) per cycle.
  [[nodiscard]] rt::LatestValue<transport::NodeStateRecord>& state_out() noexcept {
    return state_out_;
  }
  [[nodiscard]] std::atomic<std::uint32_t>& state_published() noexcept { return published_; }
  // RT -> telemetry thread.
  [[nodiscard]] rt::SpscQueue<CycleRecord, kTelemetryCapacity>& telemetry_out() noexcept {
    return telemetry_out_;
  }
  [[nodiscard]] rt::LatestValue<LoopSnapshot>& stats_out() noexcept { return stats_out_; }
  // Command thread -> RT: a validated parameter change (the newest replaces a pending one).
  void post_retune(const Retune& r) noexcept { retune_in_.write(r); }
  // RT -> telemetry: the law's parameters in force.
  [[nodiscard]] rt::LatestValue<ActiveLaw>& active_out() noexcept { return active_out_; }
  // The mode and its reason as of the last cycle (any thread).
  [[nodiscard]] Mode mode() const noexcept { return mode_.load(std::memory_order_acquire); }
  [[nodiscard]] const char* mode_reason() const noexcept {
    return reason_.load(std::memory_order_acquire);
  }
  [[nodiscard]] const NodeSettings& settings() const noexcept { return settings_; }
  // docs/nodes.md "Before engage": the newest peer state's fingerprint and parameter change (0:
  // none yet), and how many arm or engage commands the configuration checks refused (any thread).
  [[nodiscard]] std::uint64_t peer_fingerprint() const noexcept {
    return peer_fingerprint_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t peer_change_id() const noexcept {
    return peer_change_id_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t active_change_id() const noexcept {
    return active_change_id_.load(std::memory_order_acquire);
  }
  [[nodiscard]] std::uint64_t coupling_refusals() const noexcept {
    return coupling_refusals_.load(std::memory_order_acquire);
  }
  // Why the newest of those was refused (set before the count moves; a static string or one
  // of the settings').
  [[nodiscard]] const char* last_coupling_refusal() const noexcept {
    return last_refusal_.load(std::memory_order_acquire);
  }

 private:
  // The phases of step(), in order.
  TELEOP_RT void receive_peer(std::chrono::nanoseconds now) noexcept;
  TELEOP_RT [[nodiscard]] Command next_command() noexcept;
  TELEOP_RT [[nodiscard]] CycleOutputs decide(std::chrono::nanoseconds now, Command command,
                                              std::int64_t peer_age_ns, double gap_m,
                                              bool device_fault, const char* own_stall) noexcept;
  TELEOP_RT void enter(const EntryActions& actions, double own_m,
                       std::chrono::nanoseconds clock) noexcept;
  // The state machine's entry handler: carries out its entry actions with this cycle's own
  // position and clock (set before the machine steps).
  struct Entry final : EntryHandler {
    NodeCore* core{nullptr};
    double own_m{0.0};
    std::chrono::nanoseconds clock{0};
    TELEOP_RT void on_enter(Mode from, Mode to, const EntryActions& actions) noexcept override;
  };
  TELEOP_RT void publish_state(std::chrono::nanoseconds now, Mode mode, double own_m,
                               double velocity_m_per_s, double measured_force_N,
                               std::int64_t peer_age_ns, std::uint32_t flags) noexcept;
  TELEOP_RT void publish_stats(const rt::LoopTiming* timing, std::int64_t peer_age_ns) noexcept;
  TELEOP_RT void apply_retune(std::chrono::nanoseconds now, std::uint64_t master_sequence) noexcept;
  // Why arm and engage are refused now (nullptr: permitted). RT-safe.
  TELEOP_RT [[nodiscard]] const char* coupling_refusal() const noexcept;

  NodeSettings settings_;
  device::HapticDevice& device_;
  NodeStateMachine machine_;
  Entry entry_{};                   // the machine's entry handler (machine_.set_entry_handler)
  std::unique_ptr<NodeSide> side_;  // what the role decides (node_side.hpp)
  control::VelocityEstimator velocity_;
  transport::RoundTripEstimator round_trip_{};
  // The round trip over the last 9-10 s (what the supervisor's model takes).
  rt::WindowedHistogram round_trip_window_{};

  rt::LatestValue<PeerSample> peer_in_{};
  rt::SpscQueue<Command, 64> commands_in_{};
  std::atomic<std::uint64_t> commands_posted_{0};
  std::atomic<std::uint64_t> commands_applied_{0};
  rt::LatestValue<transport::NodeStateRecord> state_out_{};
  std::atomic<std::uint32_t> published_{0};
  rt::SpscQueue<CycleRecord, kTelemetryCapacity> telemetry_out_{};
  rt::LatestValue<LoopSnapshot> stats_out_{};
  rt::LatestValue<Retune> retune_in_{};
  rt::LatestValue<ActiveLaw> active_out_{};
  std::atomic<Mode> mode_{Mode::kDisarmed};
  std::atomic<const char*> reason_{"start"};
  std::atomic<std::uint64_t> peer_fingerprint_{0};
  std::atomic<std::uint64_t> peer_change_id_{0};
  std::atomic<std::uint64_t> coupling_refusals_{0};
  std::atomic<const char*> last_refusal_{""};
  std::atomic<std::uint64_t> active_change_id_{0};

  // RT-thread state.
  std::uint64_t sequence_{0};
  StallCheck stall_{};
  bool have_peer_{false};
  PeerSample peer_{};
  std::uint64_t peer_restarts_{0};
  bool peer_restarted_{false};  // since the last coupling began
  std::int64_t round_trip_ns_{0};
  std::chrono::nanoseconds safe_since_{0};
  double last_command_N_{0.0};
  double safe_from_N_{0.0};
  // Parameter changes.
  bool retune_pending_{false};
  Retune pending_{};
  bool ramping_{false};
  ActiveLaw active_{};
  ActiveLaw ramp_from_{};
  Retune ramp_to_{};  // the change being ramped to (pending_ is the next one, waiting)
  std::chrono::nanoseconds ramp_start_{0};
  std::chrono::nanoseconds ramp_length_{0};
};

}  // namespace teleop::node
