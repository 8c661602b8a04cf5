#include "supervisor/teleopctl/simulate_command.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <ostream>

#include "common/config/scene_loader.hpp"
#include "common/scene/lockstep.hpp"
#include "common/stability/analyzer.hpp"
#include "supervisor/teleopctl/analyze_command.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"

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
         "                          [--out FILE.csv] [--plot FILE.svg] [--json]\n";
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
    } else if (a.rfind("--set=", 0) == 0) {
      o.overrides.push_back(a.substr(6));
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
    } else if (a == "--out") {
      o.out_path = value("--out");
    } else if (a == "--plot") {
      o.plot_path = value("--plot");
    } else if (!a.empty() && a[0] == '-') {
      throw UsageError(fmt::format("unknown option '{}'", a));
    } else if (o.scene_path.empty()) {
      o.scene_path = a;
    } else {
      throw UsageError(fmt::format("unexpected argument '{}'", a));
    }
  }
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
    if (o.out_path) write_csv(*o.out_path, r);
    if (o.plot_path) write_plot(*o.plot_path, r);
    if (s.fault) return 5;
    return s.oscillation.detected || s.master_oscillation.detected ? 3 : 0;
  });
}

}  // namespace teleop::ctl
