// Issue 18 on the wire: NodeState with n task-space axes (proto/teleop/v1/node_state.proto fields
// 18-21, docs/nodes.md "The link"). A one-axis node sends today's bytes; an n-axis node sends
// axis 0 in the scalar fields and all n in the repeated ones; the receiver's guard rejects a peer
// with another axis count, and every hostile shape of the new fields, before the law sees it.
//
// Independent references: the one-axis bytes of the codec before these fields existed (captured
// from main at 8f4225a and checked by hand below), protobuf's own parser and serialiser of the
// message, and a bitwise CRC-32 computed here.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>

#include "common/transport/node_state_codec.hpp"
#include "teleop/v1/node_state.pb.h"

namespace teleop::transport {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// crc32 (zlib's: IEEE, reflected), bit by bit.
std::uint32_t crc32_of(std::string_view b) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const char c : b) {
    crc ^= static_cast<unsigned char>(c);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return crc ^ 0xFFFFFFFFu;
}

// What a hostile or foreign encoder sends: protobuf's serialisation of `m` with the CRC field
// (tag 0x7D and the CRC-32 of every byte before it, little-endian) appended by hand.
std::string with_crc(const teleop::v1::NodeState& m) {
  std::string bytes = m.SerializeAsString();
  const std::uint32_t crc = crc32_of(bytes);
  bytes.push_back(static_cast<char>(0x7D));
  for (int i = 0; i < 4; ++i) bytes.push_back(static_cast<char>((crc >> (8 * i)) & 0xFFu));
  return bytes;
}

// Every scalar field non-zero, so each one is on the wire.
NodeStateRecord golden_record() {
  NodeStateRecord r;
  r.session_id = 0x1234'5678'9abc'def0ULL;
  r.sequence = 7;
  r.sample_time_ns = 7'000'000;
  r.last_peer_sequence = 6;
  r.peer_age_ns = 250'000;
  r.role = Role::kMaster;
  r.mode = 4;
  r.position_m = 0.0123;
  r.velocity_m_per_s = -0.5;
  r.force_N = 2.25;
  r.fixture_in_contact = true;
  r.fixture_penetration_m = 0.001;
  r.fixture_force_N = 1.5;
  r.clutched = true;
  r.fault_flags = 5;
  r.config_fingerprint = 0x1122'3344'5566'7788ULL;
  r.parameter_change_id = 3;
  return r;
}

// golden_record() as the codec encoded it before issue 18 (main at 8f4225a), 97 bytes. By hand:
// 09 + 8 bytes: field 1 fixed64 session, little-endian; 10 07: sequence 7; 18 c0 9f ab 03:
// sample time 7'000'000 (varint); 20 06; 28 90 a1 0f: 250'000; 30 01: MASTER; 38 04: ENGAGED;
// 41/49/51 + 8 bytes: the doubles 0.0123, -0.5 (00..e0 bf), 2.25 (00..02 40); 5a 14: the
// fixture, 20 bytes (08 01, 11 + 0.001, 19 + 1.5 (00..f8 3f)); 60 01: clutched; 68 05: fault
// flags; 81 01 + 8 bytes: field 16; 88 01 03: field 17 = 3; 7d + 4 bytes: the CRC.
const std::string_view kGoldenOneAxis(
    "\x09\xf0\xde\xbc\x9a\x78\x56\x34\x12\x10\x07\x18\xc0\x9f\xab\x03"
    "\x20\x06\x28\x90\xa1\x0f\x30\x01\x38\x04\x41\x8d\x28\xed\x0d\xbe"
    "\x30\x89\x3f\x49\x00\x00\x00\x00\x00\x00\xe0\xbf\x51\x00\x00\x00"
    "\x00\x00\x00\x02\x40\x5a\x14\x08\x01\x11\xfc\xa9\xf1\xd2\x4d\x62"
    "\x50\x3f\x19\x00\x00\x00\x00\x00\x00\xf8\x3f\x60\x01\x68\x05\x81"
    "\x01\x88\x77\x66\x55\x44\x33\x22\x11\x88\x01\x03\x7d\x1b\x44\x62"
    "\x24",
    97);

// An n-axis state with a distinct value on every axis: x_j = 0.01 (j + 1), v_j = -0.1 (j + 1),
// F_j = 0.5 + j.
NodeStateRecord axes_record(int n, std::uint64_t seq, Role role = Role::kSlave) {
  NodeStateRecord r = golden_record();
  r.sequence = seq;
  r.role = role;
  r.axes = n;
  for (int j = 0; j < n; ++j) {
    const double k = static_cast<double>(j + 1);
    r.set_axis(static_cast<std::size_t>(j), 0.01 * k, -0.1 * k, 0.5 + j);
  }
  return r;
}

