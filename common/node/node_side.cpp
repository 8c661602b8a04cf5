#include "common/node/node_side.hpp"

#include <algorithm>
#include <stdexcept>

#include "common/core/rt_safe.hpp"
#include "common/node/node_core.hpp"

namespace teleop::node {
namespace {

// What both sides do alike with their own law (MasterLaw or SlaveLaw): its fault latch, its
// reset, its retune with the side's own fixture (`kOwnFixture` of the active law); and the
// position scaling alpha both need.
template <typename Law, FixtureParams ActiveLaw::*kOwnFixture>
class LawSide : public NodeSide {
 public:
  explicit LawSide(const NodeSettings& s) : law_(s.law), alpha_(s.law.scaling.position) {}

  TELEOP_RT bool law_faulted() const noexcept final { return law_.faulted(); }
  TELEOP_RT void reset_law(double position_m) noexcept final { law_.reset(position_m); }
  TELEOP_RT void retune(const ActiveLaw& a) noexcept final { law_.retune(a.gains, a.*kOwnFixture); }
  TELEOP_RT const FixtureParams& own_fixture(const ActiveLaw& a) const noexcept final {
    return a.*kOwnFixture;
  }

 protected:
  Law law_;
  double alpha_;
};

class MasterSide final : public LawSide<control::MasterLaw, &ActiveLaw::master_fixture> {
 public:
  explicit MasterSide(const NodeSettings& s) : LawSide(s), alignment_(s.alignment) {}

  TELEOP_RT double alignment_gap_m(double own_m, double peer_m) const noexcept override {
    return alpha_ * own_m - peer_m;
  }
  TELEOP_RT bool takes_clutch() const noexcept override { return true; }
  TELEOP_RT std::uint64_t master_sequence(std::uint64_t own, bool,
                                          std::uint64_t) const noexcept override {
    return own;
  }

  TELEOP_RT double command(const SideCycle& c, std::uint32_t& flags) noexcept override {
    switch (c.mode) {
      case Mode::kAligning:
        return centring(c);
      case Mode::kEngaged:
      case Mode::kClutched: {
        law_.set_clutch(c.mode == Mode::kClutched);
        const control::PeerState slave{c.peer->position_m, c.peer->velocity_m_per_s,
                                       c.peer->force_N, false, c.coupled};
        const control::Command out = law_.step(c.position_m, slave);
        flags |= law_flags(out.flags);
        // The master's actuator is pushed by -F_am (docs/architecture.md §2.1).
        return c.weight * -out.force_N + (1.0 - c.weight) * centring(c);
      }
      case Mode::kSafe:
        return c.safe_from_N * c.weight;
      case Mode::kDisarmed:
      case Mode::kArmed:
      case Mode::kFault:
        break;
    }
    return 0.0;
  }

  TELEOP_RT void publish(transport::NodeStateRecord& s, Mode mode, double) const noexcept override {
    s.force_N = 0.0;
    if (mode != Mode::kEngaged && mode != Mode::kClutched) return;
    const control::PeerState published = law_.peer_state();
    s.position_m = published.position_m;
    s.velocity_m_per_s = published.velocity_m_per_s;
    s.clutched = published.clutched;
  }

 private:
  // Toward the slave's position in master coordinates; the device is pushed along +x.
  TELEOP_RT double centring(const SideCycle& c) const noexcept {
    if (!c.have_peer) return 0.0;
    const double target_m = c.peer->position_m / alpha_;
    const double f = -alignment_.centring_stiffness_N_per_m * (c.position_m - target_m) -
                     alignment_.centring_damping_Ns_per_m * c.velocity_m_per_s;
    return std::clamp(f, -alignment_.centring_max_force_N, alignment_.centring_max_force_N);
  }

  AlignmentParams alignment_;
};

class SlaveSide final : public LawSide<control::SlaveLaw, &ActiveLaw::slave_fixture> {
 public:
  explicit SlaveSide(const NodeSettings& s) : LawSide(s) {}

  TELEOP_RT double alignment_gap_m(double own_m, double peer_m) const noexcept override {
    return alpha_ * peer_m - own_m;
  }
  TELEOP_RT bool takes_clutch() const noexcept override { return false; }
  TELEOP_RT std::uint64_t master_sequence(std::uint64_t, bool have_peer,
                                          std::uint64_t peer) const noexcept override {
    return have_peer ? peer : 0;
  }

  TELEOP_RT double command(const SideCycle& c, std::uint32_t& flags) noexcept override {
    switch (c.mode) {
      case Mode::kAligning:
      case Mode::kEngaged:
      case Mode::kClutched:
      case Mode::kSafe: {
        // Not coupled (aligning, safe, or the master not engaged yet): the law holds the slave
        // where it is with its own spring and damping.
        const bool follow = c.coupled && (c.mode == Mode::kEngaged || c.mode == Mode::kClutched);
        const control::PeerState master{c.peer->position_m, c.peer->velocity_m_per_s, 0.0,
                                        c.peer->clutched, follow};
        const control::Command out = law_.step(c.position_m, c.measured_force_N, master);
        flags |= law_flags(out.flags);
        return out.force_N;
      }
      case Mode::kDisarmed:
      case Mode::kArmed:
      case Mode::kFault:
        break;
    }
    return 0.0;
  }

  TELEOP_RT void publish(transport::NodeStateRecord& s, Mode,
                         double measured_force_N) const noexcept override {
    s.force_N = measured_force_N;
  }
};

}  // namespace

std::unique_ptr<NodeSide> NodeSide::make(const NodeSettings& settings) {
  switch (settings.role) {
    case transport::Role::kMaster:
      return std::make_unique<MasterSide>(settings);
    case transport::Role::kSlave:
      return std::make_unique<SlaveSide>(settings);
    default:
      break;
  }
  throw std::invalid_argument("node role must be master or slave");
}

std::uint32_t law_flags(const control::CommandFlags& f) noexcept {
  std::uint32_t bits = 0;
  if (f.saturated) bits |= LawFlagBits::kSaturated;
  if (f.rate_limited) bits |= LawFlagBits::kRateLimited;
  if (f.reference_limited) bits |= LawFlagBits::kReferenceLimited;
  if (f.limit_violation) bits |= LawFlagBits::kLimitViolation;
  if (f.input_fault) bits |= LawFlagBits::kInputFault;
  return bits;
}

}  // namespace teleop::node
