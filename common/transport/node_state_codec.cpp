#include "common/transport/node_state_codec.hpp"

#include <zlib.h>

#include <cmath>

#include "teleop/v1/node_state.pb.h"

namespace teleop::transport {

namespace {

teleop::v1::NodeRole to_proto(Role r) {
  switch (r) {
    case Role::kMaster:
      return teleop::v1::MASTER;
    case Role::kSlave:
      return teleop::v1::SLAVE;
    case Role::kUnknown:
      break;
  }
  return teleop::v1::NODE_ROLE_UNSPECIFIED;
}

Role from_proto(teleop::v1::NodeRole r) {
  switch (r) {
    case teleop::v1::MASTER:
      return Role::kMaster;
    case teleop::v1::SLAVE:
      return Role::kSlave;
    default:
      return Role::kUnknown;
  }
}

// The crc32 field (number 15, wire type 5) is one tag byte and four bytes, last on the wire:
// the encoder appends it by hand after every other field (16 and 17 too), so it covers them.
constexpr std::size_t kCrcFieldBytes = 5;
constexpr char kCrcTag = static_cast<char>((15 << 3) | 5);

std::uint32_t checksum(std::string_view bytes) {
  return static_cast<std::uint32_t>(
      ::crc32(0L, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(bytes.size())));
}

}  // namespace

const char* to_string(Rejection r) {
  switch (r) {
    case Rejection::kMalformed:
      return "malformed";
    case Rejection::kNonFinite:
      return "non_finite";
    case Rejection::kWrongRole:
      return "wrong_role";
    case Rejection::kWrongSession:
      return "wrong_session";
    case Rejection::kStale:
      return "stale";
    case Rejection::kCount:
      break;
  }
  return "unknown";
}

std::string encode(const NodeStateRecord& r) {
  teleop::v1::NodeState m;
  m.set_session_id(r.session_id);
  m.set_sequence(r.sequence);
  m.set_sample_time_ns(r.sample_time_ns);
  m.set_last_peer_sequence(r.last_peer_sequence);
  m.set_peer_age_ns(r.peer_age_ns);
  m.set_role(to_proto(r.role));
  m.set_mode(static_cast<teleop::v1::NodeMode>(r.mode));
  m.set_position_m(r.position_m);
  m.set_velocity_m_per_s(r.velocity_m_per_s);
  m.set_force_n(r.force_N);
  m.mutable_fixture()->set_in_contact(r.fixture_in_contact);
  m.mutable_fixture()->set_penetration_m(r.fixture_penetration_m);
  m.mutable_fixture()->set_force_n(r.fixture_force_N);
  m.set_clutched(r.clutched);
  m.set_fault_flags(r.fault_flags);
  m.set_config_fingerprint(r.config_fingerprint);
  m.set_parameter_change_id(r.parameter_change_id);
  std::string bytes = m.SerializeAsString();
  const std::uint32_t crc = checksum(bytes);
  bytes.push_back(kCrcTag);
  for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<char>((crc >> (8 * i)) & 0xFFU));
  return bytes;
}

std::optional<PeerStateFilter::Accepted> PeerStateFilter::accept(std::string_view bytes) {
  auto reject = [&](Rejection r) -> std::optional<Accepted> {
    ++rejected_[static_cast<std::size_t>(r)];
    return std::nullopt;
  };
  teleop::v1::NodeState m;
  if (bytes.size() > 4096 || !m.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())) ||
      m.sequence() == 0 || m.session_id() == 0 || !m.has_crc32() || bytes.size() < kCrcFieldBytes ||
      bytes[bytes.size() - kCrcFieldBytes] != kCrcTag ||
      checksum(bytes.substr(0, bytes.size() - kCrcFieldBytes)) != m.crc32()) {
    return reject(Rejection::kMalformed);
  }
  for (const double v : {m.position_m(), m.velocity_m_per_s(), m.force_n(),
                         m.fixture().penetration_m(), m.fixture().force_n()}) {
    if (!std::isfinite(v)) return reject(Rejection::kNonFinite);
  }
  if (from_proto(m.role()) != expected_) return reject(Rejection::kWrongRole);
  Accepted out;
  out.new_session = !session_ || *session_ != m.session_id();
  if (!out.new_session && m.sequence() <= last_sequence_) return reject(Rejection::kStale);
  if (out.new_session) {
    // A session the peer has left can only come back as a replay: a restarted peer draws a
    // new random id.
    for (const std::uint64_t old : retired_) {
      if (old == m.session_id()) return reject(Rejection::kWrongSession);
    }
    if (session_) {
      retired_[retired_next_ % retired_.size()] = *session_;
      ++retired_next_;
    }
  } else {
    lost_ += m.sequence() - last_sequence_ - 1;
  }
  session_ = m.session_id();
  last_sequence_ = m.sequence();
  ++accepted_;
  NodeStateRecord& r = out.record;
  r.session_id = m.session_id();
  r.sequence = m.sequence();
  r.sample_time_ns = m.sample_time_ns();
  r.last_peer_sequence = m.last_peer_sequence();
  r.peer_age_ns = m.peer_age_ns();
  r.role = from_proto(m.role());
  r.mode = static_cast<int>(m.mode());
  r.position_m = m.position_m();
  r.velocity_m_per_s = m.velocity_m_per_s();
  r.force_N = m.force_n();
  r.fixture_in_contact = m.fixture().in_contact();
  r.fixture_penetration_m = m.fixture().penetration_m();
  r.fixture_force_N = m.fixture().force_n();
  r.clutched = m.clutched();
  r.fault_flags = m.fault_flags();
  r.config_fingerprint = m.config_fingerprint();
  r.parameter_change_id = m.parameter_change_id();
  return out;
}

void RoundTripEstimator::sent(std::uint64_t sequence, std::chrono::nanoseconds at) noexcept {
  const std::size_t slot = sequence % kHistory;
  sequence_[slot] = sequence;
  sent_ns_[slot] = at.count();
}

std::optional<std::chrono::nanoseconds> RoundTripEstimator::echoed(
    std::uint64_t sequence, std::chrono::nanoseconds peer_held,
    std::chrono::nanoseconds now) const noexcept {
  const std::size_t slot = sequence % kHistory;
  if (sequence == 0 || sequence_[slot] != sequence) return std::nullopt;
  const auto rtt = now - std::chrono::nanoseconds(sent_ns_[slot]) - peer_held;
  if (rtt.count() < 0) return std::nullopt;
  return rtt;
}

int RoundTripEstimator::samples(std::chrono::nanoseconds round_trip,
                                std::chrono::nanoseconds period) noexcept {
  if (period.count() <= 0) return 0;
  return static_cast<int>((round_trip.count() + period.count() - 1) / period.count());
}

}  // namespace teleop::transport
