#include "common/node/node_core_axes.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "common/node/cycle_checks.hpp"
#include "common/node/node_side.hpp"

namespace teleop::node {
namespace {

using transport::Role;
using Vec = control::AxisVector;

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

template <std::size_t... I>
std::array<control::VelocityEstimator, kMaxAxes> make_estimators(double period_s, double cutoff_hz,
                                                                 std::index_sequence<I...>) {
  return {((void)I, control::VelocityEstimator(period_s, cutoff_hz))...};
}

// The first n entries of a record's array.
TELEOP_RT Vec head(const std::array<double, kMaxAxes>& a, int n) noexcept {
  Vec v = Vec::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) v(i) = a[static_cast<std::size_t>(i)];
  return v;
}

// The peer's state as a law takes it (n entries each).
TELEOP_RT control::PeerStateAxes peer_axes(const transport::NodeStateRecord& r, int n,
                                           bool clutched, bool valid) noexcept {
  control::PeerStateAxes p;
  p.position_m = head(r.positions_m, n);
  p.velocity_m_per_s = head(r.velocities_m_per_s, n);
  p.force_N = head(r.forces_N, n);
  p.clutched = clutched;
  p.valid = valid;
  return p;
}

// The seven gain matrices in GainValuesAxes' order.
constexpr std::array<control::AxisMatrix control::LawGainsAxes::*, kGainMatrices> kGainOrder{
    &control::LawGainsAxes::kpm, &control::LawGainsAxes::kps, &control::LawGainsAxes::kdm,
    &control::LawGainsAxes::kds, &control::LawGainsAxes::kvm, &control::LawGainsAxes::kvs,
    &control::LawGainsAxes::kfm};

// The stiffnesses of a side's planes.
PlaneStiffnessesAxes stiffnesses(const control::PlaneSet& planes) noexcept {
  PlaneStiffnessesAxes k{};
  for (int i = 0; i < planes.size(); ++i) {
    k[static_cast<std::size_t>(i)] = planes.plane(i).stiffness_N_per_m;
  }
  return k;
}

}  // namespace

GainValuesAxes gain_values(const control::LawGainsAxes& gains, int n) noexcept {
  GainValuesAxes out{};
  for (std::size_t g = 0; g < kGainMatrices; ++g) {
    const control::AxisMatrix& m = gains.*kGainOrder[g];
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < n; ++c) out[g][static_cast<std::size_t>(r * n + c)] = m(r, c);
    }
  }
  return out;
}

void to_law_gains(const GainValuesAxes& values, int n, control::LawGainsAxes& out) noexcept {
  for (std::size_t g = 0; g < kGainMatrices; ++g) {
    control::AxisMatrix& m = out.*kGainOrder[g];
    m = control::AxisMatrix::Zero(n, n);  // fixed capacity: no allocation
    for (int r = 0; r < n; ++r) {
      for (int c = 0; c < n; ++c) m(r, c) = values[g][static_cast<std::size_t>(r * n + c)];
    }
  }
}

// One cycle as the role's command needs it.
struct SideCycleAxes {
  Mode mode{Mode::kDisarmed};
  double weight{0.0};  // the coupling weight (engage ramp), or the safe ramp's in safe
  const Vec* position_m{nullptr};
  const Vec* velocity_m_per_s{nullptr};
  const Vec* measured_force_N{nullptr};
  bool coupled{false};
  bool have_peer{false};
  const transport::NodeStateRecord* peer{nullptr};
  const Vec* safe_from_N{nullptr};
};

// What differs between master and slave (node_side.hpp's split, with the n-axis laws). One of
// the two laws exists.
class NodeCoreAxes::Side {
 public:
  explicit Side(const NodeAxesSettings& s)
      : alignment_(s.alignment),
        alpha_(s.law.scaling.position),
        n_(s.law.axes),
        planes_(s.role == Role::kMaster ? s.law.master_planes : s.law.slave_planes) {
    if (s.role == Role::kMaster) {
      master_ = std::make_unique<control::MasterLawAxes>(s.law);
    } else if (s.role == Role::kSlave) {
      slave_ = std::make_unique<control::SlaveLawAxes>(s.law);
    } else {
      throw std::invalid_argument("NodeAxesSettings.role: must be master or slave");
    }
  }

