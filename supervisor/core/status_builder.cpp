#include "supervisor/core/status_builder.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include "common/telemetry/cycle_codec.hpp"

namespace teleop::supervisor {

void feed_monitors(const v1::CycleRecord& cycle, bool is_master, OscillationMonitor& oscillation,
                   PassivityObserver& passivity) {
  if (cycle.mode() == v1::ENGAGED || cycle.mode() == v1::CLUTCHED) {
    oscillation.add(cycle.position_m());
    passivity.add(is_master ? cycle.force_n() : -cycle.force_n(), cycle.velocity_m_per_s());
  } else {
    oscillation.clear();
    passivity.reset();
  }
}

MonitorReadings read_monitors(const OscillationMonitor& oscillation,
                              const PassivityObserver& passivity) {
  MonitorReadings r;
  if (oscillation.full()) {
    const scene::Oscillation o = oscillation.check();
    r.oscillation_amplitude_m = o.amplitude_m;
    r.oscillation_frequency_hz = o.frequency_hz;
    r.oscillating = o.detected;
  }
  r.passivity_energy_J = passivity.energy_J();
  return r;
}

void fill_node_axes(v1::NodeSummary& out, const v1::CycleRecord& cycle, bool is_master,
                    double position_scaling) {
  out.clear_axes();
  out.clear_positions_m();
  out.clear_forces_n();
  out.clear_commands_n();
  out.clear_tracking_errors_m();
  const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(cycle);
  if (!r || r->axes < 2) return;
  out.set_axes(static_cast<std::uint32_t>(r->axes));
  for (std::size_t i = 0; i < static_cast<std::size_t>(r->axes); ++i) {
    out.add_positions_m(r->position_m[i]);
    out.add_forces_n(r->force_N[i]);
    out.add_commands_n(r->command_N[i]);
    const double x_m = is_master ? r->position_m[i] : r->peer_position_m[i];
    const double x_s = is_master ? r->peer_position_m[i] : r->position_m[i];
    out.add_tracking_errors_m(position_scaling * x_m - x_s);
  }
}

NodeSummaryBuilder::NodeSummaryBuilder(bool is_master, double fixture_position_m,
                                       double fixture_stiffness_N_per_m, double window_s,
                                       double bucket_s, double position_scaling)
    : is_master_(is_master),
      position_scaling_(position_scaling),
      fixture_position_m_(fixture_position_m),
      fixture_stiffness_N_per_m_(fixture_stiffness_N_per_m),
      bucket_ns_(std::max<std::int64_t>(1, std::llround(bucket_s * 1e9))),
      buckets_kept_(static_cast<std::size_t>(std::max(1.0, std::round(window_s / bucket_s)))) {}

void NodeSummaryBuilder::reset() {
  have_ = false;
  have_cycle_ = false;
  last_.Clear();
  cycle_times_ns_.clear();
  overrun_history_.clear();
  buckets_.clear();
}

double NodeSummaryBuilder::penetration(double position_m, double stiffness_N_per_m) const {
  if (!(stiffness_N_per_m > 0.0)) return 0.0;
  return std::max(0.0, position_m - fixture_position_m_);
}

void NodeSummaryBuilder::add(const v1::Telemetry& t, std::int64_t received_ns) {
  const double stiffness = t.has_active()
                               ? (is_master_ ? t.active().master_fixture_stiffness_n_per_m()
                                             : t.active().slave_fixture_stiffness_n_per_m())
                               : fixture_stiffness_N_per_m_;
  for (const v1::CycleRecord& c : t.cycles()) {
    const std::int64_t ts = c.sample_time_ns();
    if (have_cycle_ && ts <= newest_cycle_.sample_time_ns()) continue;  // not newer: skipped
    newest_cycle_ = c;
    have_cycle_ = true;
    cycle_times_ns_.push_back(ts);
    while (cycle_times_ns_.front() < ts - 1'000'000'000) cycle_times_ns_.pop_front();
    // n > 1 axes: the traces are the norms of position and force and the deepest plane's
    // penetration (the one-axis scalars are 0 in such a record).
    const bool several = c.axes() > 1;
    const auto norm = [](const google::protobuf::RepeatedField<double>& v) {
      double sum = 0.0;
      for (const double e : v) sum += e * e;
      return std::sqrt(sum);
    };
    const auto x = static_cast<float>(several ? norm(c.positions_m()) : c.position_m());
    const auto f = static_cast<float>(several ? norm(c.forces_n()) : c.force_n());
    const auto p = static_cast<float>(several ? c.fixture_penetration_m()
                                              : penetration(c.position_m(), stiffness));
    const std::int64_t index = ts / bucket_ns_;
    if (buckets_.empty() || index > buckets_.back().index) {
      buckets_.push_back(Bucket{index, x, x, f, f, p, p});
    } else {
      Bucket& b = buckets_.back();
      b.position_min = std::min(b.position_min, x);
      b.position_max = std::max(b.position_max, x);
      b.force_min = std::min(b.force_min, f);
      b.force_max = std::max(b.force_max, f);
      b.penetration_min = std::min(b.penetration_min, p);
      b.penetration_max = std::max(b.penetration_max, p);
    }
    while (buckets_.front().index <= index - static_cast<std::int64_t>(buckets_kept_)) {
      buckets_.pop_front();
    }
  }
  const std::int64_t sent = t.sent_time_ns();
  if (overrun_history_.empty() || sent - overrun_history_.back().first >= 500'000'000) {
    overrun_history_.emplace_back(sent, t.loop().overruns());
  }
  while (overrun_history_.size() >= 2 && overrun_history_[1].first <= sent - 60'000'000'000) {
    overrun_history_.pop_front();
  }
  last_ = t;
  last_.clear_cycles();
  last_.clear_flight_record();
  have_ = true;
  received_ns_ = received_ns;
}

void NodeSummaryBuilder::fill(v1::NodeSummary& out, std::int64_t now_ns,
                              const MonitorReadings& monitors) const {
  out.Clear();
  if (!have_) return;
  const std::int64_t age = now_ns - received_ns_;
  out.set_alive(age < 500'000'000);
  out.set_telemetry_age_ns(age);
  out.set_mode(last_.mode());
  out.set_mode_reason(last_.mode_reason());
  out.set_device(last_.device());
  if (cycle_times_ns_.size() >= 2 && cycle_times_ns_.back() > cycle_times_ns_.front()) {
    out.set_loop_rate_hz(static_cast<double>(cycle_times_ns_.size() - 1) * 1e9 /
                         static_cast<double>(cycle_times_ns_.back() - cycle_times_ns_.front()));
  }
  *out.mutable_loop() = last_.loop();
  const std::uint64_t overruns = last_.loop().overruns();
  const std::uint64_t before =
      overrun_history_.empty() ? overruns : overrun_history_.front().second;
  out.set_overruns_last_minute(overruns - std::min(overruns, before));
  *out.mutable_rt() = last_.rt();
  *out.mutable_link() = last_.link();
  *out.mutable_active() = last_.active();
  if (have_cycle_) {
    const double stiffness = last_.has_active()
                                 ? (is_master_ ? last_.active().master_fixture_stiffness_n_per_m()
                                               : last_.active().slave_fixture_stiffness_n_per_m())
                                 : fixture_stiffness_N_per_m_;
    out.set_position_m(newest_cycle_.position_m());
    out.set_velocity_m_per_s(newest_cycle_.velocity_m_per_s());
    out.set_force_n(newest_cycle_.force_n());
    out.set_command_n(newest_cycle_.command_n());
    out.set_fixture_penetration_m(penetration(newest_cycle_.position_m(), stiffness));
    out.set_alignment_error_m(newest_cycle_.alignment_error_m());
    fill_node_axes(out, newest_cycle_, is_master_, position_scaling_);
  }
  const double bucket_s = static_cast<double>(bucket_ns_) * 1e-9;
  v1::Trace* traces[] = {out.mutable_position_trace_m(), out.mutable_force_trace_n(),
                         out.mutable_penetration_trace_m()};
  for (v1::Trace* tr : traces) tr->set_bucket_s(bucket_s);
  for (const Bucket& b : buckets_) {
    traces[0]->add_min(b.position_min);
    traces[0]->add_max(b.position_max);
    traces[1]->add_min(b.force_min);
    traces[1]->add_max(b.force_max);
    traces[2]->add_min(b.penetration_min);
    traces[2]->add_max(b.penetration_max);
  }
  out.set_oscillation_amplitude_m(monitors.oscillation_amplitude_m);
  out.set_oscillation_frequency_hz(monitors.oscillation_frequency_hz);
  out.set_oscillating(monitors.oscillating);
  out.set_passivity_energy_j(monitors.passivity_energy_J);
}

}  // namespace teleop::supervisor
