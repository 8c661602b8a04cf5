// NodeState frames as a node receives them from its peer (common/transport/node_state_codec.hpp).
//
// Input: a stream of frames, each [u8 control][u16 little-endian length][length bytes] (a short
// last frame takes what is left). Control bit 0: append a valid CRC field (tag 0x7D, CRC-32 of
// the bytes before it) so the fuzzer gets past the checksum to the finite, role, session and
// sequence checks. Every frame goes to four receivers: expecting the master or the slave, with
// one task-space axis or three (issue 18). Checked on every frame:
// - exactly one counter moves: accepted, or one rejection reason;
// - an accepted state is from the expected role, has non-zero session and sequence, finite
//   physical fields on every axis, the receiver's axis count, axis 0 in the scalar fields and
//   nothing beyond the last axis, a sequence newer than the last accepted one of its session (or a
//   new session that is not the current one), and ends with its CRC field;
// - the same bytes offered again are rejected as stale (a duplicate or replay);
// - encode() of the accepted record is accepted by a fresh receiver and gives the same record.
#include <cmath>
#include <cstring>
#include <optional>
#include <string>
#include <string_view>

#include "common/transport/node_state_codec.hpp"
#include "fuzz/harness/fuzz_check.hpp"

namespace teleop::fuzz {
namespace {

using transport::NodeStateRecord;
using transport::PeerStateFilter;
using transport::Rejection;
using transport::Role;

constexpr std::size_t kMaxFrames = 64;

std::uint64_t total_rejected(const PeerStateFilter& f) {
  std::uint64_t n = 0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(Rejection::kCount); ++i) {
    n += f.rejected(static_cast<Rejection>(i));
  }
  return n;
}

template <typename T>
bool same_bits(const T& a, const T& b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

bool same_record(const NodeStateRecord& a, const NodeStateRecord& b) {
  return a.session_id == b.session_id && a.sequence == b.sequence &&
         a.sample_time_ns == b.sample_time_ns && a.last_peer_sequence == b.last_peer_sequence &&
         a.peer_age_ns == b.peer_age_ns && a.role == b.role && a.mode == b.mode &&
         same_bits(a.position_m, b.position_m) &&
         same_bits(a.velocity_m_per_s, b.velocity_m_per_s) && same_bits(a.force_N, b.force_N) &&
         a.fixture_in_contact == b.fixture_in_contact &&
         same_bits(a.fixture_penetration_m, b.fixture_penetration_m) &&
         same_bits(a.fixture_force_N, b.fixture_force_N) && a.clutched == b.clutched &&
         a.fault_flags == b.fault_flags && a.config_fingerprint == b.config_fingerprint &&
         a.parameter_change_id == b.parameter_change_id && a.axes == b.axes &&
         same_bits(a.positions_m, b.positions_m) &&
         same_bits(a.velocities_m_per_s, b.velocities_m_per_s) && same_bits(a.forces_N, b.forces_N);
}

std::uint32_t crc32_of(std::string_view bytes) {
  // Bitwise CRC-32 (IEEE, reflected), independent of the codec's zlib call.
  std::uint32_t crc = 0xFFFFFFFFU;
  for (const char ch : bytes) {
    crc ^= static_cast<std::uint8_t>(ch);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1U) ^ (0xEDB88320U & (0U - (crc & 1U)));
  }
  return ~crc;
}

// One receiver and what the harness knows it accepted.
struct Receiver {
  Receiver(Role r, int n) : role(r), axes(n), filter(r, n) {}
  Role role;
  int axes;
  PeerStateFilter filter;
  std::optional<std::uint64_t> session{};
  std::uint64_t last_sequence{0};