  TELEOP_RT [[nodiscard]] bool is_master() const noexcept { return master_ != nullptr; }
  TELEOP_RT [[nodiscard]] bool law_faulted() const noexcept {
    return is_master() ? master_->faulted() : slave_->faulted();
  }
  TELEOP_RT void reset_law(const Vec& position_m) noexcept {
    if (is_master()) {
      master_->reset(position_m);
    } else {
      slave_->reset(position_m);
    }
  }
  // |alpha x_m - x_s| from this side's position and the peer's.
  TELEOP_RT [[nodiscard]] double gap_m(const Vec& own_m, const Vec& peer_m) const noexcept {
    const Vec& x_m = is_master() ? own_m : peer_m;
    const Vec& x_s = is_master() ? peer_m : own_m;
    double sum = 0.0;
    for (Eigen::Index i = 0; i < n_; ++i) {
      const double e = alpha_ * x_m(i) - x_s(i);
      sum += e * e;
    }
    return std::sqrt(sum);
  }
  TELEOP_RT [[nodiscard]] std::uint64_t master_sequence(std::uint64_t own, bool have_peer,
                                                        std::uint64_t peer) const noexcept {
    if (is_master()) return own;
    return have_peer ? peer : 0;
  }

  TELEOP_RT [[nodiscard]] Vec command(const SideCycleAxes& c, std::uint32_t& flags,
                                      unsigned& saturated, unsigned& rate_limited) noexcept {
    if (c.mode == Mode::kDisarmed || c.mode == Mode::kArmed || c.mode == Mode::kFault) {
      return Vec::Zero(n_);
    }
    if (is_master()) return master_command(c, flags, saturated, rate_limited);
    // Not coupled (aligning, safe, or the master not engaged yet): the law holds the slave
    // where it is with its own spring and damping.
    const bool follow = c.coupled && (c.mode == Mode::kEngaged || c.mode == Mode::kClutched);
    control::PeerStateAxes master = peer_axes(*c.peer, n_, c.peer->clutched, follow);
    master.force_N.setZero();
    const control::CommandAxes out = slave_->step(*c.position_m, *c.measured_force_N, master);
    note(out, flags, saturated, rate_limited);
    return out.force_N;
  }

  // Own state beyond position and velocity: the master its clutch-corrected position while
  // coupled (force 0), the slave its measured force.
  TELEOP_RT void publish(transport::NodeStateRecord& s, Mode mode, const Vec& own_m,
                         const Vec& velocity, const Vec& measured_force_N) const noexcept {
    const control::PeerStateAxes law =
        is_master() ? master_->peer_state() : control::PeerStateAxes{};
    // The law's view once it has stepped (it has n entries then).
    const bool coupled = (mode == Mode::kEngaged || mode == Mode::kClutched) &&
                         law.position_m.size() == n_ && law.velocity_m_per_s.size() == n_;
    for (Eigen::Index i = 0; i < n_; ++i) {
      const auto j = static_cast<std::size_t>(i);
      if (!is_master()) {
        s.set_axis(j, own_m(i), velocity(i), measured_force_N(i));
      } else if (coupled) {
        s.set_axis(j, law.position_m(i), law.velocity_m_per_s(i), 0.0);
      } else {
        s.set_axis(j, own_m(i), velocity(i), 0.0);
      }
    }
    s.clutched = is_master() && coupled && law.clutched;
  }

  [[nodiscard]] const control::PlaneSet& planes() const noexcept { return planes_; }

