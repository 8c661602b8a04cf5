// What differs between the master's and the slave's node (node_core.hpp): the law each runs,
// what each commands in each mode, what each publishes of itself, who counts the master's
// sequence and who takes the clutch. NodeCore asks its side instead of branching on the role.
// Everything but make() is RT-safe (no allocation, lock, I/O or throw).
#pragma once

#include <cstdint>
#include <memory>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/core/rt_safe.hpp"
#include "common/node/node_state_machine.hpp"
#include "common/transport/node_state_codec.hpp"

namespace teleop::node {

struct NodeSettings;
struct ActiveLaw;

// One cycle as a side's command needs it.
struct SideCycle {
  Mode mode{Mode::kDisarmed};
  double weight{0.0};  // the coupling weight (engage ramp), or the safe ramp's in safe
  double position_m{0.0};
  double velocity_m_per_s{0.0};
  double measured_force_N{0.0};
  bool coupled{false};  // a peer state that is coupled too, and no device fault
  bool have_peer{false};
  const transport::NodeStateRecord* peer{nullptr};  // the newest (zeros before any), never null
  double safe_from_N{0.0};                          // the command when safe began
};

class NodeSide {
 public:
  virtual ~NodeSide() = default;
  // The side of `settings.role`; throws std::invalid_argument for another role or bad law
  // parameters.
  [[nodiscard]] static std::unique_ptr<NodeSide> make(const NodeSettings& settings);

  TELEOP_RT [[nodiscard]] virtual bool law_faulted() const noexcept = 0;
  // A fresh law at `position_m`: no offset, no stale filter state, the coupling fading in.
  TELEOP_RT virtual void reset_law(double position_m) noexcept = 0;
  // The parameters in force (a guarded change, ramped by the caller).
  TELEOP_RT virtual void retune(const ActiveLaw& active) noexcept = 0;
  // alpha x_m - x_s (slave coordinates) from this side's position and the peer's.
  TELEOP_RT [[nodiscard]] virtual double alignment_gap_m(double own_m,
                                                         double peer_m) const noexcept = 0;
  // Whether the operator's clutch commands are this side's (the slave holds by itself while
  // the master indexes).
  TELEOP_RT [[nodiscard]] virtual bool takes_clutch() const noexcept = 0;
  // The master's sequence as this side knows it: its own on the master, the newest master
  // state's on the slave.
  TELEOP_RT [[nodiscard]] virtual std::uint64_t master_sequence(
      std::uint64_t own, bool have_peer, std::uint64_t peer) const noexcept = 0;
  // The actuator command of this cycle, N (law flags or-ed into `flags`).
  TELEOP_RT [[nodiscard]] virtual double command(const SideCycle& c,
                                                 std::uint32_t& flags) noexcept = 0;
  // What this side publishes of itself beyond position and velocity: the master its
  // clutch-corrected position while coupled, the slave its measured force.
  TELEOP_RT virtual void publish(transport::NodeStateRecord& s, Mode mode,
                                 double measured_force_N) const noexcept = 0;
  // This side's fixture among the parameters in force.
  TELEOP_RT [[nodiscard]] virtual const FixtureParams& own_fixture(
      const ActiveLaw& a) const noexcept = 0;
};

// Law flag bits (CycleRecord::flags) of a law's command flags.
TELEOP_RT [[nodiscard]] std::uint32_t law_flags(const control::CommandFlags& f) noexcept;

}  // namespace teleop::node
