#include "supervisor/teleopctl/simulate_command.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <ostream>
#include <sstream>
#include <string_view>

#include "common/config/axes_config.hpp"
#include "common/config/scene_loader.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/device/sim_device.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/proto_schema.hpp"
#include "common/record/session.hpp"
#include "common/record/session_recorder.hpp"
#include "common/scene/lockstep.hpp"
#include "common/stability/analyzer.hpp"
#include "supervisor/core/report.hpp"
#include "supervisor/core/session_output.hpp"
#include "supervisor/core/stability_guard.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/axes_commands.hpp"
#include "supervisor/teleopctl/progress_line.hpp"
#include "supervisor/teleopctl/session_file.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"
#include "teleop/v1/supervisor.pb.h"
#include "teleop/v1/telemetry.pb.h"

namespace teleop::ctl {

namespace {

using nlohmann::json;

json oscillation_json(const scene::Oscillation& o) {
  return {{"detected", o.detected},
          {"amplitude_m", o.amplitude_m},
          {"frequency_hz", o.frequency_hz},
          {"previous_amplitude_m", o.previous_amplitude_m}};
}

void write_csv(const std::string& path, const scene::SimulationResult& r) {
  std::ofstream f(path);
  for (std::size_t i = 0; i < r.columns.size(); ++i) f << (i ? "," : "") << r.columns[i];
  f << "\n";
  const std::size_t n = r.columns.size();
  for (std::size_t row = 0; n > 0 && row * n < r.rows.size(); ++row) {
    for (std::size_t i = 0; i < n; ++i) {
      // Shortest round-trip representation: the same doubles give the same bytes.
      f << (i ? "," : "") << fmt::format("{}", r.rows[row * n + i]);
    }
    f << "\n";
  }
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
}

// --- the session file (--out FILE.mcap) -------------------------------------------------------

// What the supervisor would publish at the start of this session (supervisor/core/report.hpp):
// the analyser on the configured loop with the scene's round trip, which is the one the lockstep
// simulator plays.
[[nodiscard]] v1::StabilityReport start_report(const TeleopParams& params) {
  supervisor::StabilityGuard guard(params);
  const supervisor::Assessment a = guard.assess(guard.configured_inputs());
  return supervisor::to_report(
      a, supervisor::ReportContext{0, 0,
                                   static_cast<std::int64_t>(std::llround(
                                       1e9 * a.inputs.round_trip_samples / params.sample_rate_hz)),
                                   "start (teleopctl simulate)", 0});
}

// The true force on each device's load cell at time 0 (the simulation's rows start after the
// first period).
[[nodiscard]] double initial_force_N(device::SimDeviceConfig cfg, std::chrono::nanoseconds period,
                                     double position_m) {
  cfg.period = period;
  cfg.initial_position_m = position_m;
  device::SimDevice dev(cfg);
  if (!dev.configure().ok() || !dev.activate().ok()) return 0.0;
  const device::SimTruth t = dev.truth();
  return cfg.human ? t.output.human_force_N : t.output.environment_force_N;
}

// The lockstep rows as a live session would have recorded them (common/record/session.hpp's
// topics, types and conventions): /config, /supervisor/stability, the metadata and the
// configuration attachment at the session's start, then /master/telemetry and
// /slave/telemetry, kCyclesPerMessage cycles per message, logged at the end of the last cycle's
// period, and each cycle on /master/cycle and /slave/cycle (supervisor/core/session_output.hpp).
// Log times are the start (the wall clock when the run began, or --log-start-ns) plus
// simulated time; the cycles' sample times (publish_time) are simulated time from 0.
//
// Cycle k (sequence k + 1, sample time k T) is what each node's law saw at its sample k: the
// row's *_sensed_m; the force on its load cell then, which the row before carries (the true
// force: no load-cell noise; at k = 0 the initial state's); the velocity its law estimates
// from the sensed positions; the command it wrote, held over [kT, (k+1)T) (the master's
// actuator is driven by -F_am); the peer state of that sample: the slave's at once, the
// master's round_trip_delay_samples late.
// The simulation's rows by column name.
class SimRows {
 public:
  explicit SimRows(const scene::SimulationResult& r) : r_(r), n_cols_(r.columns.size()) {}
  [[nodiscard]] std::size_t col(const char* name) const {
    for (std::size_t i = 0; i < n_cols_; ++i) {
      if (r_.columns[i] == name) return i;
    }
    throw std::logic_error(fmt::format("simulation rows have no column '{}'", name));
  }
  [[nodiscard]] std::size_t rows() const { return n_cols_ == 0 ? 0 : r_.rows.size() / n_cols_; }
  [[nodiscard]] double at(std::size_t row, std::size_t c) const {
    return r_.rows[row * n_cols_ + c];
  }