  // The law from now on runs `active`'s gains and this side's plane stiffnesses.
  TELEOP_RT void retune(const ActiveLawAxes& active) noexcept {
    control::LawGainsAxes gains;
    to_law_gains(active.gains, n_, gains);
    const PlaneStiffnessesAxes& k =
        is_master() ? active.master_planes_N_per_m : active.slave_planes_N_per_m;
    for (int i = 0; i < planes_.size(); ++i) {
      planes_.set_stiffness(i, k[static_cast<std::size_t>(i)]);
    }
    if (is_master()) {
      master_->retune(gains, planes_);
    } else {
      slave_->retune(gains, planes_);
    }
  }

 private:
  TELEOP_RT static void note(const control::CommandAxes& out, std::uint32_t& flags,
                             unsigned& saturated, unsigned& rate_limited) noexcept {
    flags |= law_flags(out.flags);
    saturated |= out.saturated_axes;
    rate_limited |= out.rate_limited_axes;
  }

  TELEOP_RT [[nodiscard]] Vec master_command(const SideCycleAxes& c, std::uint32_t& flags,
                                             unsigned& saturated, unsigned& rate_limited) noexcept {
    if (c.mode == Mode::kAligning) return centring(c);
    if (c.mode == Mode::kSafe) {
      Vec f = Vec::Zero(n_);
      for (Eigen::Index i = 0; i < n_; ++i) f(i) = (*c.safe_from_N)(i)*c.weight;
      return f;
    }
    // Engaged or clutched.
    master_->set_clutch(c.mode == Mode::kClutched);
    const control::PeerStateAxes slave = peer_axes(*c.peer, n_, false, c.coupled);
    const control::CommandAxes out = master_->step(*c.position_m, slave);
    note(out, flags, saturated, rate_limited);
    // The master's actuator is pushed by -F_am (docs/architecture.md §2.1).
    const Vec centre = centring(c);
    Vec f = Vec::Zero(n_);
    for (Eigen::Index i = 0; i < n_; ++i) {
      f(i) = c.weight * -out.force_N(i) + (1.0 - c.weight) * centre(i);
    }
    return f;
  }

  // Toward the slave's position in master coordinates, its norm clamped (direction kept).
  TELEOP_RT [[nodiscard]] Vec centring(const SideCycleAxes& c) const noexcept {
    Vec f = Vec::Zero(n_);
    if (!c.have_peer) return f;
    double sum = 0.0;
    for (Eigen::Index i = 0; i < n_; ++i) {
      const double target_m = c.peer->positions_m[static_cast<std::size_t>(i)] / alpha_;
      f(i) = -alignment_.centring_stiffness_N_per_m * ((*c.position_m)(i)-target_m) -
             alignment_.centring_damping_Ns_per_m * (*c.velocity_m_per_s)(i);
      sum += f(i) * f(i);
    }
    const double max_N = alignment_.centring_max_force_N;
    const double norm = std::sqrt(sum);
    if (norm <= max_N) return f;
    if (n_ == 1) {
      f(0) = std::clamp(f(0), -max_N, max_N);  // NodeCore's arithmetic, bit for bit
    } else {
      f *= max_N / norm;
    }
    return f;
  }

  std::unique_ptr<control::MasterLawAxes> master_;
  std::unique_ptr<control::SlaveLawAxes> slave_;
  AlignmentParams alignment_;
  double alpha_;
  int n_;
  control::PlaneSet planes_;
};

