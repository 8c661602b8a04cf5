#include "common/transport/node_state_codec.hpp"

#include <zlib.h>

#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>

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

// Equal bit for bit (a NaN equals itself here; 0.0 and -0.0 differ).
bool same_bits(double a, double b) {
  std::uint64_t x = 0;
  std::uint64_t y = 0;
  std::memcpy(&x, &a, sizeof x);
  std::memcpy(&y, &b, sizeof y);
  return x == y;
}

// The number of task-space axes a parsed state carries, or 0 if its axis fields break the rule
// of node_state.proto: absent axes means one axis and no repeated fields; present, 1..kMaxAxes
// with every repeated field that long and entry 0 equal to the scalar fields.
int wire_axes(const teleop::v1::NodeState& m) {
  const int positions = m.positions_m_size();
  const int velocities = m.velocities_m_per_s_size();
  const int forces = m.forces_n_size();
  if (!m.has_axes()) return positions == 0 && velocities == 0 && forces == 0 ? 1 : 0;
  if (m.axes() < 1 || m.axes() > static_cast<std::uint32_t>(kMaxAxes)) return 0;
  const int n = static_cast<int>(m.axes());
  if (positions != n || velocities != n || forces != n) return 0;
  if (!same_bits(m.positions_m(0), m.position_m()) ||
      !same_bits(m.velocities_m_per_s(0), m.velocity_m_per_s()) ||
      !same_bits(m.forces_n(0), m.force_n())) {
    return 0;
  }
  return n;
}

bool all_finite(const google::protobuf::RepeatedField<double>& values) {
  for (const double v : values) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

bool physical_fields_finite(const teleop::v1::NodeState& m) {
  for (const double v : {m.position_m(), m.velocity_m_per_s(), m.force_n(),
                         m.fixture().penetration_m(), m.fixture().force_n()}) {
    if (!std::isfinite(v)) return false;
  }
  return all_finite(m.positions_m()) && all_finite(m.velocities_m_per_s()) &&
         all_finite(m.forces_n());
}

void set_axes(teleop::v1::NodeState& m, const NodeStateRecord& r) {
  if (r.axes < 1 || r.axes > kMaxAxes) {
    throw std::invalid_argument("NodeStateRecord.axes must be 1.." + std::to_string(kMaxAxes) +
                                ", got " + std::to_string(r.axes));
  }
  if (r.axes == 1) {  // today's bytes: the scalars alone
    m.set_position_m(r.position_m);
    m.set_velocity_m_per_s(r.velocity_m_per_s);
    m.set_force_n(r.force_N);
    return;
  }
  m.set_position_m(r.positions_m[0]);
  m.set_velocity_m_per_s(r.velocities_m_per_s[0]);
  m.set_force_n(r.forces_N[0]);
  m.set_axes(static_cast<std::uint32_t>(r.axes));
  const auto n = static_cast<std::size_t>(r.axes);
  for (std::size_t j = 0; j < n; ++j) {
    m.add_positions_m(r.positions_m[j]);
    m.add_velocities_m_per_s(r.velocities_m_per_s[j]);
    m.add_forces_n(r.forces_N[j]);
  }
}

void to_record(const teleop::v1::NodeState& m, int axes, NodeStateRecord& r) {
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
  r.axes = axes;
  r.positions_m = {};
  r.velocities_m_per_s = {};
  r.forces_N = {};
  r.set_axis(0, r.position_m, r.velocity_m_per_s, r.force_N);
  if (m.has_axes()) {
    for (int j = 1; j < axes; ++j) {
      r.set_axis(static_cast<std::size_t>(j), m.positions_m(j), m.velocities_m_per_s(j),
                 m.forces_n(j));
    }
  }
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
    case Rejection::kWrongAxes:
      return "wrong_axes";
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
  set_axes(m, r);
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

PeerStateFilter::PeerStateFilter(Role expected_peer, int expected_axes)
    : expected_(expected_peer), expected_axes_(expected_axes) {
  if (expected_axes < 1 || expected_axes > kMaxAxes) {
    throw std::invalid_argument("PeerStateFilter expected_axes must be 1.." +
                                std::to_string(kMaxAxes) + ", got " +
                                std::to_string(expected_axes));
  }
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
  const int axes = wire_axes(m);
  if (axes == 0) return reject(Rejection::kMalformed);
  if (!physical_fields_finite(m)) return reject(Rejection::kNonFinite);
  if (from_proto(m.role()) != expected_) return reject(Rejection::kWrongRole);
  if (axes != expected_axes_) return reject(Rejection::kWrongAxes);
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
  to_record(m, axes, out.record);
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
