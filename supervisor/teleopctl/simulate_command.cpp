#include "supervisor/teleopctl/simulate_command.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <ostream>

#include "common/config/scene_loader.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/device/sim_device.hpp"
#include "common/record/mcap_writer.hpp"
#include "common/record/proto_schema.hpp"
#include "common/scene/lockstep.hpp"
#include "common/stability/analyzer.hpp"
#include "supervisor/core/report.hpp"
#include "supervisor/core/stability_guard.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
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

// Cycles per Telemetry message: a live node's 50 messages/s at 1 kHz.
constexpr std::size_t kCyclesPerMessage = 20;

[[nodiscard]] bool is_mcap_path(const std::string& path) {
  return path.size() >= 5 && path.compare(path.size() - 5, 5, ".mcap") == 0;
}

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

// The simulation's rows, by column name.
class Rows {
 public:
  explicit Rows(const scene::SimulationResult& r) : r_(r), n_cols_(r.columns.size()) {}
  [[nodiscard]] std::size_t column(const char* name) const {
    for (std::size_t i = 0; i < n_cols_; ++i) {
      if (r_.columns[i] == name) return i;
    }
    throw std::logic_error(fmt::format("simulation rows have no column '{}'", name));
  }
  [[nodiscard]] std::size_t count() const { return n_cols_ == 0 ? 0 : r_.rows.size() / n_cols_; }
  [[nodiscard]] double at(std::size_t row, std::size_t c) const {
    return r_.rows[row * n_cols_ + c];
  }

 private:
  const scene::SimulationResult& r_;
  std::size_t n_cols_;
};

// The lockstep simulator's start (lockstep.cpp): at rest, or at the static equilibrium.
struct LockstepStart {
  double master_m;
  double slave_m;
};

LockstepStart lockstep_start(const scene::SceneSetup& setup) {
  if (!setup.equilibrium_perturbation_m) {
    return {setup.master.initial_position_m, setup.slave.initial_position_m};
  }
  const scene::Equilibrium eq = scene::static_equilibrium(setup.teleop, setup.equilibrium_push_N);
  return {eq.master_m, eq.slave_m + *setup.equilibrium_perturbation_m};
}

