// The wire format and the receiver's guard: what a network does to packets (duplicates,
// replays, reordering, garbage, NaN) never reaches a control law, and each is counted.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <string_view>

#include "common/transport/node_state_codec.hpp"
#include "teleop/v1/node_state.pb.h"

namespace teleop::transport {
namespace {

using std::chrono::microseconds;
using std::chrono::milliseconds;

NodeStateRecord master_state(std::uint64_t seq) {
  NodeStateRecord r;
  r.session_id = 0x1234'5678'9abc'def0ULL;
  r.sequence = seq;
  r.sample_time_ns = static_cast<std::int64_t>(seq) * 1'000'000;
  r.last_peer_sequence = seq - 1;
  r.peer_age_ns = 250'000;
  r.role = Role::kMaster;
  r.mode = 4;
  r.position_m = 0.0123;
  r.velocity_m_per_s = -0.5;
  r.fixture_in_contact = true;
  r.fixture_penetration_m = 0.001;
  r.fixture_force_N = 1.5;
  r.clutched = true;
  r.fault_flags = 5;
  return r;
}

TEST(NodeStateCodec, RoundTripKeepsEveryField) {
  PeerStateFilter f(Role::kMaster);
  const NodeStateRecord in = master_state(7);
  const auto out = f.accept(encode(in));
  ASSERT_TRUE(out.has_value());
  EXPECT_TRUE(out->new_session);
  const NodeStateRecord& r = out->record;
  EXPECT_EQ(r.session_id, in.session_id);
  EXPECT_EQ(r.sequence, 7u);
  EXPECT_EQ(r.sample_time_ns, in.sample_time_ns);
  EXPECT_EQ(r.last_peer_sequence, 6u);
  EXPECT_EQ(r.peer_age_ns, 250'000);
  EXPECT_EQ(r.role, Role::kMaster);
  EXPECT_EQ(r.mode, 4);
  EXPECT_EQ(r.position_m, 0.0123);
  EXPECT_EQ(r.velocity_m_per_s, -0.5);
  EXPECT_TRUE(r.fixture_in_contact);
  EXPECT_EQ(r.fixture_penetration_m, 0.001);
  EXPECT_EQ(r.fixture_force_N, 1.5);
  EXPECT_TRUE(r.clutched);
  EXPECT_EQ(r.fault_flags, 5u);
}

TEST(NodeStateCodec, DuplicatesReplaysAndReordersAreDroppedAndCounted) {
  PeerStateFilter f(Role::kMaster);
  ASSERT_TRUE(f.accept(encode(master_state(10))).has_value());
  EXPECT_FALSE(f.accept(encode(master_state(10))).has_value());  // duplicate
  EXPECT_FALSE(f.accept(encode(master_state(9))).has_value());   // reordered / replayed
  const auto next = f.accept(encode(master_state(12)));          // a loss is fine
  ASSERT_TRUE(next.has_value());
  EXPECT_FALSE(next->new_session);
  EXPECT_FALSE(f.accept(encode(master_state(11))).has_value());  // late
  EXPECT_EQ(f.rejected(Rejection::kStale), 3u);
  EXPECT_EQ(f.accepted(), 2u);
}

TEST(NodeStateCodec, ARestartedPeerIsANewSession) {
  PeerStateFilter f(Role::kMaster);
  ASSERT_TRUE(f.accept(encode(master_state(500))).has_value());
  NodeStateRecord restarted = master_state(1);
  restarted.session_id = 42;
  const auto r = f.accept(encode(restarted));
  ASSERT_TRUE(r.has_value());
  EXPECT_TRUE(r->new_session);
}

TEST(NodeStateCodec, AReplayedEarlierSessionIsRejectedAndGapsCountAsLost) {
  PeerStateFilter f(Role::kMaster);
  const std::uint64_t first = master_state(1).session_id;
  ASSERT_TRUE(f.accept(encode(master_state(1))).has_value());
  ASSERT_TRUE(f.accept(encode(master_state(4))).has_value());  // 2 and 3 never came
  EXPECT_EQ(f.lost(), 2u);
  NodeStateRecord restarted = master_state(1);
  restarted.session_id = first + 1;
  ASSERT_TRUE(f.accept(encode(restarted)).has_value());
  // A capture of the first session, even far ahead in sequence, is a replay.
  EXPECT_FALSE(f.accept(encode(master_state(1000))).has_value());
  EXPECT_EQ(f.rejected(Rejection::kWrongSession), 1u);
  EXPECT_EQ(f.rejected(Rejection::kStale), 0u);
  // Losses are counted within a session only (a restart starts over).
  restarted.sequence = 3;
  ASSERT_TRUE(f.accept(encode(restarted)).has_value());
  EXPECT_EQ(f.lost(), 3u);
}

TEST(NodeStateCodec, GarbageNonFiniteAndWrongRoleNeverPass) {
  PeerStateFilter f(Role::kMaster);
  EXPECT_FALSE(f.accept("\xff\xff\xff\xff garbage").has_value());
  EXPECT_FALSE(f.accept(std::string(10000, 'x')).has_value());  // oversized
  const std::string good = encode(master_state(3));
  // Cut anywhere (protobuf would parse many of these with fields missing) or one bit flipped.
  for (std::size_t n = 1; n < good.size(); ++n) {
    EXPECT_FALSE(f.accept(std::string_view(good).substr(0, n)).has_value()) << n;
  }
  std::string flipped = good;
  flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x10);
  EXPECT_FALSE(f.accept(flipped).has_value());
  EXPECT_EQ(f.rejected(Rejection::kMalformed), 2u + (good.size() - 1) + 1u);
  for (const double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    NodeStateRecord r = master_state(4);
    r.position_m = bad;
    EXPECT_FALSE(f.accept(encode(r)).has_value());
    r = master_state(4);
    r.fixture_force_N = -bad;
    EXPECT_FALSE(f.accept(encode(r)).has_value());
  }
  EXPECT_EQ(f.rejected(Rejection::kNonFinite), 4u);
  NodeStateRecord slave = master_state(5);
  slave.role = Role::kSlave;
  EXPECT_FALSE(f.accept(encode(slave)).has_value());
  EXPECT_EQ(f.rejected(Rejection::kWrongRole), 1u);
  EXPECT_EQ(f.accepted(), 0u);
  // Nothing above moved the guard: the next good state is still accepted.
  EXPECT_TRUE(f.accept(encode(master_state(6))).has_value());
}

TEST(RoundTripEstimator, EchoMinusHoldTimeInWholeSamples) {
  // Sent #100 at 50 ms; the peer held it 0.4 ms before echoing; the echo arrives at 53.1 ms:
  // round trip 3.1 - 0.4 = 2.7 ms, i.e. 3 samples at 1 kHz (rounded up).
  RoundTripEstimator rt;
  rt.sent(100, milliseconds(50));
  const auto d = rt.echoed(100, microseconds(400), microseconds(53100));
  ASSERT_TRUE(d.has_value());
  EXPECT_EQ(*d, microseconds(2700));
  EXPECT_EQ(RoundTripEstimator::samples(*d, milliseconds(1)), 3);
  EXPECT_EQ(RoundTripEstimator::samples(milliseconds(2), milliseconds(1)), 2);
  // Forgotten (overwritten by a sequence kHistory later) or never sent: no estimate.
  rt.sent(100 + RoundTripEstimator::kHistory, milliseconds(60));
  EXPECT_FALSE(rt.echoed(100, microseconds(0), milliseconds(70)).has_value());
  EXPECT_FALSE(rt.echoed(7, microseconds(0), milliseconds(70)).has_value());
}

}  // namespace
}  // namespace teleop::transport

