// The one conversion of a control cycle each way (common/telemetry/cycle_codec.hpp): a record
// with every field distinct survives node -> proto -> bytes -> proto -> node unchanged, and
// every field of teleop.v1.CycleRecord but the per-channel session_id is written, so a field
// added to the proto and forgotten in the codec fails here.
#include <gtest/gtest.h>

#include <cstdint>
#include <optional>
#include <string>

#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::telemetry {
namespace {

// telemetry.proto: fields 19 (axes) and on carry n > 1 axes only.
constexpr int kFirstAxesField = 19;

node::CycleRecord distinct_record() {
  node::CycleRecord r;
  r.sequence = 123'456'789'012ULL;
  r.sample_time_ns = 987'654'321'000LL;
  r.mode = node::Mode::kClutched;
  r.reason = "not carried";
  r.position_m = 0.0123;
  r.velocity_m_per_s = -0.45;
  r.force_N = 3.25;
  r.command_N = -7.5;
  r.peer_sequence = 123'456'789'000ULL;
  r.peer_position_m = -0.0042;
  r.peer_age_ns = 1'750'000;
  r.coupling_weight = 0.625;
  r.flags = 0x1F01U;
  r.wakeup_latency_ns = 23'456;
  r.round_trip_ns = 2'100'000;
  r.master_sequence = 123'456'789'015ULL;
  r.parameter_change_id = 4;
  r.alignment_error_m = 1.5e-4;
  return r;
}

TEST(CycleCodec, RoundTripKeepsEveryField) {
  const node::CycleRecord in = distinct_record();
  v1::CycleRecord wire;
  to_proto(in, wire);
  v1::CycleRecord parsed;
  ASSERT_TRUE(parsed.ParseFromString(wire.SerializeAsString()));
  const node::CycleRecord out = from_proto(parsed);
  EXPECT_EQ(out.sequence, in.sequence);
  EXPECT_EQ(out.sample_time_ns, in.sample_time_ns);
  EXPECT_EQ(out.mode, in.mode);
  EXPECT_STREQ(out.reason, "");  // not recorded per cycle
  EXPECT_EQ(out.position_m, in.position_m);
  EXPECT_EQ(out.velocity_m_per_s, in.velocity_m_per_s);
  EXPECT_EQ(out.force_N, in.force_N);
  EXPECT_EQ(out.command_N, in.command_N);
  EXPECT_EQ(out.peer_sequence, in.peer_sequence);
  EXPECT_EQ(out.peer_position_m, in.peer_position_m);
  EXPECT_EQ(out.peer_age_ns, in.peer_age_ns);
  EXPECT_EQ(out.coupling_weight, in.coupling_weight);
  EXPECT_EQ(out.flags, in.flags);
  EXPECT_EQ(out.wakeup_latency_ns, in.wakeup_latency_ns);
  EXPECT_EQ(out.round_trip_ns, in.round_trip_ns);
  EXPECT_EQ(out.master_sequence, in.master_sequence);
  EXPECT_EQ(out.parameter_change_id, in.parameter_change_id);
  EXPECT_EQ(out.alignment_error_m, in.alignment_error_m);
}

TEST(CycleCodec, WritesEveryProtoField) {
  v1::CycleRecord wire;
  to_proto(distinct_record(), wire);
  const google::protobuf::Descriptor* d = v1::CycleRecord::descriptor();
  const google::protobuf::Reflection* r = wire.GetReflection();
  for (int i = 0; i < d->field_count(); ++i) {
    const google::protobuf::FieldDescriptor* f = d->field(i);
    if (f->name() == "session_id") {
      EXPECT_FALSE(r->HasField(wire, f)) << "session_id belongs to the per-cycle channel";
      continue;
    }
    if (f->number() >= kFirstAxesField) {  // n > 1 only: a one-axis record keeps its bytes
      EXPECT_TRUE(f->is_repeated() ? r->FieldSize(wire, f) == 0 : !r->HasField(wire, f))
          << f->name() << " is written for one axis";
      continue;
    }
    EXPECT_TRUE(r->HasField(wire, f))
        << "teleop.v1.CycleRecord." << f->name() << " is not written by cycle_codec's to_proto";
  }
}

// Three axes, every entry distinct (axis i, quantity q: a different number each).
node::CycleRecordAxes distinct_axes_record() {
  node::CycleRecordAxes r;
  r.sequence = 77;
  r.sample_time_ns = 5'000'000;
  r.mode = node::Mode::kEngaged;
  r.axes = 3;
  for (std::size_t i = 0; i < 3; ++i) {
    const double a = static_cast<double>(i + 1);
    r.position_m[i] = 0.01 * a;
    r.velocity_m_per_s[i] = -0.1 * a;
    r.force_N[i] = 1.5 * a;
    r.command_N[i] = -2.5 * a;
    r.peer_position_m[i] = 0.003 * a;
  }
  r.peer_sequence = 70;
  r.peer_age_ns = 1'250'000;
  r.coupling_weight = 0.5;
  r.flags = 0x101U;
  r.wakeup_latency_ns = 12'345;
  r.round_trip_ns = 2'000'000;
  r.master_sequence = 76;
  r.alignment_error_m = 2e-4;
  r.fixture_penetration_m = 3.5e-4;
  return r;
}

TEST(CycleCodec, ThreeAxesWriteEveryAxisFieldAndLeaveTheOneAxisScalarsZero) {
  v1::CycleRecord wire;
  to_proto(distinct_axes_record(), wire);
  EXPECT_EQ(wire.axes(), 3U);
  ASSERT_EQ(wire.positions_m_size(), 3);
  EXPECT_EQ(wire.positions_m(2), 0.03);
  EXPECT_EQ(wire.commands_n(1), -5.0);
  EXPECT_EQ(wire.fixture_penetration_m(), 3.5e-4);
  // A one-axis reader must see no axis in the scalars (0 is unset in proto3).
  EXPECT_EQ(wire.position_m(), 0.0);
  EXPECT_EQ(wire.velocity_m_per_s(), 0.0);
  EXPECT_EQ(wire.force_n(), 0.0);
  EXPECT_EQ(wire.command_n(), 0.0);
  EXPECT_EQ(wire.peer_position_m(), 0.0);
  EXPECT_EQ(axes_of(wire), 3);
  v1::CycleRecord parsed;
  ASSERT_TRUE(parsed.ParseFromString(wire.SerializeAsString()));
  const std::optional<node::CycleRecordAxes> back = axes_from_proto(parsed);
  ASSERT_TRUE(back.has_value());
  const node::CycleRecordAxes in = distinct_axes_record();
  EXPECT_EQ(back->axes, 3);
  EXPECT_EQ(back->position_m, in.position_m);
  EXPECT_EQ(back->velocity_m_per_s, in.velocity_m_per_s);
  EXPECT_EQ(back->force_N, in.force_N);
  EXPECT_EQ(back->command_N, in.command_N);
  EXPECT_EQ(back->peer_position_m, in.peer_position_m);
  EXPECT_EQ(back->sequence, 77U);
  EXPECT_EQ(back->mode, node::Mode::kEngaged);
  EXPECT_EQ(back->fixture_penetration_m, 3.5e-4);
  EXPECT_EQ(back->master_sequence, 76U);
}

TEST(CycleCodec, OneAxisRecordsKeepTheirBytesAndReadAsAxisZero) {
  // A CycleRecordAxes of one axis encodes exactly as the one-axis record with the same values
  // (the parameter change id, which CycleRecordAxes does not carry, left 0).
  node::CycleRecord one = distinct_record();
  one.parameter_change_id = 0;
  node::CycleRecordAxes axes;
  axes.sequence = one.sequence;
  axes.sample_time_ns = one.sample_time_ns;
  axes.mode = one.mode;
  axes.axes = 1;
  axes.position_m[0] = one.position_m;
  axes.velocity_m_per_s[0] = one.velocity_m_per_s;
  axes.force_N[0] = one.force_N;
  axes.command_N[0] = one.command_N;
  axes.peer_position_m[0] = one.peer_position_m;
  axes.peer_sequence = one.peer_sequence;
  axes.peer_age_ns = one.peer_age_ns;
  axes.coupling_weight = one.coupling_weight;
  axes.flags = one.flags;
  axes.wakeup_latency_ns = one.wakeup_latency_ns;
  axes.round_trip_ns = one.round_trip_ns;
  axes.master_sequence = one.master_sequence;
  axes.alignment_error_m = one.alignment_error_m;
  v1::CycleRecord a;
  v1::CycleRecord b;
  to_proto(one, a);
  to_proto(axes, b);
  EXPECT_EQ(a.SerializeAsString(), b.SerializeAsString());
  const std::optional<node::CycleRecordAxes> back = axes_from_proto(a);
  ASSERT_TRUE(back.has_value());
  EXPECT_EQ(back->axes, 1);
  EXPECT_EQ(back->position_m[0], one.position_m);
  EXPECT_EQ(back->command_N[0], one.command_N);
  EXPECT_EQ(back->peer_position_m[0], one.peer_position_m);
}

TEST(CycleCodec, AnAxesRecordWithTheWrongNumberOfEntriesOrTooManyAxesIsRefused) {
  v1::CycleRecord wire;
  to_proto(distinct_axes_record(), wire);
  v1::CycleRecord short_force = wire;
  short_force.mutable_forces_n()->RemoveLast();
  EXPECT_FALSE(axes_from_proto(short_force).has_value());
  v1::CycleRecord seven = wire;
  seven.set_axes(7);
  EXPECT_FALSE(axes_from_proto(seven).has_value());
  v1::CycleRecord huge = wire;
  huge.set_axes(0xFFFFFFFFU);
  EXPECT_FALSE(axes_from_proto(huge).has_value());
  v1::CycleRecord one_with_lists = wire;
  one_with_lists.set_axes(1);
  EXPECT_FALSE(axes_from_proto(one_with_lists).has_value());
}

TEST(CycleCodec, ModesMatchTheWireNumbers) {
  // telemetry.proto / node_state.proto: DISARMED = 1 ... FAULT = 7, 0 unspecified.
  EXPECT_EQ(to_proto(node::Mode::kDisarmed), v1::DISARMED);
  EXPECT_EQ(to_proto(node::Mode::kEngaged), v1::ENGAGED);
  EXPECT_EQ(to_proto(node::Mode::kFault), v1::FAULT);
  EXPECT_EQ(from_proto(v1::SAFE), node::Mode::kSafe);
  EXPECT_EQ(from_proto(v1::NODE_MODE_UNSPECIFIED), node::Mode::kDisarmed);
  EXPECT_EQ(from_proto(static_cast<v1::NodeMode>(42)), node::Mode::kDisarmed);
}

}  // namespace
}  // namespace teleop::telemetry
