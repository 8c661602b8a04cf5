// The one conversion of a control cycle each way (common/telemetry/cycle_codec.hpp): a record
// with every field distinct survives node -> proto -> bytes -> proto -> node unchanged, and
// every field of teleop.v1.CycleRecord but the per-channel session_id is written, so a field
// added to the proto and forgotten in the codec fails here.
#include <gtest/gtest.h>

#include <cstdint>
#include <string>

#include "common/node/node_core.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::telemetry {
namespace {

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
    EXPECT_TRUE(r->HasField(wire, f))
        << "teleop.v1.CycleRecord." << f->name() << " is not written by cycle_codec's to_proto";
  }
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