NodeCoreAxes::NodeCoreAxes(const NodeAxesSettings& settings, device::HapticDeviceAxes& device)
    : settings_(settings),
      device_(device),
      machine_(settings.machine),
      velocity_(make_estimators(std::chrono::duration<double>(settings.period).count(),
                                settings.law.velocity_cutoff_hz,
                                std::make_index_sequence<kMaxAxes>{})) {
  if (settings_.period.count() <= 0) {
    throw std::invalid_argument("NodeAxesSettings.period: must be > 0");
  }
  if (settings_.law.axes != device.axes()) {
    throw std::invalid_argument("NodeAxesSettings.law.axes: must equal the device's axes()");
  }
  side_ = std::make_unique<Side>(settings_);  // validates the law (names the field)
  entry_.core = this;
  machine_.set_entry_handler(&entry_);
  own_m_ = Vec::Zero(axes());
  last_command_N_ = Vec::Zero(axes());
  safe_from_N_ = Vec::Zero(axes());
  active_.axes = axes();
  active_.master_planes = settings_.law.master_planes.size();
  active_.slave_planes = settings_.law.slave_planes.size();
  active_.gains = gain_values(settings_.law.gains, axes());
  active_.master_planes_N_per_m = stiffnesses(settings_.law.master_planes);
  active_.slave_planes_N_per_m = stiffnesses(settings_.law.slave_planes);
  active_out_.write(active_);
}

// As NodeCore::apply_retune, on every gain-matrix element and plane stiffness.
void NodeCoreAxes::apply_retune(std::chrono::nanoseconds now,
                                std::uint64_t master_sequence) noexcept {
  RetuneAxes incoming{};
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
    ramp_to_ = pending_;  // a change posted while this one ramps waits for its own sequence
    active_.change_id = pending_.id;
    active_.applied_at_master_sequence = pending_.apply_at_master_sequence;
  }
  if (!ramping_) return;
  const double length = static_cast<double>(ramp_length_.count());
  const double w =
      length <= 0.0
          ? 1.0
          : std::clamp(static_cast<double>((now - ramp_start_).count()) / length, 0.0, 1.0);
  const auto lerp = [w](double a, double b) { return a + w * (b - a); };
  const auto used = static_cast<std::size_t>(axes() * axes());
  for (std::size_t g = 0; g < kGainMatrices; ++g) {
    for (std::size_t i = 0; i < used; ++i) {
      active_.gains[g][i] = lerp(ramp_from_.gains[g][i], ramp_to_.gains[g][i]);
    }
  }
  for (std::size_t i = 0; i < active_.master_planes_N_per_m.size(); ++i) {
    active_.master_planes_N_per_m[i] =
        lerp(ramp_from_.master_planes_N_per_m[i], ramp_to_.master_planes_N_per_m[i]);
    active_.slave_planes_N_per_m[i] =
        lerp(ramp_from_.slave_planes_N_per_m[i], ramp_to_.slave_planes_N_per_m[i]);
  }
  active_.ramp_progress = w;
  side_->retune(active_);
  if (w >= 1.0) ramping_ = false;
  active_out_.write(active_);
}

NodeCoreAxes::~NodeCoreAxes() = default;

bool NodeCoreAxes::post_command(Command command) noexcept {
  if (!commands_in_.try_push(command)) return false;
  commands_posted_.fetch_add(1, std::memory_order_acq_rel);
  return true;
}