// A three-axis slave state as protobuf's own message, valid in every way (the hostile tests
// break one thing at a time).
teleop::v1::NodeState three_axis_message(std::uint64_t seq) {
  teleop::v1::NodeState m;
  m.set_session_id(99);
  m.set_sequence(seq);
  m.set_role(teleop::v1::SLAVE);
  m.set_mode(teleop::v1::ENGAGED);
  m.set_position_m(0.01);
  m.set_velocity_m_per_s(-0.1);
  m.set_force_n(0.5);
  m.set_axes(3);
  for (int j = 0; j < 3; ++j) {
    m.add_positions_m(0.01 * (j + 1));
    m.add_velocities_m_per_s(-0.1 * (j + 1));
    m.add_forces_n(0.5 + j);
  }
  return m;
}

TEST(NodeStateAxes, OneAxisBytesAreTodays) {
  EXPECT_EQ(encode(golden_record()), kGoldenOneAxis);
  // The same through protobuf's own serialiser of the one-axis message (no field 18-21 set).
  teleop::v1::NodeState m;
  ASSERT_TRUE(m.ParseFromArray(kGoldenOneAxis.data(), static_cast<int>(kGoldenOneAxis.size())));
  EXPECT_FALSE(m.has_axes());
  EXPECT_EQ(m.positions_m_size(), 0);
  m.clear_crc32();
  EXPECT_EQ(with_crc(m), kGoldenOneAxis);
  // At n = 1 the arrays are not read: whatever is in them, the bytes are today's.
  NodeStateRecord junk = golden_record();
  junk.positions_m = {9, 8, 7, 6, 5, 4};
  junk.forces_N[5] = kNaN;
  EXPECT_EQ(encode(junk), kGoldenOneAxis);
}

TEST(NodeStateAxes, OneAxisRoundTripFillsAxisZero) {
  PeerStateFilter f(Role::kMaster);  // the default: one axis, as every caller before issue 18
  const auto out = f.accept(kGoldenOneAxis);
  ASSERT_TRUE(out.has_value());
  const NodeStateRecord& r = out->record;
  EXPECT_EQ(r.axes, 1);
  EXPECT_EQ(r.position_m, 0.0123);
  EXPECT_EQ(r.velocity_m_per_s, -0.5);
  EXPECT_EQ(r.force_N, 2.25);
  EXPECT_EQ(r.positions_m[0], 0.0123);
  EXPECT_EQ(r.velocities_m_per_s[0], -0.5);
  EXPECT_EQ(r.forces_N[0], 2.25);
  for (std::size_t j = 1; j < r.positions_m.size(); ++j) {
    EXPECT_EQ(r.positions_m[j], 0.0);
    EXPECT_EQ(r.velocities_m_per_s[j], 0.0);
    EXPECT_EQ(r.forces_N[j], 0.0);
  }
  EXPECT_EQ(encode(r), kGoldenOneAxis);  // and back to the same bytes
}