 private:
  const scene::SimulationResult& r_;
  std::size_t n_cols_;
};

// One node's cycle as the law saw it (the caller fills the node's own values).
void set_cycle(v1::CycleRecord& c, std::uint64_t seq, std::int64_t time_ns, double position_m,
               double velocity_m_per_s, double force_N, double command_N) {
  c.set_sequence(seq);
  c.set_sample_time_ns(time_ns);
  c.set_mode(v1::ENGAGED);
  c.set_position_m(position_m);
  c.set_velocity_m_per_s(velocity_m_per_s);
  c.set_force_n(force_N);
  c.set_command_n(command_N);
}

void write_session_mcap(const std::string& path, const config::LoadedConfig& cfg,
                        const scene::SceneSetup& setup, const scene::SimulationResult& r,
                        std::int64_t start_ns) {
  const SimRows sim(r);
  const std::size_t c_xm = sim.col("master_sensed_m");
  const std::size_t c_xs = sim.col("slave_sensed_m");
  const std::size_t c_fam = sim.col("master_force_N");
  const std::size_t c_fas = sim.col("slave_force_N");
  const std::size_t c_fh = sim.col("human_force_N");
  const std::size_t c_fe = sim.col("environment_force_N");
  const std::size_t rows = sim.rows();

  const TeleopParams& p = setup.teleop;
  const double rate = p.sample_rate_hz;
  const std::int64_t period_ns = std::llround(1e9 / rate);
  const std::chrono::nanoseconds period{period_ns};
  const std::size_t delay = static_cast<std::size_t>(p.round_trip_delay_samples);
  // The lockstep simulator's start (lockstep.cpp): at rest, or at the static equilibrium.
  double master0 = setup.master.initial_position_m;
  double slave0 = setup.slave.initial_position_m;
  if (setup.equilibrium_perturbation_m) {
    const scene::Equilibrium eq = scene::static_equilibrium(p, setup.equilibrium_push_N);
    master0 = eq.master_m;
    slave0 = eq.slave_m + *setup.equilibrium_perturbation_m;
  }
  const double master_f0 = initial_force_N(setup.master, period, master0);
  const double slave_f0 = initial_force_N(setup.slave, period, slave0);
  const double period_s = 1.0 / rate;
  control::VelocityEstimator master_velocity(period_s, setup.law.velocity_cutoff_hz);
  control::VelocityEstimator slave_velocity(period_s, setup.law.velocity_cutoff_hz);
  master_velocity.reset(master0);
  slave_velocity.reset(slave0);

  SessionFile file(path);
  write_session_start(file, cfg, start_report(p), start_ns);
  const std::uint64_t seed = setup.seed;
  const SimulatedTelemetry frame{&p,
                                 0x5349'4D00'0000'0000ULL ^ (2 * seed + 1),
                                 0x5349'4D00'0000'0000ULL ^ (2 * seed + 2),
                                 period_s,
                                 delay,
                                 static_cast<std::int64_t>(delay) * period_ns};
  SimulatedNodes nodes(file, frame, start_ns, period_ns);
  for (std::size_t k = 0; k < rows; ++k) {
    const std::uint64_t seq = k + 1;
    const std::int64_t time_ns = static_cast<std::int64_t>(k) * period_ns;
    const double xm = sim.at(k, c_xm);
    const double xs = sim.at(k, c_xs);
    // The slave's view of the master: its state `delay` samples ago (the lockstep's in-flight
    // buffer starts with the master's initial position).
    const bool have_master = k >= delay;
    const double xm_seen = have_master ? sim.at(k - delay, c_xm) : master0;
    const std::uint64_t master_seq_seen = have_master ? k - delay + 1 : 0;

    v1::CycleRecord* c = &nodes.master_cycle(k);
    // 0.0 -: no negative zero in the CSV
    set_cycle(*c, seq, time_ns, xm, master_velocity.step(xm),
              k == 0 ? master_f0 : sim.at(k - 1, c_fh), 0.0 - sim.at(k, c_fam));
    c->set_peer_sequence(seq);
    c->set_peer_position_m(xs);
    c->set_peer_age_ns(0);
    c->set_coupling_weight(1.0);
    c->set_round_trip_ns(frame.round_trip_ns);
    c->set_master_sequence(seq);

    c = &nodes.slave_cycle();
    set_cycle(*c, seq, time_ns, xs, slave_velocity.step(xs),
              k == 0 ? slave_f0 : sim.at(k - 1, c_fe), sim.at(k, c_fas));
    c->set_peer_sequence(master_seq_seen);
    c->set_peer_position_m(xm_seen);
    c->set_peer_age_ns(frame.round_trip_ns);
    c->set_coupling_weight(1.0);
    c->set_round_trip_ns(frame.round_trip_ns);
    c->set_master_sequence(master_seq_seen);
    nodes.done(k, k + 1 == rows);
  }
  file.close();
}

// "human_force_N" -> "human force", "slave_position_m" -> "slave".
std::string trace_name(const std::string& column) {
  std::string name = column.substr(0, column.rfind('_'));
  if (name.ends_with("_position")) name.resize(name.size() - 9);
  for (char& c : name) c = c == '_' ? ' ' : c;
  return name;
}

// A trace's colour follows its node: the master and the hand on it in one colour, the slave
// and its environment in another, a force device's signals after them.
std::size_t trace_colour(const std::string& column, std::size_t& next) {
  if (column.starts_with("master") || column.starts_with("human")) return 0;
  if (column.starts_with("slave") || column.starts_with("environment")) return 1;
  return next++;
}

// A fixture as a dashed line at its position in the position panel.
void add_fixture(Chart& chart, const char* side, const FixtureParams& f, double t_end,
                 std::size_t colour) {
  if (!(f.stiffness_N_per_m > 0.0)) return;
  add_level(chart, 0, fmt::format("{} fixture ({:g} N/m)", side, f.stiffness_N_per_m),
            1e3 * f.position_m, 0.0, t_end, line_colour(colour));
}

// Positions (mm) above forces (N) against time: what the devices and the people did; the
// laws' internal signals (sensed positions, actuator forces, averages) stay in --out.
void write_plot(const std::string& path, const std::string& scene_name,
                const scene::SceneSetup& setup, const scene::SimulationResult& r) {
  const SimRows sim(r);
  const std::size_t n = r.columns.size();
  const bool bilateral = r.summary.kind == "bilateral";
  Chart chart = position_force_chart(
      bilateral ? "Bilateral paddles, simulated: positions and forces"
                : "Force-controlled device, simulated: positions and forces",
      fmt::format("teleopctl simulate {}, {:g} s",
                  std::filesystem::path(scene_name).filename().string(), r.summary.duration_s));
  const std::size_t stride = plot_stride(sim.rows());
  std::size_t next = bilateral ? 2 : 0;
  for (std::size_t i = 1; i < n; ++i) {
    const std::string& c = r.columns[i];
    const bool position = c.ends_with("_position_m");
    const bool force = c.ends_with("_force_N") && c.find("average") == std::string::npos &&
                       c != "master_force_N" && c != "slave_force_N" && c != "actuator_force_N";
    if (!position && !force) continue;
    Series s{trace_name(c), {}, line_colour(trace_colour(c, next)), true};
    for (std::size_t row = 0; row < sim.rows(); row += stride) {
      s.points.emplace_back(sim.at(row, 0), position ? 1e3 * sim.at(row, i) : sim.at(row, i));
    }
    chart.panels[position ? 0 : 1].series.push_back(std::move(s));
  }
  if (bilateral) {
    add_fixture(chart, "master", setup.teleop.master_fixture, r.summary.duration_s, 0);
    add_fixture(chart, "slave", setup.teleop.slave_fixture, r.summary.duration_s, 1);
  }
  write_svg(path, chart);
}

}  // namespace

json simulation_document(const config::LoadedConfig& cfg, const scene::SceneSetup& setup,
                         const scene::SimulationResult& r) {
  const scene::SimulationSummary& s = r.summary;
  json j = {{"scene", cfg.source_name},
            {"kind", s.kind},
            {"duration_s", s.duration_s},
            {"steps", s.steps},
            {"ideal", setup.ideal},
            {"seed", setup.seed},
            {"max_penetration_master_m", s.max_penetration_master_m},
            {"max_penetration_slave_m", s.max_penetration_slave_m},
            {"tracking_error_rms_m", s.tracking_error_rms_m},
            {"force_error_rms_N", s.force_error_rms_N},
            {"force_error_peak_N", s.force_error_peak_N},
            {"parasitic_force_peak_N", s.parasitic_force_peak_N},
            {"oscillation", oscillation_json(s.oscillation)},
            {"fault", s.fault},
            {"wall_time_s", s.wall_time_s},
            {"real_time_factor", s.real_time_factor}};
  if (s.kind == "bilateral") {
    j["master_oscillation"] = oscillation_json(s.master_oscillation);
    // What the analyser predicts for this loop with its fixtures engaged.
    const TeleopParams& p = setup.teleop;
    const stability::AnalysisResult a = stability::analyze(p);
    j["predicted"] = {{"verdict", stability::to_string(a.verdict)},
                      {"min_damping_ratio", a.min_damping_ratio},
                      {"spectral_radius", a.spectral_radius}};
  }
  return j;
}

std::string simulate_usage() {
  return "usage: teleopctl simulate SCENE [--duration S] [--seed N] [--set PATH=VALUE]...\n"
         "                          [--out FILE.csv|FILE.mcap] [--log-start-ns N]\n"
         "                          [--plot FILE.svg] [--json]\n\n"
         "--out FILE.csv writes the time series (SI units, named columns); --out FILE.mcap a\n"
         "session file as teleop-supervisor records a live run (/config, /master/telemetry and\n"
         "/slave/telemetry with every cycle, /master/cycle and /slave/cycle one message per\n"
         "cycle, /supervisor/stability, metadata, the scene as an attachment), for 'teleopctl\n"
         "replay', Foxglove or PlotJuggler. Its log times are the wall clock when the run began\n"
         "plus simulated time; --log-start-ns N starts them at N instead (0: simulated time, and\n"
         "the same bytes for the same scene). With axes > 1 the session's cycles carry every axis\n"
         "(docs/simulate.md \"Several axes from the command line\").\n";
}

SimulateOptions parse_simulate_args(const std::vector<std::string>& args) {
  SimulateOptions o;
  ArgCursor c(args);
  while (c.next()) {
    const std::string& a = c.arg();
    auto value = [&](const char* flag) -> const std::string& { return c.value(flag); };
    if (a == "--json") {
      o.json = true;
    } else if (a == "--set") {
      o.overrides.push_back(value("--set"));
    } else if (a == "--duration") {
      const std::string& v = value("--duration");
      const double d = parse_number(v, "--duration");
      if (!(d > 0.0)) {
        throw UsageError(fmt::format("--duration: '{}' is not a positive number of seconds", v));
      }
      o.duration_s = d;
    } else if (a == "--seed") {
      const std::string& v = value("--seed");
      unsigned long long s = 0;
      const auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), s);
      if (ec != std::errc{} || p != v.data() + v.size()) {
        throw UsageError(fmt::format("--seed: '{}' is not a non-negative integer", v));
      }
      o.seed = s;
    } else if (a == "--log-start-ns") {
      const std::string v = value("--log-start-ns");
      long long n = 0;
      const auto [p, ec] = std::from_chars(v.data(), v.data() + v.size(), n);
      if (ec != std::errc{} || p != v.data() + v.size() || n < 0) {
        throw UsageError(fmt::format(
            "--log-start-ns: '{}' is not a non-negative integer (ns since the epoch)", v));
      }
      o.log_start_ns = n;
    } else if (a == "--out") {
      o.out_path = value("--out");
    } else if (a == "--plot") {
      o.plot_path = svg_plot_path(value("--plot"));
    } else {
      take_only_positional(a, o.scene_path, "-");
    }
  }
  if (o.scene_path.empty()) throw UsageError("missing SCENE");
  return o;
}

