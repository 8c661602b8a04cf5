// One control cycle between its two forms: node::CycleRecord (node_core.hpp), which the RT
// thread fills and the session library hands out, and teleop.v1.CycleRecord (telemetry.proto),
// which telemetry and session files carry. Written once each way, here: the node's telemetry
// thread encodes with it, the session reader decodes with it, the supervisor's per-cycle
// channels are its output. Not for the RT thread (protobuf).
#pragma once

#include <cstdint>

#include "common/node/node_core.hpp"
#include "common/node/node_state_machine.hpp"
#include "teleop/v1/node_state.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::telemetry {

// The mode's teleop.v1.NodeMode (node::wire_mode), and back (unspecified or unknown: disarmed).
[[nodiscard]] v1::NodeMode to_proto(node::Mode m) noexcept;
[[nodiscard]] node::Mode from_proto(v1::NodeMode m) noexcept;

// Every field of `rec` into `out` (its other fields, e.g. session_id, left as they are). The
// record's `reason` is not carried per cycle.
void to_proto(const node::CycleRecord& rec, v1::CycleRecord& out);
// Every field back; reason "" (static).
[[nodiscard]] node::CycleRecord from_proto(const v1::CycleRecord& c) noexcept;

}  // namespace teleop::telemetry
