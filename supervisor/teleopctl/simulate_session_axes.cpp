#include "supervisor/teleopctl/simulate_session_axes.hpp"

#include <cmath>
#include <cstddef>

#include "common/node/node_core_axes.hpp"
#include "common/node/node_side.hpp"
#include "common/telemetry/cycle_codec.hpp"
#include "supervisor/core/axes_supervision.hpp"
#include "supervisor/core/stability_guard_axes.hpp"
#include "supervisor/teleopctl/session_file.hpp"

namespace teleop::ctl {

namespace {

// What the supervisor would publish at the start of this session: the n-axis assessment of the
// configured loop with the scene's round trip, the one the lockstep simulator plays.
[[nodiscard]] v1::StabilityReport start_report_axes(const TeleopAxesParams& p) {
  const supervisor::AxesAssessment a =
      supervisor::assess_axes(p, p.analysis.required_damping_ratio);
  const auto round_trip_ns =
      static_cast<std::int64_t>(std::llround(1e9 * p.round_trip_delay_samples / p.sample_rate_hz));
  return supervisor::to_report(
      a, p, supervisor::ReportContext{0, 0, round_trip_ns, "start (teleopctl simulate)", 0});
}

// One node's cycle as its law saw it (the caller fills the peer fields).
node::CycleRecordAxes own_cycle(std::size_t k, std::int64_t period_ns, const control::AxisVector& x,
                                const control::AxisVector& v, const control::AxisVector& f,
                                const control::CommandAxes& c, double command_sign) {
  node::CycleRecordAxes r;
  r.sequence = k + 1;
  r.sample_time_ns = static_cast<std::int64_t>(k) * period_ns;
  r.clock_ns = r.sample_time_ns;
  r.mode = node::Mode::kEngaged;
  r.axes = static_cast<int>(x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const auto j = static_cast<std::size_t>(i);
    r.position_m[j] = x(i);
    r.velocity_m_per_s[j] = v(i);
    r.force_N[j] = f(i);
    r.command_N[j] = 0.0 + command_sign * c.force_N(i);  // 0.0 +: no negative zero in the CSV
  }
  r.coupling_weight = 1.0;
  r.flags = node::law_flags(c.flags);
  r.fixture_penetration_m = c.penetration_m;
  return r;
}

}  // namespace

scene::AxesSimulationResult simulate_axes_session(const std::string& path,
                                                  const config::LoadedConfig& cfg,
                                                  const scene::AxesSceneSetup& setup,
                                                  std::int64_t start_ns,
                                                  const scene::Progress& progress) {
  const TeleopAxesParams& p = setup.teleop;
  const std::int64_t period_ns = std::llround(1e9 / p.sample_rate_hz);
  const auto delay = static_cast<std::size_t>(p.round_trip_delay_samples);
  const std::int64_t round_trip_ns = static_cast<std::int64_t>(delay) * period_ns;
  SessionFile file(path);
  write_session_start(file, cfg, start_report_axes(p), start_ns);
  // The same session ids as a one-axis session of seed 0 (the n-axis simulator has no seed).
  const SimulatedTelemetry frame{nullptr,
                                 0x5349'4D00'0000'0001ULL,
                                 0x5349'4D00'0000'0002ULL,
                                 1.0 / p.sample_rate_hz,
                                 delay,
                                 round_trip_ns};
  SimulatedNodes nodes(file, frame, start_ns, period_ns);
  const auto steps = static_cast<std::size_t>(std::lround(setup.duration_s * p.sample_rate_hz));
  const auto observer = [&](const scene::AxesCycleView& c) {
    const auto k = static_cast<std::size_t>(c.k);
    node::CycleRecordAxes m = own_cycle(k, period_ns, c.master_m, c.master_velocity_m_per_s,
                                        c.master_force_N, c.master_command, -1.0);
    m.peer_sequence = k + 1;
    m.master_sequence = k + 1;
    m.round_trip_ns = round_trip_ns;
    for (Eigen::Index i = 0; i < c.slave_m.size(); ++i) {
      m.peer_position_m[static_cast<std::size_t>(i)] = c.slave_m(i);
    }
    telemetry::to_proto(m, nodes.master_cycle(k));
    // The slave's view of the master: its state `delay` samples ago (the initial one before).
    node::CycleRecordAxes s = own_cycle(k, period_ns, c.slave_m, c.slave_velocity_m_per_s,
                                        c.slave_force_N, c.slave_command, 1.0);
    s.peer_sequence = k >= delay ? k - delay + 1 : 0;
    s.master_sequence = s.peer_sequence;
    s.peer_age_ns = round_trip_ns;
    s.round_trip_ns = round_trip_ns;
    for (Eigen::Index i = 0; i < c.slave_received.position_m.size(); ++i) {
      s.peer_position_m[static_cast<std::size_t>(i)] = c.slave_received.position_m(i);
    }
    telemetry::to_proto(s, nodes.slave_cycle());
    nodes.done(k, k + 1 == steps);
  };
  scene::AxesSimulationResult r = scene::simulate_axes(setup, progress, observer);
  file.close();
  return r;
}

}  // namespace teleop::ctl