int run_simulate(const SimulateOptions& o, std::ostream& out, std::ostream& err) {
  return run_guarded("simulate", err, [&] {
    // A session file's log times start at the wall clock of the run (before simulating).
    const std::int64_t start_ns = o.log_start_ns ? *o.log_start_ns : supervisor::wall_clock_ns();
    std::vector<std::string> sets = o.overrides;
    if (o.duration_s) sets.push_back(fmt::format("scene.duration_s={}", *o.duration_s));
    if (o.seed) sets.push_back(fmt::format("scene.seed={}", *o.seed));
    // to_scene_setup validates the parsed file once and builds the sides as the nodes do.
    const config::LoadedConfig cfg = config::parse_config_file(o.scene_path, sets);
    // Several task-space axes: the n-axis simulator (axes_commands.cpp).
    if (config::configured_axes(cfg.config) > 1) return run_simulate_axes(cfg, o, out, err);
    const scene::SceneSetup setup = config::to_scene_setup(cfg);
    scene::SimulationResult r;
    {
      ProgressLine progress(err, "simulate", !o.json && stderr_is_terminal());
      r = scene::simulate(setup, [&](double f) { progress.update(f); });
    }
    const scene::SimulationSummary& s = r.summary;

    const json j = simulation_document(cfg, setup, r);
    if (o.json) {
      out << j.dump(2) << "\n";
    } else {
      out << fmt::format("{}: {} scene, {:g} s simulated in {:.3f} s ({:.0f}x real time)\n",
                         cfg.source_name, s.kind, s.duration_s, s.wall_time_s, s.real_time_factor);
      out << fmt::format("  oscillation: {} (amplitude {:.3g} m at {:.3g} Hz)\n",
                         s.oscillation.detected ? "SUSTAINED" : "none", s.oscillation.amplitude_m,
                         s.oscillation.frequency_hz);
      if (j.contains("predicted")) {
        out << fmt::format("  analyser predicts: {} (minimum damping ratio {:.4f})\n",
                           j["predicted"]["verdict"].get<std::string>(),
                           j["predicted"]["min_damping_ratio"].get<double>());
      }
      out << fmt::format("  max penetration: master {:.4g} m, slave {:.4g} m\n",
                         s.max_penetration_master_m, s.max_penetration_slave_m);
      out << fmt::format(
          "  tracking error rms {:.4g} m; force error rms {:.4g} N (peak {:.4g} N)\n",
          s.tracking_error_rms_m, s.force_error_rms_N, s.force_error_peak_N);
      out << fmt::format("  parasitic force peak {:.4g} N\n", s.parasitic_force_peak_N);
      if (s.fault) out << "  a control law latched a fault\n";
    }
    if (o.out_path && is_mcap_path(*o.out_path)) {
      if (setup.force_device) {
        throw std::runtime_error(fmt::format(
            "{}: a session file needs a bilateral scene (master and slave); this is a force "
            "device scene: write --out FILE.csv",
            *o.out_path));
      }
      if (setup.output_rate_hz > 0.0 && setup.output_rate_hz < setup.teleop.sample_rate_hz) {
        // The session carries every cycle: the same run at full rate (deterministic).
        scene::SceneSetup full = setup;
        full.output_rate_hz = 0.0;
        write_session_mcap(*o.out_path, cfg, full, scene::simulate(full), start_ns);
      } else {
        write_session_mcap(*o.out_path, cfg, setup, r, start_ns);
      }
    } else if (o.out_path) {
      write_csv(*o.out_path, r);
    }
    if (o.plot_path) write_plot(*o.plot_path, cfg.source_name, setup, r);
    if (s.fault) return 5;
    return s.oscillation.detected || s.master_oscillation.detected ? 3 : 0;
  });
}

}  // namespace teleop::ctl
