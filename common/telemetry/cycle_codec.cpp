#include "common/telemetry/cycle_codec.hpp"

namespace teleop::telemetry {

v1::NodeMode to_proto(node::Mode m) noexcept {
  return static_cast<v1::NodeMode>(node::wire_mode(m));
}

node::Mode from_proto(v1::NodeMode m) noexcept { return node::mode_from_wire(static_cast<int>(m)); }

void to_proto(const node::CycleRecord& rec, v1::CycleRecord& out) {
  out.set_sequence(rec.sequence);
  out.set_sample_time_ns(rec.sample_time_ns);
  out.set_mode(to_proto(rec.mode));
  out.set_position_m(rec.position_m);
  out.set_velocity_m_per_s(rec.velocity_m_per_s);
  out.set_force_n(rec.force_N);
  out.set_command_n(rec.command_N);
  out.set_peer_sequence(rec.peer_sequence);
  out.set_peer_position_m(rec.peer_position_m);
  out.set_peer_age_ns(rec.peer_age_ns);
  out.set_coupling_weight(rec.coupling_weight);
  out.set_flags(rec.flags);
  out.set_wakeup_latency_ns(rec.wakeup_latency_ns);
  out.set_round_trip_ns(rec.round_trip_ns);
  out.set_master_sequence(rec.master_sequence);
  out.set_parameter_change_id(rec.parameter_change_id);
  out.set_alignment_error_m(rec.alignment_error_m);
}

node::CycleRecord from_proto(const v1::CycleRecord& c) noexcept {
  node::CycleRecord r;
  r.sequence = c.sequence();
  r.sample_time_ns = c.sample_time_ns();
  r.mode = from_proto(c.mode());
  r.position_m = c.position_m();
  r.velocity_m_per_s = c.velocity_m_per_s();
  r.force_N = c.force_n();
  r.command_N = c.command_n();
  r.peer_sequence = c.peer_sequence();
  r.peer_position_m = c.peer_position_m();
  r.peer_age_ns = c.peer_age_ns();
  r.coupling_weight = c.coupling_weight();
  r.flags = c.flags();
  r.wakeup_latency_ns = c.wakeup_latency_ns();
  r.round_trip_ns = c.round_trip_ns();
  r.master_sequence = c.master_sequence();
  r.parameter_change_id = c.parameter_change_id();
  r.alignment_error_m = c.alignment_error_m();
  return r;
}

}  // namespace teleop::telemetry