// docs/nodes.md "Before engage": the configuration fingerprint (field 16) and the parameter change
// (17) travel with every state, and the checksum covers them although they are numbered above
// it: flipping a byte of the fingerprint must not pass as another fingerprint.
namespace teleop::transport {
namespace {
namespace fingerprint_wire {

NodeStateRecord with_fingerprint(std::uint64_t seq) {
  NodeStateRecord r = master_state(seq);
  r.config_fingerprint = 0x1122'3344'5566'7788ULL;
  r.parameter_change_id = 3;
  return r;
}

// Where field 16 (fixed64: tag (16 << 3) | 1 = 129, varint 0x81 0x01) and its 8 little-endian
// bytes are in the encoding.
std::size_t fingerprint_offset(const std::string& bytes, std::uint64_t value) {
  std::string needle = {static_cast<char>(0x81), static_cast<char>(0x01)};
  for (int i = 0; i < 8; ++i) needle.push_back(static_cast<char>((value >> (8 * i)) & 0xFF));
  return bytes.find(needle);
}

// crc32 (zlib's: IEEE, reflected), computed here bit by bit.
std::uint32_t crc32_of(std::string_view b) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const char c : b) {
    crc ^= static_cast<unsigned char>(c);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xFFFFFFFFu;
}

}  // namespace fingerprint_wire

TEST(NodeStateCodec, FingerprintAndParameterChangeRoundTrip) {
  PeerStateFilter f(Role::kMaster);
  const auto out = f.accept(encode(fingerprint_wire::with_fingerprint(7)));
  ASSERT_TRUE(out.has_value());
  EXPECT_EQ(out->record.config_fingerprint, 0x1122'3344'5566'7788ULL);
  EXPECT_EQ(out->record.parameter_change_id, 3u);
}

TEST(NodeStateCodec, TheChecksumIsLastAndCoversTheFingerprint) {
  const std::string bytes = encode(fingerprint_wire::with_fingerprint(7));
  const std::size_t at = fingerprint_wire::fingerprint_offset(bytes, 0x1122'3344'5566'7788ULL);
  ASSERT_NE(at, std::string::npos) << "field 16 not found on the wire";
  // The last five bytes are field 15 (tag (15 << 3) | 5 = 0x7D) with the zlib crc32 of every
  // byte before it, little-endian.
  ASSERT_GT(bytes.size(), 5u);
  EXPECT_LT(at, bytes.size() - 5) << "the fingerprint must come before the checksum";
  EXPECT_EQ(static_cast<unsigned char>(bytes[bytes.size() - 5]), 0x7Du);
  const std::uint32_t crc =
      fingerprint_wire::crc32_of(std::string_view(bytes).substr(0, bytes.size() - 5));
  std::uint32_t wire = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    wire |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[bytes.size() - 4 + i]))
            << (8 * i);
  }
  EXPECT_EQ(wire, crc);
  // Any byte of the fingerprint flipped: rejected as malformed, never read as another one.
  for (std::size_t i = at + 2; i < at + 10; ++i) {
    PeerStateFilter f(Role::kMaster);
    std::string bad = bytes;
    bad[i] = static_cast<char>(bad[i] ^ 0x01);
    EXPECT_FALSE(f.accept(bad).has_value()) << "byte " << i;
    EXPECT_EQ(f.rejected(Rejection::kMalformed), 1u);
  }
}

TEST(NodeStateCodec, AnOlderPeersStateIsAcceptedWithoutAFingerprint) {
  // An older encoder: protobuf's own serialisation, without fields 16 and 17, the checksum
  // (field 15, the highest it knew) set over the body and serialised last.
  teleop::v1::NodeState m;
  m.set_session_id(77);
  m.set_sequence(5);
  m.set_role(teleop::v1::MASTER);
  m.set_mode(teleop::v1::ARMED);
  m.set_position_m(0.01);
  m.set_crc32(fingerprint_wire::crc32_of(m.SerializeAsString()));
  PeerStateFilter f(Role::kMaster);
  const auto out = f.accept(m.SerializeAsString());
  ASSERT_TRUE(out.has_value());
  EXPECT_EQ(out->record.config_fingerprint, 0u);  // the node then refuses to arm
  EXPECT_EQ(out->record.parameter_change_id, 0u);
}

}  // namespace
}  // namespace teleop::transport