TEST(NodeStateAxes, RoundTripAtThreeAndSixAxes) {
  for (const int n : {1, 3, 6}) {
    PeerStateFilter f(Role::kSlave, n);
    const NodeStateRecord in = axes_record(n, 11);
    const auto out = f.accept(encode(in));
    ASSERT_TRUE(out.has_value()) << n;
    const NodeStateRecord& r = out->record;
    EXPECT_EQ(r.axes, n);
    for (int j = 0; j < kMaxAxes; ++j) {
      const auto u = static_cast<std::size_t>(j);
      const double k = static_cast<double>(j + 1);
      EXPECT_EQ(r.positions_m[u], j < n ? 0.01 * k : 0.0) << n << " " << j;
      EXPECT_EQ(r.velocities_m_per_s[u], j < n ? -0.1 * k : 0.0) << n << " " << j;
      EXPECT_EQ(r.forces_N[u], j < n ? 0.5 + j : 0.0) << n << " " << j;
    }
    EXPECT_EQ(r.position_m, 0.01);
    EXPECT_EQ(r.velocity_m_per_s, -0.1);
    EXPECT_EQ(r.force_N, 0.5);
    EXPECT_EQ(r.fixture_force_N, 1.5);
    EXPECT_EQ(r.config_fingerprint, 0x1122'3344'5566'7788ULL);
    EXPECT_EQ(f.accepted(), 1u);
  }
}

TEST(NodeStateAxes, ThreeAxisWireLayoutAsProtobufReadsIt) {
  NodeStateRecord in = axes_record(3, 11);
  in.position_m = 42.0;  // at n > 1 the scalar members are not read: axis 0 goes out
  const std::string bytes = encode(in);
  teleop::v1::NodeState m;
  ASSERT_TRUE(m.ParseFromArray(bytes.data(), static_cast<int>(bytes.size())));
  ASSERT_TRUE(m.has_axes());
  EXPECT_EQ(m.axes(), 3u);
  ASSERT_EQ(m.positions_m_size(), 3);
  ASSERT_EQ(m.velocities_m_per_s_size(), 3);
  ASSERT_EQ(m.forces_n_size(), 3);
  EXPECT_EQ(m.positions_m(2), 0.03);
  EXPECT_EQ(m.velocities_m_per_s(1), -0.2);
  EXPECT_EQ(m.forces_n(2), 2.5);
  // What a reader that knows only the scalar fields sees: axis 0.
  EXPECT_EQ(m.position_m(), 0.01);
  EXPECT_EQ(m.velocity_m_per_s(), -0.1);
  EXPECT_EQ(m.force_n(), 0.5);
  // Packed: field 19, wire type 2 (tag (19 << 3) | 2 = 154: varint 9a 01), 24 bytes.
  EXPECT_NE(bytes.find(std::string("\x9a\x01\x18", 3)), std::string::npos);
  // The CRC is still the last field and covers every byte before it, the new fields included.
  ASSERT_GT(bytes.size(), 5u);
  EXPECT_EQ(static_cast<unsigned char>(bytes[bytes.size() - 5]), 0x7Du);
  EXPECT_EQ(m.crc32(), crc32_of(std::string_view(bytes).substr(0, bytes.size() - 5)));
  // Any byte of the state cut off or flipped (the new fields included): malformed.
  PeerStateFilter f(Role::kSlave, 3);
  for (std::size_t cut = 1; cut < bytes.size(); ++cut) {
    EXPECT_FALSE(f.accept(std::string_view(bytes).substr(0, cut)).has_value()) << cut;
  }
  for (std::size_t i = 0; i + 5 < bytes.size(); ++i) {
    std::string bad = bytes;
    bad[i] = static_cast<char>(bad[i] ^ 0x04);
    EXPECT_FALSE(f.accept(bad).has_value()) << i;
  }
  EXPECT_EQ(f.rejected(Rejection::kMalformed), 2 * (bytes.size() - 1) - 4);
  EXPECT_TRUE(f.accept(bytes).has_value());
}

TEST(NodeStateAxes, APeerWithAnotherAxisCountNeverReachesTheLaw) {
  PeerStateFilter three(Role::kSlave, 3);
  // A one-axis peer (today's node) talking to a three-axis node, and the other way round.
  EXPECT_FALSE(three.accept(encode(axes_record(1, 100))).has_value());
  EXPECT_FALSE(three.accept(encode(axes_record(6, 101))).has_value());
  EXPECT_EQ(three.rejected(Rejection::kWrongAxes), 2u);
  EXPECT_STREQ(to_string(Rejection::kWrongAxes), "wrong_axes");
  PeerStateFilter one(Role::kSlave);
  EXPECT_FALSE(one.accept(encode(axes_record(3, 5))).has_value());
  EXPECT_EQ(one.rejected(Rejection::kWrongAxes), 1u);
  // Neither moved the guard: the first good state, with a sequence below the rejected ones, is
  // the first of its session.
  const auto ok = three.accept(encode(axes_record(3, 50)));
  ASSERT_TRUE(ok.has_value());
  EXPECT_TRUE(ok->new_session);
  EXPECT_EQ(three.accepted(), 1u);
  for (const Rejection r : {Rejection::kMalformed, Rejection::kNonFinite, Rejection::kWrongRole,
                            Rejection::kStale, Rejection::kWrongSession}) {
    EXPECT_EQ(three.rejected(r), 0u) << to_string(r);
  }
  // A well-formed state from the wrong role is counted as the wrong role, whatever its axes.
  EXPECT_FALSE(three.accept(encode(axes_record(1, 60, Role::kMaster))).has_value());
  EXPECT_EQ(three.rejected(Rejection::kWrongRole), 1u);
}

TEST(NodeStateAxes, HostileAxisFieldsAreMalformed) {
  PeerStateFilter f(Role::kSlave, 3);
  std::uint64_t seq = 1;
  auto offer = [&](teleop::v1::NodeState m) {
    m.set_sequence(seq++);
    return f.accept(with_crc(m)).has_value();
  };
  ASSERT_TRUE(offer(three_axis_message(0)));  // the unbroken message is accepted
  teleop::v1::NodeState m = three_axis_message(0);
  m.mutable_velocities_m_per_s()->RemoveLast();  // lengths 3, 2, 3
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.add_forces_n(1.0);  // lengths 3, 3, 4
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.set_axes(7);  // more than kMaxAxes, every field 7 long
  for (int j = 3; j < 7; ++j) {
    m.add_positions_m(0.0);
    m.add_velocities_m_per_s(0.0);
    m.add_forces_n(0.0);
  }
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.set_axes(0);  // present and zero (optional: on the wire as 90 01 00)
  m.clear_positions_m();
  m.clear_velocities_m_per_s();
  m.clear_forces_n();
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.set_axes(0xFFFFFFFFu);
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.clear_axes();  // repeated fields without a count
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.set_position_m(0.02);  // the scalar is not axis 0
  EXPECT_FALSE(offer(m));
  m = three_axis_message(0);
  m.set_force_n(-0.5);
  EXPECT_FALSE(offer(m));
  // A huge repeated field: 400 positions (3.2 kB, under the size limit), and 1000 (over it).
  for (const int huge : {400, 1000}) {
    m = three_axis_message(0);
    for (int j = 3; j < huge; ++j) m.add_positions_m(0.001 * j);
    EXPECT_FALSE(offer(m)) << huge;
  }
  EXPECT_EQ(f.rejected(Rejection::kMalformed), 10u);
  EXPECT_EQ(f.accepted(), 1u);
  // Nothing above moved the guard.
  EXPECT_TRUE(offer(three_axis_message(0)));
}

TEST(NodeStateAxes, NonFiniteInAnyAxisIsRejected) {
  PeerStateFilter f(Role::kSlave, 3);
  std::uint64_t seq = 1;
  for (const double bad : {kNaN, kInf, -kInf}) {
    NodeStateRecord r = axes_record(3, seq++);
    r.positions_m[2] = bad;  // axis 2 only: the scalars (axis 0) are finite
    EXPECT_FALSE(f.accept(encode(r)).has_value());
    r = axes_record(3, seq++);
    r.velocities_m_per_s[1] = bad;
    EXPECT_FALSE(f.accept(encode(r)).has_value());
    r = axes_record(3, seq++);
    r.set_axis(0, 0.01, -0.1, bad);  // axis 0: scalar and entry 0 alike
    EXPECT_FALSE(f.accept(encode(r)).has_value());
  }
  EXPECT_EQ(f.rejected(Rejection::kNonFinite), 9u);
  EXPECT_EQ(f.rejected(Rejection::kMalformed), 0u);
  EXPECT_EQ(f.accepted(), 0u);
}

TEST(NodeStateAxes, UnpackedRepeatedFieldsAreReadAlike) {
  // protobuf readers accept a repeated double unpacked (one tag per value); so does ours. Built
  // by hand: the one-axis body of three_axis_message, then axes and each value with its own tag.
  teleop::v1::NodeState m = three_axis_message(5);
  m.clear_axes();
  m.clear_positions_m();
  m.clear_velocities_m_per_s();
  m.clear_forces_n();
  std::string body = m.SerializeAsString();
  body += std::string("\x90\x01\x03", 3);  // field 18 varint: 3
  auto put_double = [&body](char tag, double v) {
    body += std::string{static_cast<char>(tag), '\x01'};  // fields 19-21, wire type 1 (64-bit)
    std::uint64_t bits = 0;
    std::memcpy(&bits, &v, sizeof bits);
    for (int i = 0; i < 8; ++i) body.push_back(static_cast<char>((bits >> (8 * i)) & 0xFFu));
  };
  for (int j = 0; j < 3; ++j) {
    put_double(static_cast<char>(0x99), 0.01 * (j + 1));  // (19 << 3) | 1 = 153
    put_double(static_cast<char>(0xA1), -0.1 * (j + 1));  // (20 << 3) | 1 = 161
    put_double(static_cast<char>(0xA9), 0.5 + j);         // (21 << 3) | 1 = 169
  }
  const std::uint32_t crc = crc32_of(body);
  body.push_back(static_cast<char>(0x7D));
  for (int i = 0; i < 4; ++i) body.push_back(static_cast<char>((crc >> (8 * i)) & 0xFFu));
  PeerStateFilter f(Role::kSlave, 3);
  const auto out = f.accept(body);
  ASSERT_TRUE(out.has_value());
  EXPECT_EQ(out->record.positions_m[2], 0.03);
  EXPECT_EQ(out->record.velocities_m_per_s[1], -0.2);
  EXPECT_EQ(out->record.forces_N[2], 2.5);
}

TEST(NodeStateAxes, CountsOutsideOneToSixAreRefusedByName) {
  for (const int bad : {0, -1, 7}) {
    try {
      PeerStateFilter f(Role::kSlave, bad);
      ADD_FAILURE() << "expected_axes " << bad << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("expected_axes"), std::string::npos) << e.what();
    }
    NodeStateRecord r = golden_record();
    r.axes = bad;
    try {
      (void)encode(r);
      ADD_FAILURE() << "axes " << bad << " encoded";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("axes"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace teleop::transport
