#include "common/telemetry/cycle_codec.hpp"

#include <algorithm>
#include <array>
#include <cstddef>

namespace teleop::telemetry {

v1::NodeMode to_proto(node::Mode m) noexcept {
  return static_cast<v1::NodeMode>(node::wire_mode(m));
}

node::Mode from_proto(v1::NodeMode m) noexcept { return node::mode_from_wire(static_cast<int>(m)); }

namespace {

// The fields one axis and n axes share, by name (node::CycleRecord, node::CycleRecordAxes).
template <typename Record>
void put_common(const Record& rec, v1::CycleRecord& out) {
  out.set_sequence(rec.sequence);
  out.set_sample_time_ns(rec.sample_time_ns);
  out.set_mode(to_proto(rec.mode));
  out.set_peer_sequence(rec.peer_sequence);
  out.set_peer_age_ns(rec.peer_age_ns);
  out.set_coupling_weight(rec.coupling_weight);
  out.set_flags(rec.flags);
  out.set_wakeup_latency_ns(rec.wakeup_latency_ns);
  out.set_round_trip_ns(rec.round_trip_ns);
  out.set_master_sequence(rec.master_sequence);
  out.set_alignment_error_m(rec.alignment_error_m);
  out.set_parameter_change_id(rec.parameter_change_id);
}

template <typename Record>
void take_common(const v1::CycleRecord& c, Record& r) noexcept {
  r.sequence = c.sequence();
  r.sample_time_ns = c.sample_time_ns();
  r.mode = from_proto(c.mode());
  r.peer_sequence = c.peer_sequence();
  r.peer_age_ns = c.peer_age_ns();
  r.coupling_weight = c.coupling_weight();
  r.flags = c.flags();
  r.wakeup_latency_ns = c.wakeup_latency_ns();
  r.round_trip_ns = c.round_trip_ns();
  r.master_sequence = c.master_sequence();
  r.alignment_error_m = c.alignment_error_m();
  r.parameter_change_id = c.parameter_change_id();
}

}  // namespace

void to_proto(const node::CycleRecord& rec, v1::CycleRecord& out) {
  put_common(rec, out);
  out.set_position_m(rec.position_m);
  out.set_velocity_m_per_s(rec.velocity_m_per_s);
  out.set_force_n(rec.force_N);
  out.set_command_n(rec.command_N);
  out.set_peer_position_m(rec.peer_position_m);
}

node::CycleRecord from_proto(const v1::CycleRecord& c) noexcept {
  node::CycleRecord r;
  take_common(c, r);
  r.position_m = c.position_m();
  r.velocity_m_per_s = c.velocity_m_per_s();
  r.force_N = c.force_n();
  r.command_N = c.command_n();
  r.peer_position_m = c.peer_position_m();
  return r;
}

namespace {

void put(const std::array<double, kMaxAxes>& values, int axes,
         google::protobuf::RepeatedField<double>& out) {
  out.Clear();
  for (int i = 0; i < axes; ++i) out.Add(values[static_cast<std::size_t>(i)]);
}

bool take(const google::protobuf::RepeatedField<double>& in, int axes,
          std::array<double, kMaxAxes>& out) noexcept {
  if (in.size() != axes) return false;
  for (int i = 0; i < axes; ++i) out[static_cast<std::size_t>(i)] = in.Get(i);
  return true;
}

}  // namespace

void to_proto(const node::CycleRecordAxes& rec, v1::CycleRecord& out) {
  put_common(rec, out);
  if (rec.axes <= 1) {
    out.set_position_m(rec.position_m[0]);
    out.set_velocity_m_per_s(rec.velocity_m_per_s[0]);
    out.set_force_n(rec.force_N[0]);
    out.set_command_n(rec.command_N[0]);
    out.set_peer_position_m(rec.peer_position_m[0]);
    return;
  }
  out.set_axes(static_cast<std::uint32_t>(rec.axes));
  put(rec.position_m, rec.axes, *out.mutable_positions_m());
  put(rec.velocity_m_per_s, rec.axes, *out.mutable_velocities_m_per_s());
  put(rec.force_N, rec.axes, *out.mutable_forces_n());
  put(rec.command_N, rec.axes, *out.mutable_commands_n());
  put(rec.peer_position_m, rec.axes, *out.mutable_peer_positions_m());
  out.set_fixture_penetration_m(rec.fixture_penetration_m);
}

int axes_of(const v1::CycleRecord& c) noexcept {
  return c.axes() <= 1 ? 1 : static_cast<int>(std::min<std::uint32_t>(c.axes(), 1U << 20));
}

std::optional<node::CycleRecordAxes> axes_from_proto(const v1::CycleRecord& c) noexcept {
  node::CycleRecordAxes r;
  take_common(c, r);
  const int axes = axes_of(c);
  if (axes > kMaxAxes) return std::nullopt;
  r.axes = axes;
  if (axes == 1) {
    // A one-axis record; an axes = 1 record with repeated fields is malformed.
    if (!c.positions_m().empty() || !c.velocities_m_per_s().empty() || !c.forces_n().empty() ||
        !c.commands_n().empty() || !c.peer_positions_m().empty()) {
      return std::nullopt;
    }
    r.position_m[0] = c.position_m();
    r.velocity_m_per_s[0] = c.velocity_m_per_s();
    r.force_N[0] = c.force_n();
    r.command_N[0] = c.command_n();
    r.peer_position_m[0] = c.peer_position_m();
    return r;
  }
  if (!take(c.positions_m(), axes, r.position_m) ||
      !take(c.velocities_m_per_s(), axes, r.velocity_m_per_s) ||
      !take(c.forces_n(), axes, r.force_N) || !take(c.commands_n(), axes, r.command_N) ||
      !take(c.peer_positions_m(), axes, r.peer_position_m)) {
    return std::nullopt;
  }
  r.fixture_penetration_m = c.fixture_penetration_m();
  return r;
}

}  // namespace teleop::telemetry
