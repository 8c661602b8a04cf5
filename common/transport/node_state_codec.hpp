// NodeState on the wire: protobuf bytes <-> the plain record the nodes use, and the receiver's
// guard against what a network does to packets (docs/architecture.md §3.2: protobuf stops here; the
// nodes' RT code sees the plain record). Runs on the link thread (protobuf allocates), never on the
// RT thread.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "common/core/rt_safe.hpp"
#include "common/core/teleop_axes.hpp"

namespace teleop::transport {

enum class Role : std::uint8_t { kUnknown, kMaster, kSlave };

// The plain record (trivially copyable, so it can cross to the RT thread by LatestValue).
struct NodeStateRecord {
  std::uint64_t session_id{0};
  std::uint64_t sequence{0};
  std::int64_t sample_time_ns{0};
  std::uint64_t last_peer_sequence{0};
  std::int64_t peer_age_ns{0};
  Role role{Role::kUnknown};
  int mode{0};  // teleop.v1.NodeMode value
  double position_m{0.0};
  double velocity_m_per_s{0.0};
  double force_N{0.0};
  bool fixture_in_contact{false};
  double fixture_penetration_m{0.0};
  double fixture_force_N{0.0};
  bool clutched{false};
  std::uint32_t fault_flags{0};
  // docs/nodes.md "Before engage": the sender's configuration fingerprint (0: none, an older node)
  // and the guarded parameter change it runs (0: the file's).
  std::uint64_t config_fingerprint{0};
  std::uint64_t parameter_change_id{0};
  // Issue 18: n task-space axes (1..kMaxAxes), axis j in entry j of the arrays (entries from
  // `axes` on are unused). What encode() sends: at axes = 1 the scalar fields above, exactly as a
  // one-axis node always has (the arrays are not read); at axes > 1 the arrays, with entry 0
  // also sent as the scalar fields (the scalar members are not read). A received record has both
  // views filled: the scalars are axis 0 and entry 0 equals them at every n. set_axis() keeps
  // the two views equal on the sending side too.
  int axes{1};
  std::array<double, kMaxAxes> positions_m{};
  std::array<double, kMaxAxes> velocities_m_per_s{};
  std::array<double, kMaxAxes> forces_N{};

  // Axis j's position (m), velocity (m/s) and force (N); axis 0 goes to the scalars as well.
  // j must be < kMaxAxes.
  TELEOP_RT void set_axis(std::size_t j, double position, double velocity, double force) noexcept {
    positions_m[j] = position;
    velocities_m_per_s[j] = velocity;
    forces_N[j] = force;
    if (j == 0) {
      position_m = position;
      velocity_m_per_s = velocity;
      force_N = force;
    }
  }
};

[[nodiscard]] std::string encode(const NodeStateRecord& record);

// Why a received packet did not reach the control law.
enum class Rejection : std::uint8_t {
  kMalformed,     // not a NodeState, or truncated
  kNonFinite,     // NaN or infinity in a physical field
  kWrongRole,     // not from the expected peer role
  kStale,         // sequence not newer than the last accepted one: duplicate, replay, reorder
  kWrongSession,  // from a session of the peer that has ended (a replay from a capture)
  kWrongAxes,     // a well-formed state with another number of task-space axes than ours
  kCount,
};
[[nodiscard]] const char* to_string(Rejection r);

// Accepts only well-formed, finite, newer states from the expected role with the expected
// number of task-space axes (1 unless told: a one-axis node's callers are unchanged); a new
// session id (the peer restarted) is accepted and reported, so the node can drop to safe and
// require a new engagement. Counts every rejection by reason. An expected_axes outside
// 1..kMaxAxes throws std::invalid_argument naming it.
class PeerStateFilter {
 public:
  explicit PeerStateFilter(Role expected_peer, int expected_axes = 1);

  struct Accepted {
    NodeStateRecord record{};
    bool new_session{false};  // the first state, or the peer restarted
  };
  [[nodiscard]] std::optional<Accepted> accept(std::string_view bytes);

  [[nodiscard]] std::uint64_t rejected(Rejection r) const {
    return rejected_[static_cast<std::size_t>(r)];
  }
  [[nodiscard]] std::uint64_t accepted() const { return accepted_; }
  // Sequence numbers of the current session never received (gaps between accepted states).
  [[nodiscard]] std::uint64_t lost() const { return lost_; }

 private:
  Role expected_;
  int expected_axes_{1};
  std::optional<std::uint64_t> session_{};
  std::uint64_t last_sequence_{0};
  std::uint64_t accepted_{0};
  std::uint64_t lost_{0};
  // Sessions the peer has left, newest overwriting oldest.
  std::array<std::uint64_t, 16> retired_{};
  std::size_t retired_next_{0};
  std::array<std::uint64_t, static_cast<std::size_t>(Rejection::kCount)> rejected_{};
};

// Round trip from echoed sequence numbers, without synchronised clocks: remember when each of
// our sequences was sent; when the peer echoes one with the time it held it, the round trip is
// now - sent - held. Fixed-size ring: no allocation.
class RoundTripEstimator {
 public:
  static constexpr std::size_t kHistory = 1024;

  TELEOP_RT void sent(std::uint64_t sequence, std::chrono::nanoseconds at) noexcept;
  // The round trip this echo shows, if the echoed sequence is still in the history.
  TELEOP_RT [[nodiscard]] std::optional<std::chrono::nanoseconds> echoed(
      std::uint64_t sequence, std::chrono::nanoseconds peer_held,
      std::chrono::nanoseconds now) const noexcept;
  // Rounded up to whole periods, as the stability model takes it (docs/architecture.md §2.5).
  TELEOP_RT [[nodiscard]] static int samples(std::chrono::nanoseconds round_trip,
                                             std::chrono::nanoseconds period) noexcept;

 private:
  std::array<std::uint64_t, kHistory> sequence_{};
  std::array<std::int64_t, kHistory> sent_ns_{};
};

}  // namespace teleop::transport