// The lockstep rows as a live session would have recorded them (session_recorder.cpp's
// topics and types): /config, /supervisor/stability at log time 0, then /master/telemetry and
// /slave/telemetry, kCyclesPerMessage cycles per message, logged at the end of the last cycle's
// period (simulated time).
//
// Cycle k (sequence k + 1, sample time k T) is what each node's law saw at its sample k: the
// row's *_sensed_m; the force on its load cell then, which the row before carries (the true
// force: no load-cell noise; at k = 0 the initial state's); the velocity its law estimates
// from the sensed positions; the command it wrote, held over [kT, (k+1)T) (the master's
// actuator is driven by -F_am); the peer state of that sample: the slave's at once, the
// master's round_trip_delay_samples late.
class SessionFile {
 public:
  SessionFile(const std::string& path, const scene::SceneSetup& setup,
              const scene::SimulationResult& r)
      : p_(setup.teleop),
        rows_(r),
        c_xm_(rows_.column("master_sensed_m")),
        c_xs_(rows_.column("slave_sensed_m")),
        c_fam_(rows_.column("master_force_N")),
        c_fas_(rows_.column("slave_force_N")),
        c_fh_(rows_.column("human_force_N")),
        c_fe_(rows_.column("environment_force_N")),
        period_ns_(std::llround(1e9 / p_.sample_rate_hz)),
        period_s_(1.0 / p_.sample_rate_hz),
        delay_(static_cast<std::size_t>(p_.round_trip_delay_samples)),
        round_trip_ns_(static_cast<std::int64_t>(delay_) * period_ns_),
        start_(lockstep_start(setup)),
        master_f0_(
            initial_force_N(setup.master, std::chrono::nanoseconds{period_ns_}, start_.master_m)),
        slave_f0_(
            initial_force_N(setup.slave, std::chrono::nanoseconds{period_ns_}, start_.slave_m)),
        master_velocity_(period_s_, setup.law.velocity_cutoff_hz),
        slave_velocity_(period_s_, setup.law.velocity_cutoff_hz),
        master_session_(0x5349'4D00'0000'0000ULL ^ (2 * setup.seed + 1)),
        slave_session_(0x5349'4D00'0000'0000ULL ^ (2 * setup.seed + 2)),
        writer_(path, writer_options()) {
    master_velocity_.reset(start_.master_m);
    slave_velocity_.reset(start_.slave_m);
    config_ch_ = channel(v1::SystemConfig::descriptor(), "/config");
    report_ch_ = channel(v1::StabilityReport::descriptor(), "/supervisor/stability");
    master_ch_ = channel(v1::Telemetry::descriptor(), "/master/telemetry");
    slave_ch_ = channel(v1::Telemetry::descriptor(), "/slave/telemetry");
  }

  // /config and /supervisor/stability at log time 0.
  void write_start(const config::LoadedConfig& cfg) {
    write(config_ch_, 0, cfg.config.SerializeAsString());
    write(report_ch_, 0, start_report(p_).SerializeAsString());
  }

  // Every row, kCyclesPerMessage cycles to a message on each node's telemetry.
  void write_telemetry() {
    v1::Telemetry mt;
    v1::Telemetry st;
    const std::size_t rows = rows_.count();
    for (std::size_t k = 0; k < rows; ++k) {
      if (k % kCyclesPerMessage == 0) {
        start_message(mt, true);
        start_message(st, false);
      }
      add_cycles(k, mt, st);
      if ((k + 1) % kCyclesPerMessage == 0 || k + 1 == rows) {
        const std::int64_t now = static_cast<std::int64_t>(k) * period_ns_ + period_ns_;
        finish_message(mt, true, k + 1, now);
        finish_message(st, false, k + 1, now);
        write(master_ch_, now, mt.SerializeAsString());
        write(slave_ch_, now, st.SerializeAsString());
      }
    }
  }

  void close() {
    if (!writer_.close()) throw std::runtime_error(writer_.error());
  }

 private:
  static record::WriterOptions writer_options() {
    record::WriterOptions options;
    options.library = "teleop-record (teleopctl simulate)";
    // Offline: chunks by size only, so the same scene gives the same bytes.
    options.max_chunk_age = std::chrono::nanoseconds::max();
    return options;
  }

  // One schema per type, as the live recorder keeps them.
  std::uint16_t channel(const google::protobuf::Descriptor* d, const char* topic) {
    auto it = schemas_.find(d);
    if (it == schemas_.end()) {
      it = schemas_.emplace(d, writer_.add_schema(record::protobuf_schema(d))).first;
    }
    return writer_.add_channel(record::protobuf_channel(it->second, topic));
  }

  void write(std::uint16_t ch, std::int64_t log_time_ns, const std::string& bytes) {
    if (!writer_.write(ch, static_cast<std::uint64_t>(log_time_ns), bytes)) {
      throw std::runtime_error(writer_.error());
    }
  }

  void start_message(v1::Telemetry& t, bool master) const {
    t.Clear();
    t.set_session_id(master ? master_session_ : slave_session_);
    t.set_role(master ? v1::MASTER : v1::SLAVE);
    t.set_mode(v1::ENGAGED);
    t.set_mode_reason("simulated (teleopctl simulate, lockstep)");
    t.set_device("sim");
    v1::ActiveParameters* a = t.mutable_active();
    *a->mutable_gains() = supervisor::to_proto(p_.gains);
    a->set_master_fixture_stiffness_n_per_m(p_.master_fixture.stiffness_N_per_m);
    a->set_slave_fixture_stiffness_n_per_m(p_.slave_fixture.stiffness_N_per_m);
    a->set_ramp_progress(1.0);
  }

  void finish_message(v1::Telemetry& t, bool master, std::size_t cycles_so_far,
                      std::int64_t now) const {
    t.set_sent_time_ns(now);
    v1::LoopStats* l = t.mutable_loop();
    l->set_period_s(period_s_);
    l->set_cycles(cycles_so_far);
    v1::LinkStats* k = t.mutable_link();
    k->set_accepted(master ? cycles_so_far : (cycles_so_far > delay_ ? cycles_so_far - delay_ : 0));
    k->set_round_trip_ns(round_trip_ns_);
    k->set_round_trip_p50_ns(round_trip_ns_);
    k->set_round_trip_p99_ns(round_trip_ns_);
    k->set_round_trip_samples(static_cast<std::int32_t>(delay_));
    k->set_one_way_latency_ns(round_trip_ns_ / 2);
    k->set_peer_session_id(master ? slave_session_ : master_session_);
    k->set_peer_age_ns(master ? 0 : round_trip_ns_);
  }

  // Cycle k of each node.
  void add_cycles(std::size_t k, v1::Telemetry& mt, v1::Telemetry& st) {
    const std::uint64_t seq = k + 1;
    const std::int64_t time_ns = static_cast<std::int64_t>(k) * period_ns_;
    const double xm = rows_.at(k, c_xm_);
    const double xs = rows_.at(k, c_xs_);
    // The slave's view of the master: its state `delay` samples ago (the lockstep's in-flight
    // buffer starts with the master's initial position).
    const bool have_master = k >= delay_;
    const double xm_seen = have_master ? rows_.at(k - delay_, c_xm_) : start_.master_m;
    const std::uint64_t master_seq_seen = have_master ? k - delay_ + 1 : 0;

    v1::CycleRecord* c = mt.add_cycles();
    c->set_sequence(seq);
    c->set_sample_time_ns(time_ns);
    c->set_mode(v1::ENGAGED);
    c->set_position_m(xm);
    c->set_velocity_m_per_s(master_velocity_.step(xm));
    c->set_force_n(k == 0 ? master_f0_ : rows_.at(k - 1, c_fh_));
    c->set_command_n(0.0 - rows_.at(k, c_fam_));  // 0.0 -: no negative zero in the CSV
    c->set_peer_sequence(seq);
    c->set_peer_position_m(xs);
    c->set_peer_age_ns(0);
    c->set_coupling_weight(1.0);
    c->set_round_trip_ns(round_trip_ns_);
    c->set_master_sequence(seq);

    c = st.add_cycles();
    c->set_sequence(seq);
    c->set_sample_time_ns(time_ns);
    c->set_mode(v1::ENGAGED);
    c->set_position_m(xs);
    c->set_velocity_m_per_s(slave_velocity_.step(xs));
    c->set_force_n(k == 0 ? slave_f0_ : rows_.at(k - 1, c_fe_));
    c->set_command_n(rows_.at(k, c_fas_));
    c->set_peer_sequence(master_seq_seen);
    c->set_peer_position_m(xm_seen);
    c->set_peer_age_ns(round_trip_ns_);
    c->set_coupling_weight(1.0);
    c->set_round_trip_ns(round_trip_ns_);
    c->set_master_sequence(master_seq_seen);
  }

  const TeleopParams& p_;
  Rows rows_;
  std::size_t c_xm_;
  std::size_t c_xs_;
  std::size_t c_fam_;
  std::size_t c_fas_;
  std::size_t c_fh_;
  std::size_t c_fe_;
  std::int64_t period_ns_;
  double period_s_;
  std::size_t delay_;
  std::int64_t round_trip_ns_;
  LockstepStart start_;
  double master_f0_;
  double slave_f0_;
  control::VelocityEstimator master_velocity_;
  control::VelocityEstimator slave_velocity_;
  std::uint64_t master_session_;
  std::uint64_t slave_session_;
  // Opened last: nothing is written when the rows or the setup are unusable.
  record::McapWriter writer_;
  std::map<const google::protobuf::Descriptor*, std::uint16_t> schemas_{};
  std::uint16_t config_ch_{0};
  std::uint16_t report_ch_{0};
  std::uint16_t master_ch_{0};
  std::uint16_t slave_ch_{0};
};

void write_session_mcap(const std::string& path, const config::LoadedConfig& cfg,
                        const scene::SceneSetup& setup, const scene::SimulationResult& r) {
  SessionFile file(path, setup, r);
  file.write_start(cfg);
  file.write_telemetry();
  file.close();
}

void write_plot(const std::string& path, const scene::SimulationResult& r) {
  const std::size_t n = r.columns.size();
  Chart chart;
  chart.title = r.summary.kind == "bilateral" ? "Positions (mm) and forces (N)"
                                              : "Positions (mm) and forces (N), force device";
  chart.x_label = "time (s)";
  chart.y_label = "mm / N";
  const char* colours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e"};
  // Positions in millimetres, forces in newtons, on one axis.
  std::vector<std::size_t> picks;
  for (std::size_t i = 1; i < n; ++i) {
    const std::string& c = r.columns[i];
    const bool sensed = c.find("sensed") != std::string::npos;
    const bool internal = c.find("average") != std::string::npos || c == "master_force_N" ||
                          c == "slave_force_N" || c == "actuator_force_N";
    if (!sensed && !internal) picks.push_back(i);
  }
  const std::size_t stride = std::max<std::size_t>(1, r.rows.size() / n / 2000);
  for (std::size_t p = 0; p < picks.size(); ++p) {
    const std::size_t col = picks[p];
    const bool position = r.columns[col].ends_with("_m");
    Series s{position ? r.columns[col] + " (mm)" : r.columns[col], {}, colours[p % 5], true};
    for (std::size_t row = 0; row * n < r.rows.size(); row += stride) {
      const double v = r.rows[row * n + col];
      s.points.emplace_back(r.rows[row * n], position ? 1e3 * v : v);
    }
    chart.series.push_back(std::move(s));
  }
  std::ofstream f(path);
  f << render_svg(chart);
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
}

}  // namespace

std::string simulate_usage() {
  return "usage: teleopctl simulate SCENE [--duration S] [--seed N] [--set PATH=VALUE]...\n"
         "                          [--out FILE.csv|FILE.mcap] [--plot FILE.svg] [--json]\n\n"
         "--out FILE.csv writes the time series (SI units, named columns); --out FILE.mcap a\n"
         "session file as teleop-supervisor records a live run (/config, /master/telemetry and\n"
         "/slave/telemetry with every cycle, /supervisor/stability), for 'teleopctl replay'.\n";
}

SimulateOptions parse_simulate_args(const std::vector<std::string>& args) {
  SimulateOptions o;
  parse_file_command_args(args, {o.scene_path, o.overrides, o.json}, [&](ArgCursor& c) {
    const std::string& a = c.arg();
    auto value = [&](const char* flag) -> const std::string& { return c.value(flag); };
    if (a == "--duration") {
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
    } else if (a == "--out") {
      o.out_path = value("--out");
    } else if (a == "--plot") {
      o.plot_path = value("--plot");
    } else {
      return false;
    }
    return true;
  });
  if (o.scene_path.empty()) throw UsageError("missing SCENE");
  return o;
}

int run_simulate(const SimulateOptions& o, std::ostream& out, std::ostream& err) {
  return run_guarded("simulate", err, [&] {
    std::vector<std::string> sets = o.overrides;
    if (o.duration_s) sets.push_back(fmt::format("scene.duration_s={}", *o.duration_s));
    if (o.seed) sets.push_back(fmt::format("scene.seed={}", *o.seed));
    const config::LoadedConfig cfg = config::load_config_file(o.scene_path, sets);
    const scene::SceneSetup setup = config::to_scene_setup(cfg);
    const scene::SimulationResult r = scene::simulate(setup);
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
        write_session_mcap(*o.out_path, cfg, full, scene::simulate(full));
      } else {
        write_session_mcap(*o.out_path, cfg, setup, r);
      }
    } else if (o.out_path) {
      write_csv(*o.out_path, r);
    }
    if (o.plot_path) write_plot(*o.plot_path, r);
    if (s.fault) return 5;
    return s.oscillation.detected || s.master_oscillation.detected ? 3 : 0;
  });
}

}  // namespace teleop::ctl