  void offer(std::string_view bytes) {
    const std::uint64_t accepted_before = filter.accepted();
    const std::uint64_t rejected_before = total_rejected(filter);
    const std::uint64_t lost_before = filter.lost();
    const auto got = filter.accept(bytes);
    const std::uint64_t accepted_moved = filter.accepted() - accepted_before;
    const std::uint64_t rejected_moved = total_rejected(filter) - rejected_before;
    TELEOP_FUZZ_CHECK(accepted_moved + rejected_moved == 1, "one counter per packet");
    TELEOP_FUZZ_CHECK(got.has_value() == (accepted_moved == 1), "counted as what it returned");
    TELEOP_FUZZ_CHECK(filter.lost() >= lost_before, "lost only grows");
    if (!got) return;

    const NodeStateRecord& r = got->record;
    TELEOP_FUZZ_CHECK(r.role == role, "accepted from the wrong role");
    TELEOP_FUZZ_CHECK(r.session_id != 0 && r.sequence != 0, "zero session or sequence accepted");
    for (const double v : {r.position_m, r.velocity_m_per_s, r.force_N, r.fixture_penetration_m,
                           r.fixture_force_N}) {
      TELEOP_FUZZ_CHECK(std::isfinite(v), "non-finite physical field accepted");
    }
    TELEOP_FUZZ_CHECK(r.axes == axes, "accepted with another axis count");
    for (std::size_t j = 0; j < r.positions_m.size(); ++j) {
      for (const double v : {r.positions_m[j], r.velocities_m_per_s[j], r.forces_N[j]}) {
        TELEOP_FUZZ_CHECK(std::isfinite(v), "non-finite axis accepted");
        if (j >= static_cast<std::size_t>(axes)) TELEOP_FUZZ_CHECK(v == 0.0, "beyond the axes");
      }
    }
    TELEOP_FUZZ_CHECK(same_bits(r.position_m, r.positions_m[0]) &&
                          same_bits(r.velocity_m_per_s, r.velocities_m_per_s[0]) &&
                          same_bits(r.force_N, r.forces_N[0]),
                      "the scalar fields are not axis 0");
    TELEOP_FUZZ_CHECK(
        bytes.size() >= 5 && static_cast<std::uint8_t>(bytes[bytes.size() - 5]) == 0x7D,
        "accepted without the CRC field last on the wire");
    if (got->new_session) {
      TELEOP_FUZZ_CHECK(!session || *session != r.session_id, "new_session for the same session");
    } else {
      TELEOP_FUZZ_CHECK(session && *session == r.session_id, "old session not flagged new");
      TELEOP_FUZZ_CHECK(r.sequence > last_sequence, "sequence not newer than the last accepted");
    }
    session = r.session_id;
    last_sequence = r.sequence;

    // A duplicate (a replayed capture of this very packet) never reaches the law.
    const std::uint64_t stale_before = filter.rejected(Rejection::kStale);
    TELEOP_FUZZ_CHECK(!filter.accept(bytes).has_value(), "the same packet accepted twice");
    TELEOP_FUZZ_CHECK(filter.rejected(Rejection::kStale) == stale_before + 1,
                      "a duplicate not counted as stale");

    // encode -> accept round trip.
    PeerStateFilter fresh(role, axes);
    const std::string encoded = transport::encode(r);
    const auto again = fresh.accept(encoded);
    TELEOP_FUZZ_CHECK(again.has_value(), "encode() of an accepted state is rejected");
    TELEOP_FUZZ_CHECK(again->new_session, "first state of a receiver is a new session");
    TELEOP_FUZZ_CHECK(same_record(again->record, r), "encode/accept round trip changed the state");
  }
};

}  // namespace

int node_state(const std::uint8_t* data, std::size_t size) {
  Receiver receivers[] = {
      {Role::kMaster, 1}, {Role::kSlave, 1}, {Role::kMaster, 3}, {Role::kSlave, 3}};
  std::size_t pos = 0;
  for (std::size_t frames = 0; pos < size && frames < kMaxFrames; ++frames) {
    const std::uint8_t control = data[pos++];
    std::size_t length = 0;
    if (pos + 2 <= size) {
      length =
          static_cast<std::size_t>(data[pos]) | (static_cast<std::size_t>(data[pos + 1]) << 8U);
      pos += 2;
    } else {
      pos = size;
    }
    length = std::min(length, size - pos);
    std::string frame(reinterpret_cast<const char*>(data + pos), length);
    pos += length;
    if ((control & 1U) != 0) {
      const std::uint32_t crc = crc32_of(frame);
      frame.push_back(static_cast<char>(0x7D));
      for (unsigned i = 0; i < 4; ++i)
        frame.push_back(static_cast<char>((crc >> (8U * i)) & 0xFFU));
    }
    for (Receiver& r : receivers) r.offer(frame);
  }
  return 0;
}

}  // namespace teleop::fuzz