const char* NodeCoreAxes::coupling_refusal() const noexcept {
  if (!settings_.permits_coupling) {
    return settings_.coupling_refusal.empty()
               ? "arm and engage refused: the configuration check at start failed"
               : settings_.coupling_refusal.c_str();
  }
  if (newest_wrong_axes_) {
    return "arm and engage refused: the peer has another number of task-space axes";
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

Vec NodeCoreAxes::peer_positions() const noexcept { return head(peer_.state.positions_m, axes()); }

void NodeCoreAxes::step(std::chrono::nanoseconds now, const rt::LoopTiming* timing) noexcept {
  const std::chrono::nanoseconds clock =
      timing != nullptr && timing->cycles() > 0 ? timing->last_woke() : now;
  step(now, clock, timing);
}

void NodeCoreAxes::step(std::chrono::nanoseconds now, std::chrono::nanoseconds clock,
                        const rt::LoopTiming* timing) noexcept {
  ++sequence_;
  const int n = axes();
  const char* own_stall = stall_.check(clock, settings_.period, settings_.machine.peer_timeout);

  device::SampleAxes sample{};
  const device::Status read = device_.read(sample);
  const bool sized = sample.position_m.size() == n && sample.force_N.size() == n;
  const bool device_fault =
      !read.ok() || !sized || (sample.flags & device::SampleFlags::kFault) != 0;
  own_m_ = sized ? Vec(sample.position_m) : Vec::Zero(n);
  const Vec measured_N = sized ? Vec(sample.force_N) : Vec::Zero(n);
  Vec velocity = Vec::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    auto& estimator = velocity_[static_cast<std::size_t>(i)];
    velocity(i) =
        std::isfinite(own_m_(i)) ? estimator.step(own_m_(i)) : estimator.velocity_m_per_s();
  }
  receive_peer(now);
  const std::int64_t peer_age_ns = peer_state_age_ns(have_peer_, clock, peer_.arrival_ns);
  const Vec peer_m = peer_positions();
  const double gap_m = have_peer_ ? side_->gap_m(own_m_, peer_m) : 0.0;
  entry_.clock = clock;
  CycleOutputs out = decide(now, next_command(), peer_age_ns, gap_m, device_fault, own_stall);
  // Faulted by the device: its own words when it has them (a USB link lost, a device of another
  // protocol version or channel count), the newest each cycle.
  if (out.mode == Mode::kFault && out.reason == kDeviceFaultReason && !read.ok() &&
      read.message != nullptr && *read.message != '\0') {
    out.reason = read.message;
  }
  const Mode mode = out.mode;
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
  unsigned saturated = 0;
  unsigned rate_limited = 0;
  Vec force_N = Vec::Zero(n);
  if (!device_fault) {
    SideCycleAxes c;
    c.mode = mode;
    c.weight = weight;
    c.position_m = &own_m_;
    c.velocity_m_per_s = &velocity;
    c.measured_force_N = &measured_N;
    c.coupled = have_peer_ && peer_coupled(peer_.state.mode);
    c.have_peer = have_peer_;
    c.peer = &peer_.state;
    c.safe_from_N = &safe_from_N_;
    force_N = side_->command(c, flags, saturated, rate_limited);
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    if (!std::isfinite(force_N(i))) force_N(i) = 0.0;
  }
  device::CommandAxes command;
  command.force_N = force_N;
  (void)device_.write(command);
  last_command_N_ = force_N;
  (void)device_.tick(settings_.period);

  double penetration_m = 0.0;
  publish_state(now, mode, velocity, measured_N, peer_age_ns, flags, penetration_m);
  mode_.store(mode, std::memory_order_release);
  reason_.store(out.reason, std::memory_order_release);

  CycleRecordAxes rec;
  rec.sequence = sequence_;
  rec.sample_time_ns = now.count();
  rec.clock_ns = clock.count();
  rec.mode = mode;
  rec.reason = out.reason;
  rec.axes = n;
  for (Eigen::Index i = 0; i < n; ++i) {
    const auto j = static_cast<std::size_t>(i);
    rec.position_m[j] = own_m_(i);
    rec.velocity_m_per_s[j] = velocity(i);
    rec.force_N[j] = measured_N(i);
    rec.command_N[j] = force_N(i);
    rec.peer_position_m[j] = have_peer_ ? peer_m(i) : 0.0;
  }
  rec.peer_sequence = have_peer_ ? peer_.state.sequence : 0;
  rec.peer_age_ns = peer_age_ns;
  rec.coupling_weight = weight;
  rec.flags = flags;
  rec.saturated_axes = saturated;
  rec.rate_limited_axes = rate_limited;
  rec.round_trip_ns = round_trip_ns_;
  rec.master_sequence = master_sequence;
  rec.parameter_change_id = active_.change_id;
  rec.alignment_error_m = gap_m;
  rec.fixture_penetration_m = penetration_m;
  if (timing != nullptr && timing->cycles() > 0) {
    rec.wakeup_latency_ns = timing->last_wakeup_latency().count();
  }
  (void)telemetry_out_.try_push(rec);
  if (sequence_ % NodeCore::kStatsEvery == 1) publish_stats(timing, peer_age_ns);
}

void NodeCoreAxes::publish_stats(const rt::LoopTiming* timing, std::int64_t peer_age_ns) noexcept {
  LoopSnapshot s;
  fill_loop_snapshot(s, timing, sequence_,
                     LinkSnapshotInputs{round_trip_ns_, &round_trip_window_, peer_restarts_,
                                        have_peer_ ? peer_.state.session_id : 0, peer_age_ns});
  stats_out_.write(s);
}

// The newest peer state with this node's number of axes; another count is dropped and noted.
void NodeCoreAxes::receive_peer(std::chrono::nanoseconds now) noexcept {
  round_trip_window_.advance(now.count());  // moves on while no echo comes back
  PeerSample incoming{};
  if (!peer_in_.read(incoming)) return;
  if (incoming.state.axes != axes()) {
    newest_wrong_axes_ = true;
    peer_wrong_axes_.fetch_add(1, std::memory_order_acq_rel);
    return;
  }
  newest_wrong_axes_ = false;
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

Command NodeCoreAxes::next_command() noexcept {
  return take_command(commands_in_, commands_applied_, side_->is_master());
}

CycleOutputs NodeCoreAxes::decide(std::chrono::nanoseconds now, Command command,
                                  std::int64_t peer_age_ns, double gap_m, bool device_fault,
                                  const char* own_stall) noexcept {
  CycleInputs in;
  in.now = now;
  in.command = command;
  in.peer_seen = have_peer_;
  in.peer_age = std::chrono::nanoseconds(peer_age_ns);
  in.aligned =
      have_peer_ && gap_m <= settings_.alignment.tolerance_m && peer_coupling(peer_.state.mode);
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

void NodeCoreAxes::Entry::on_enter(Mode /*from*/, Mode /*to*/,
                                   const EntryActions& actions) noexcept {
  core->enter(actions, clock);
}

void NodeCoreAxes::enter(const EntryActions& a, std::chrono::nanoseconds clock) noexcept {
  if (a.reset_law) side_->reset_law(own_m_);
  if (a.forget_peer_restart) peer_restarted_ = false;
  if (a.device_engaged) device_.on_engaged();
  if (a.device_disengaged) device_.on_disengaged();
  if (a.start_safe_ramp) {
    safe_since_ = clock;
    safe_from_N_ = last_command_N_;
  }
}

void NodeCoreAxes::publish_state(std::chrono::nanoseconds now, Mode mode, const Vec& velocity,
                                 const Vec& measured_force_N, std::int64_t peer_age_ns,
                                 std::uint32_t flags, double& penetration_m) noexcept {
  transport::NodeStateRecord state;
  state.session_id = settings_.session_id;
  state.sequence = sequence_;
  state.sample_time_ns = now.count();
  state.last_peer_sequence = have_peer_ ? peer_.state.sequence : 0;
  state.peer_age_ns = peer_age_ns;
  state.role = settings_.role;
  state.mode = wire_mode(mode);
  state.axes = axes();
  side_->publish(state, mode, own_m_, velocity, measured_force_N);
  // The own law's planes at the raw position: the deepest one's penetration, the summed
  // resistance's norm.
  penetration_m = 0.0;
  if (control::all_finite(own_m_)) {
    const control::PlaneSetOutput planes = side_->planes().evaluate(own_m_);
    if (planes.deepest_plane >= 0) {
      state.fixture_in_contact = true;
      state.fixture_penetration_m = planes.penetration_m;
      state.fixture_force_N = planes.force_N.norm();
      penetration_m = planes.penetration_m;
    }
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

}  // namespace teleop::node
