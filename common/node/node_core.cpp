#include "common/node/node_core.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "common/node/cycle_checks.hpp"

namespace teleop::node {
namespace {

using transport::Role;

bool peer_coupling(int wire) noexcept {
  return wire == wire_mode(Mode::kAligning) || wire == wire_mode(Mode::kEngaged) ||
         wire == wire_mode(Mode::kClutched);
}
bool peer_coupled(int wire) noexcept {
  return wire == wire_mode(Mode::kEngaged) || wire == wire_mode(Mode::kClutched);
}
bool peer_down(int wire) noexcept {
  return wire == wire_mode(Mode::kSafe) || wire == wire_mode(Mode::kFault);
}

}  // namespace

NodeCore::NodeCore(const NodeSettings& settings, device::HapticDevice& device)
    : settings_(settings),
      device_(device),
      machine_(settings.machine),
      velocity_(std::chrono::duration<double>(settings.period).count(),
                settings.law.velocity_cutoff_hz) {
  if (settings_.period.count() <= 0) throw std::invalid_argument("node period must be > 0");
  side_ = NodeSide::make(settings_);
  entry_.core = this;
  machine_.set_entry_handler(&entry_);
  active_.gains = settings_.law.gains;
  active_.master_fixture = settings_.law.master_fixture;
  active_.slave_fixture = settings_.law.slave_fixture;
  active_out_.write(active_);
}

void NodeCore::apply_retune(std::chrono::nanoseconds now, std::uint64_t master_sequence) noexcept {
  Retune incoming{};
  if (retune_in_.read(incoming)) {
    pending_ = incoming;
    retune_pending_ = true;
  }
  if (retune_pending_ && master_sequence >= pending_.apply_at_master_sequence) {
    retune_pending_ = false;
    ramping_ = true;
    ramp_from_ = active_;
    ramp_start_ = now;
    ramp_length_ = pending_.ramp;
    // The ramp's own target: a change posted while it runs waits for its own sequence.
    ramp_to_ = pending_;
    active_.change_id = pending_.id;
    // The agreed sequence (the slave may first see a later master state than that one).
    active_.applied_at_master_sequence = pending_.apply_at_master_sequence;
  }
  if (!ramping_) return;
  const double length = static_cast<double>(ramp_length_.count());
  const double w =
      length <= 0.0
          ? 1.0
          : std::clamp(static_cast<double>((now - ramp_start_).count()) / length, 0.0, 1.0);
  auto lerp = [w](double a, double b) { return a + w * (b - a); };
  const Gains& a = ramp_from_.gains;
  const Gains& b = ramp_to_.gains;
  active_.gains =
      Gains{lerp(a.kpm, b.kpm), lerp(a.kps, b.kps), lerp(a.kdm, b.kdm), lerp(a.kds, b.kds),
            lerp(a.kvm, b.kvm), lerp(a.kvs, b.kvs), lerp(a.kfm, b.kfm)};
  active_.master_fixture = FixtureParams{
      lerp(ramp_from_.master_fixture.stiffness_N_per_m, ramp_to_.master_fixture.stiffness_N_per_m),
      ramp_to_.master_fixture.position_m};
  active_.slave_fixture = FixtureParams{
      lerp(ramp_from_.slave_fixture.stiffness_N_per_m, ramp_to_.slave_fixture.stiffness_N_per_m),
      ramp_to_.slave_fixture.position_m};
  active_.ramp_progress = w;
  side_->retune(active_);
  if (w >= 1.0) ramping_ = false;
  active_out_.write(active_);
}

const char* NodeCore::coupling_refusal() const noexcept {
  if (!settings_.permits_coupling) {
    return settings_.coupling_refusal.empty()
               ? "arm and engage refused: the configuration check at start failed"
               : settings_.coupling_refusal.c_str();
  }
  if (!have_peer_) {
    return "arm and engage refused: no state from the peer yet (its configuration fingerprint "
           "is unknown)";
  }
  if (peer_.state.config_fingerprint == 0) {
    return "arm and engage refused: the peer sends no configuration fingerprint (an older "
           "version?)";
  }
  if (peer_.state.config_fingerprint != settings_.config_fingerprint) {
    return "arm and engage refused: configuration fingerprint differs from the peer's";
  }
  if (peer_.state.parameter_change_id != active_.change_id) {
    return "arm and engage refused: the peer runs another parameter change";
  }
  return nullptr;
}

bool NodeCore::post_command(Command command) noexcept {
  if (!commands_in_.try_push(command)) return false;
  commands_posted_.fetch_add(1, std::memory_order_acq_rel);
  return true;
}

void NodeCore::step(std::chrono::nanoseconds now, const rt::LoopTiming* timing) noexcept {
  const std::chrono::nanoseconds clock =
      timing != nullptr && timing->cycles() > 0 ? timing->last_woke() : now;
  step(now, clock, timing);
}

void NodeCore::step(std::chrono::nanoseconds now, std::chrono::nanoseconds clock,
                    const rt::LoopTiming* timing) noexcept {
  ++sequence_;
  const char* own_stall = stall_.check(clock, settings_.period, settings_.machine.peer_timeout);

  device::Sample sample{};
  const device::Status read = device_.read(sample);
  const bool device_fault = !read.ok() || (sample.flags & device::SampleFlags::kFault) != 0;
  const double velocity_m_per_s = velocity_.step(sample.position_m);
  receive_peer(now);
  // Against the clock: after a stall the deadline is as old as the stall.
  const std::int64_t peer_age_ns = peer_state_age_ns(have_peer_, clock, peer_.arrival_ns);

  const double own_m = sample.position_m;
  const double gap_m = have_peer_ ? side_->alignment_gap_m(own_m, peer_.state.position_m) : 0.0;
  // A transition calls entry_ (enter()) from within the machine's step, with these.
  entry_.own_m = own_m;
  entry_.clock = clock;
  const CycleOutputs out = decide(now, next_command(), peer_age_ns, gap_m, device_fault, own_stall);
  const Mode mode = out.mode;
  // A restart matters only to a coupling that was in progress.
  if (mode == Mode::kDisarmed || mode == Mode::kArmed) peer_restarted_ = false;

  double weight = out.coupling_weight;
  if (mode == Mode::kSafe) {
    const double ramp = static_cast<double>(settings_.safe_ramp.count());
    const double since = static_cast<double>((clock - safe_since_).count());
    weight = ramp <= 0.0 ? 0.0 : std::clamp(1.0 - since / ramp, 0.0, 1.0);
  }
  const std::uint64_t master_sequence =
      side_->master_sequence(sequence_, have_peer_, peer_.state.sequence);
  apply_retune(now, master_sequence);
  std::uint32_t flags = sample.flags;
  double force_N = 0.0;
  if (!device_fault) {
    SideCycle c;
    c.mode = mode;
    c.weight = weight;
    c.position_m = own_m;
    c.velocity_m_per_s = velocity_m_per_s;
    c.measured_force_N = sample.force_N;
    c.coupled = have_peer_ && peer_coupled(peer_.state.mode);
    c.have_peer = have_peer_;
    c.peer = &peer_.state;
    c.safe_from_N = safe_from_N_;
    force_N = side_->command(c, flags);
  }
  if (!std::isfinite(force_N)) force_N = 0.0;
  (void)device_.write(device::Command{force_N});
  last_command_N_ = force_N;
  (void)device_.tick(settings_.period);

  publish_state(now, mode, own_m, velocity_m_per_s, sample.force_N, peer_age_ns, flags);
  mode_.store(mode, std::memory_order_release);
  reason_.store(out.reason, std::memory_order_release);

  CycleRecord rec;
  rec.sequence = sequence_;
  rec.sample_time_ns = now.count();
  rec.mode = mode;
  rec.reason = out.reason;
  rec.position_m = own_m;
  rec.velocity_m_per_s = velocity_m_per_s;
  rec.force_N = sample.force_N;
  rec.command_N = force_N;
  rec.peer_sequence = have_peer_ ? peer_.state.sequence : 0;
  rec.peer_position_m = have_peer_ ? peer_.state.position_m : 0.0;
  rec.peer_age_ns = peer_age_ns;
  rec.coupling_weight = weight;
  rec.flags = flags;
  rec.round_trip_ns = round_trip_ns_;
  rec.master_sequence = master_sequence;
  rec.parameter_change_id = active_.change_id;
  rec.alignment_error_m = gap_m;
  if (timing != nullptr && timing->cycles() > 0) {
    rec.wakeup_latency_ns = timing->last_wakeup_latency().count();
  }
  (void)telemetry_out_.try_push(rec);
  if (sequence_ % kStatsEvery == 1) publish_stats(timing, peer_age_ns);
}

// The newest peer state from the link thread, and the round trip its echo measures.
void NodeCore::receive_peer(std::chrono::nanoseconds now) noexcept {
  // The round trip's window moves on even while no echo comes back.
  round_trip_window_.advance(now.count());
  PeerSample incoming{};
  if (!peer_in_.read(incoming)) return;
  if (have_peer_ && incoming.state.session_id != peer_.state.session_id) {
    ++peer_restarts_;
    peer_restarted_ = true;
  }
  peer_ = incoming;
  have_peer_ = true;
  peer_fingerprint_.store(incoming.state.config_fingerprint, std::memory_order_release);
  peer_change_id_.store(incoming.state.parameter_change_id, std::memory_order_release);
  note_echo(incoming.state, incoming.arrival_ns, now, round_trip_, round_trip_ns_,
            round_trip_window_);
}

// The operator's command of this cycle (one per cycle, in order); the clutch only on the side
// that takes it.
Command NodeCore::next_command() noexcept {
  return take_command(commands_in_, commands_applied_, side_->takes_clutch());
}

// The state machine's step on this cycle's inputs.
CycleOutputs NodeCore::decide(std::chrono::nanoseconds now, Command command,
                              std::int64_t peer_age_ns, double gap_m, bool device_fault,
                              const char* own_stall) noexcept {
  CycleInputs in;
  in.now = now;
  in.command = command;
  in.peer_seen = have_peer_;
  in.peer_age = std::chrono::nanoseconds(peer_age_ns);
  in.aligned = have_peer_ && std::abs(gap_m) <= settings_.alignment.tolerance_m &&
               peer_coupling(peer_.state.mode);
  in.device_fault = device_fault;
  in.law_fault = side_->law_faulted();
  in.peer_failed = have_peer_ && (peer_down(peer_.state.mode) || peer_restarted_);
  in.peer_disengaged = have_peer_ && !peer_coupling(peer_.state.mode) && !in.peer_failed;
  in.own_stall = own_stall;
  in.coupling_refusal = coupling_refusal();
  const CycleOutputs out = machine_.step(in);
  if (out.refused) {
    last_refusal_.store(out.reason, std::memory_order_release);
    coupling_refusals_.fetch_add(1, std::memory_order_acq_rel);
  }
  return out;
}

void NodeCore::Entry::on_enter(Mode /*from*/, Mode /*to*/, const EntryActions& actions) noexcept {
  core->enter(actions, own_m, clock);
}

// The entry actions the state machine declared for this transition (entry_actions()).
void NodeCore::enter(const EntryActions& a, double own_m, std::chrono::nanoseconds clock) noexcept {
  // A fresh law at each stage: no offset, no stale filter state, the coupling fading in.
  // Not on unclutch: the law absorbs the operator's indexing offset (master_law.hpp).
  if (a.reset_law) side_->reset_law(own_m);
  if (a.forget_peer_restart) peer_restarted_ = false;
  // The scene starts at the first engagement; the (simulated) operator takes it up again at
  // each later one.
  if (a.device_engaged) device_.on_engaged();
  if (a.device_disengaged) device_.on_disengaged();
  if (a.start_safe_ramp) {
    safe_since_ = clock;
    safe_from_N_ = last_command_N_;
  }
}

// Own state to the peer (the sender thread sends it).
void NodeCore::publish_state(std::chrono::nanoseconds now, Mode mode, double own_m,
                             double velocity_m_per_s, double measured_force_N,
                             std::int64_t peer_age_ns, std::uint32_t flags) noexcept {
  transport::NodeStateRecord state;
  state.session_id = settings_.session_id;
  state.sequence = sequence_;
  state.sample_time_ns = now.count();
  state.last_peer_sequence = have_peer_ ? peer_.state.sequence : 0;
  state.peer_age_ns = peer_age_ns;
  state.role = settings_.role;
  state.mode = wire_mode(mode);
  state.position_m = own_m;
  state.velocity_m_per_s = velocity_m_per_s;
  side_->publish(state, mode, measured_force_N);
  const FixtureParams& fixture = side_->own_fixture(active_);
  if (fixture.stiffness_N_per_m > 0.0 && own_m > fixture.position_m) {
    state.fixture_in_contact = true;
    state.fixture_penetration_m = own_m - fixture.position_m;
    state.fixture_force_N = fixture.stiffness_N_per_m * state.fixture_penetration_m;
  }
  state.fault_flags = flags;
  state.config_fingerprint = settings_.config_fingerprint;
  state.parameter_change_id = active_.change_id;
  active_change_id_.store(active_.change_id, std::memory_order_release);
  round_trip_.sent(sequence_, now);
  state_out_.write(state);
  published_.fetch_add(1, std::memory_order_release);
  published_.notify_one();
}

void NodeCore::publish_stats(const rt::LoopTiming* timing, std::int64_t peer_age_ns) noexcept {
  LoopSnapshot s;
  fill_loop_snapshot(s, timing, sequence_,
                     LinkSnapshotInputs{round_trip_ns_, &round_trip_window_, peer_restarts_,
                                        have_peer_ ? peer_.state.session_id : 0, peer_age_ns});
  stats_out_.write(s);
}

}  // namespace teleop::node
