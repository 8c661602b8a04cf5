// One control cycle between its two forms: node::CycleRecord (node_core.hpp), which the RT
// thread fills and the session library hands out, and teleop.v1.CycleRecord (telemetry.proto),
// which telemetry and session files carry. Written once each way, here: the node's telemetry
// thread encodes with it, the session reader decodes with it, the supervisor's per-cycle
// channels are its output. Not for the RT thread (protobuf).
#pragma once

#include <cstdint>
#include <optional>

#include "common/node/node_core.hpp"
#include "common/node/node_core_axes.hpp"
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

// n task-space axes (issue 18; telemetry.proto CycleRecord.axes). A record of n > 1 axes
// writes `axes` and the per-axis repeated fields and leaves the one-axis scalars 0; a record of
// one axis is written exactly as the one-axis record above (axes unset, the scalars hold it),
// so one-axis sessions keep their bytes. flags carries SampleFlags | LawFlagBits; the
// saturated and rate-limited axis masks, reason and clock are not carried per cycle.
void to_proto(const node::CycleRecordAxes& rec, v1::CycleRecord& out);
// Either form back as n axes: a one-axis record (axes 0 or 1) as axis 0 of a 1-axis record.
// Returns nullopt, naming nothing, for a record whose axes exceed kMaxAxes or whose repeated
// fields do not hold `axes` entries each (a reader refuses such a record).
[[nodiscard]] std::optional<node::CycleRecordAxes> axes_from_proto(
    const v1::CycleRecord& c) noexcept;
// The record's number of task-space axes: 1 for a one-axis record, else its `axes`.
[[nodiscard]] int axes_of(const v1::CycleRecord& c) noexcept;

}  // namespace teleop::telemetry
