#include "supervisor/teleopctl/axes_commands.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <string>
#include <vector>

#include "common/config/axes_config.hpp"
#include "common/config/axes_scene_loader.hpp"
#include "supervisor/core/session_output.hpp"
#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/json_output.hpp"
#include "supervisor/teleopctl/progress_line.hpp"
#include "supervisor/teleopctl/session_file.hpp"
#include "supervisor/teleopctl/simulate_session_axes.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"

namespace teleop::ctl {

namespace {

using nlohmann::json;
using stability::Side;

const char* side_name(Side side) { return side == Side::kMaster ? "master" : "slave"; }

json vector_json(const Eigen::VectorXd& v) {
  json a = json::array();
  for (Eigen::Index i = 0; i < v.size(); ++i) a.push_back(v(i));
  return a;
}

std::string vector_text(const Eigen::VectorXd& v) {
  std::string s = "[";
  for (Eigen::Index i = 0; i < v.size(); ++i) s += fmt::format("{}{:.4g}", i ? ", " : "", v(i));
  return s + "]";
}

json humans_json(const std::vector<stability::HumanSample>& humans) {
  if (humans.empty()) return nullptr;
  json a = json::array();
  for (const stability::HumanSample& h : humans) a.push_back(human_json(h));
  return a;
}

std::string human_text(const stability::HumanSample& h) {
  std::string s =
      fmt::format("m_h = {:.4g} kg, b_h = {:.4g} Ns/m, k_h = {:.4g} N/m", h.impedance.mass_kg,
                  h.impedance.damping_Ns_per_m, h.impedance.stiffness_N_per_m);
  if (h.has_force) s += fmt::format(" at grip force {:.4g} N", h.force_N);
  return s;
}

// The humans to report, one per axis: the analysis's, except that a fixed human is reported as
// configured (the diagonals of its matrices: analyze_axes keeps the fixed human's matrices and,
// analysing a coupled loop whole, reports a placeholder sample per axis).
std::vector<stability::HumanSample> reported(const std::vector<stability::HumanSample>& humans,
                                             const TeleopAxesParams& p) {
  if (humans.empty() || p.human.kind != HumanKind::kFixed) return humans;
  std::vector<stability::HumanSample> out(humans.size());
  for (std::size_t i = 0; i < out.size(); ++i) {
    const auto j = static_cast<Eigen::Index>(i);
    out[i].impedance = {p.human.fixed.mass_kg(j, j), p.human.fixed.damping_Ns_per_m(j, j),
                        p.human.fixed.stiffness_N_per_m(j, j)};
  }
  return out;
}

const PlaneFixtureParams& plane_of(const TeleopAxesParams& p, const stability::PlaneLimit& l) {
  return l.side == Side::kMaster ? p.master_planes[l.plane] : p.slave_planes[l.plane];
}

json plane_json(const stability::PlaneLimit& l, const TeleopAxesParams& p, bool limiting) {
  const PlaneFixtureParams& plane = plane_of(p, l);
  const auto opt = [](const std::optional<double>& v) { return v ? json(*v) : json(nullptr); };
  json j = {{"side", side_name(l.side)},
            {"index", l.plane},
            {"normal", vector_json(plane.normal)},
            {"offset_m", plane.offset_m},
            {"stiffness_N_per_m", plane.stiffness_N_per_m},
            {"max_stable_stiffness_N_per_m", opt(l.max_stable_stiffness_N_per_m)},
            {"limit_crossing_N_per_m", opt(l.limit_crossing_N_per_m)},
            {"worst_human", humans_json(reported(l.worst_human, p))},
            {"humans_evaluated", l.humans_evaluated},
            {"limiting", limiting}};
  if (!l.reason.empty()) j["reason"] = l.reason;
  if (l.invalid) j["invalid"] = true;
  if (l.uncertain) j["uncertain"] = true;
  return j;
}

// --- analyze ---------------------------------------------------------------------------------

void check_analyze_options(const AnalyzeOptions& o, int n) {
  const std::string axes = fmt::format("axes: {}", n);
  if (o.max_stiffness_side) {
    throw UsageError(fmt::format(
        "--max-stiffness is the one-axis fixture's limit; with {} the analysis gives every "
        "plane's limit (teleopctl analyze {})",
        axes, o.config_path));
  }
  if (!o.rates_hz.empty() || o.sweep) {
    throw UsageError(
        fmt::format("--rates and --sweep are not available with {} (one axis only)", axes));
  }
  if (o.plot_path) {
    throw UsageError(fmt::format("--plot is not available with {} (one axis only so far)", axes));
  }
}

void print_planes(const stability::AxesAnalysis& r, const TeleopAxesParams& p, std::ostream& out) {
  if (r.plane_limits.empty()) {
    out << "  no stiff plane: no plane limit\n";
    return;
  }
  out << "  plane stiffness limits (the other planes held at their stiffness):\n";
  for (std::size_t i = 0; i < r.plane_limits.size(); ++i) {
    const stability::PlaneLimit& l = r.plane_limits[i];
    const PlaneFixtureParams& plane = plane_of(p, l);
    const std::string limit = l.max_stable_stiffness_N_per_m
                                  ? fmt::format("{:.6g} N/m", *l.max_stable_stiffness_N_per_m)
                                  : std::string("none");
    out << fmt::format("    {} plane {} (normal {}, offset {:g} m): {:g} N/m, limit {}{}\n",
                       side_name(l.side), l.plane, vector_text(plane.normal), plane.offset_m,
                       plane.stiffness_N_per_m, limit,
                       r.limiting_plane && *r.limiting_plane == i ? "  <- limiting" : "");
    if (!l.reason.empty()) out << "      " << l.reason << "\n";
  }
}

void print_analysis(const config::LoadedConfig& cfg, const stability::AxesAnalysis& r,
                    const TeleopAxesParams& p, std::ostream& out) {
  out << fmt::format("{}: {} ({} axes)\n", cfg.source_name, stability::to_string(r.verdict),
                     p.axes);
  if (r.verdict == stability::Verdict::kInvalid) {
    out << "  the model cannot be analysed: " << r.invalid_reason << "\n";
  }
  out << fmt::format(
      "  loop: {} at {:g} Hz, round trip {} samples, {} master and {} slave planes; analysed "
      "{}\n",
      stability::to_string(r.structure), p.sample_rate_hz, p.round_trip_delay_samples,
      p.master_planes.size(), p.slave_planes.size(),
      r.decoupled ? "axis by axis (the axes decouple)" : "whole (the axes couple)");
  out << fmt::format(
      "  spectral radius {:.6f} (margin {:.6f}), minimum damping ratio {:.4f} (required {:g})\n",
      r.spectral_radius, r.stability_margin, r.min_damping_ratio,
      p.analysis.required_damping_ratio);
  out << fmt::format("  humans evaluated: {}, band search {}\n", r.humans_evaluated,
                     r.band_exhaustive ? "exhaustive" : "not exhaustive (grids walked, refined)");
  const std::vector<stability::HumanSample> worst = reported(r.worst_human, p);
  if (worst.empty()) {
    out << "  worst human: "
        << (p.human.kind == HumanKind::kNone ? "none configured"
                                             : "n/a (the human does not enter this loop)")
        << "\n";
  } else {
    out << (p.human.kind == HumanKind::kFixed ? "  the fixed human, per axis:\n"
                                              : "  worst human per axis:\n");
    for (std::size_t i = 0; i < worst.size(); ++i) {
      out << fmt::format("    axis {}: {}\n", i, human_text(worst[i]));
    }
  }
  print_planes(r, p, out);
}

// --- simulate ---------------------------------------------------------------------------------

void check_simulate_options(const SimulateOptions& o, int n) {
  const std::string axes = fmt::format("axes: {}", n);
  if (o.seed) {
    throw UsageError(
        fmt::format("--seed: the {} simulator has ideal sensors and no random source", axes));
  }
}

json oscillation_json(const scene::Oscillation& o, int axis) {
  return {{"detected", o.detected},
          {"amplitude_m", o.amplitude_m},
          {"frequency_hz", o.frequency_hz},
          {"previous_amplitude_m", o.previous_amplitude_m},
          {"axis", axis}};
}

// The last row's value of every column named `name[i]`.
json last_row_json(const scene::AxesSimulationResult& r, const std::string& name, int n) {
  const std::size_t columns = r.columns.size();
  json a = json::array();
  if (columns == 0 || r.rows.size() < columns) return a;
  const std::size_t last = r.rows.size() - columns;
  for (int i = 0; i < n; ++i) {
    const std::string column = fmt::format("{}[{}]", name, i);
    for (std::size_t c = 0; c < columns; ++c) {
      if (r.columns[c] == column) a.push_back(r.rows[last + c]);
    }
  }
  return a;
}

json simulation_json(const config::LoadedConfig& cfg, const scene::AxesSceneSetup& setup,
                     const scene::AxesSimulationResult& r) {
  const scene::AxesSimulationSummary& s = r.summary;
  const int n = s.axes;
  json j = {
      {"scene", cfg.source_name},
      {"kind", "bilateral"},
      {"axes", n},
      {"duration_s", s.duration_s},
      {"steps", s.steps},
      {"ideal", true},
      {"max_penetration_master_m", s.max_penetration_master_m},
      {"max_penetration_slave_m", s.max_penetration_slave_m},
      {"tracking_error_rms_m", s.tracking_error_rms_m},
      {"force_error_rms_N", s.force_error_rms_N},
      {"oscillation", oscillation_json(s.oscillation, s.oscillation_axis)},
      {"master_oscillation", oscillation_json(s.master_oscillation, s.master_oscillation_axis)},
      {"fault", s.fault},
      {"wall_time_s", s.wall_time_s},
      {"real_time_factor", s.real_time_factor},
      {"push_direction", vector_json(setup.push_direction.normalized())},
      {"final",
       {{"time_s", r.rows.size() >= r.columns.size() && !r.columns.empty()
                       ? r.rows[r.rows.size() - r.columns.size()]
                       : 0.0},
        {"master_position_m", last_row_json(r, "master_position_m", n)},
        {"slave_position_m", last_row_json(r, "slave_position_m", n)}}}};
  if (s.equilibrium) {
    j["equilibrium"] = {{"master_m", vector_json(s.equilibrium->master_m)},
                        {"slave_m", vector_json(s.equilibrium->slave_m)}};
  }
  // What the analyser predicts for this loop with its planes engaged.
  const stability::AxesAnalysis a = stability::analyze_axes(setup.teleop);
  j["predicted"] = {{"verdict", stability::to_string(a.verdict)},
                    {"min_damping_ratio", a.min_damping_ratio},
                    {"spectral_radius", a.spectral_radius}};
  return j;
}

void write_csv(const std::string& path, const scene::AxesSimulationResult& r) {
  std::ofstream f(path);
  const std::size_t n = r.columns.size();
  for (std::size_t i = 0; i < n; ++i) f << (i ? "," : "") << r.columns[i];
  f << "\n";
  for (std::size_t row = 0; n > 0 && row * n < r.rows.size(); ++row) {
    for (std::size_t i = 0; i < n; ++i)
      f << (i ? "," : "") << fmt::format("{}", r.rows[row * n + i]);
    f << "\n";
  }
  if (!f) throw std::runtime_error(fmt::format("cannot write '{}'", path));
}

// Positions (mm) above forces (N), every axis: the master solid, the slave dashed, the hand's
// force solid and the slave environment's dashed, one colour per axis.
void write_plot(const std::string& path, const std::string& scene_name,
                const scene::AxesSimulationResult& r) {
  const std::size_t columns = r.columns.size();
  const std::size_t rows = columns ? r.rows.size() / columns : 0;
  Chart chart = position_force_chart(
      fmt::format("{}-axis teleoperator, simulated: positions and forces", r.summary.axes),
      fmt::format("teleopctl simulate {}, {:g} s",
                  std::filesystem::path(scene_name).filename().string(), r.summary.duration_s));
  const std::size_t stride = plot_stride(rows);
  for (std::size_t c = 1; c < columns; ++c) {
    const std::string& name = r.columns[c];
    const bool position = name.starts_with("master_position") || name.starts_with("slave_position");
    const bool force = name.starts_with("human_force") || name.starts_with("environment_force");
    if (!position && !force) continue;
    const std::size_t open = name.find('[');
    const std::size_t axis = std::stoul(name.substr(open + 1));
    std::string label = name.substr(0, name.rfind('_', open));
    for (char& ch : label) ch = ch == '_' ? ' ' : ch;
    Series s{fmt::format("{} [{}]", label, axis), {}, line_colour(axis), true};
    s.dashed = name.starts_with("slave") || name.starts_with("environment");
    for (std::size_t row = 0; row < rows; row += stride) {
      const double v = r.rows[row * columns + c];
      s.points.emplace_back(r.rows[row * columns], position ? 1e3 * v : v);
    }
    chart.panels[position ? 0 : 1].series.push_back(std::move(s));
  }
  write_svg(path, chart);
}

void print_simulation(const config::LoadedConfig& cfg, const scene::AxesSimulationSummary& s,
                      const json& j, std::ostream& out) {
  out << fmt::format(
      "{}: bilateral scene, {} axes, {:g} s simulated in {:.3f} s ({:.0f}x real "
      "time)\n",
      cfg.source_name, s.axes, s.duration_s, s.wall_time_s, s.real_time_factor);
  out << fmt::format(
      "  oscillation: slave {} (axis {}, amplitude {:.3g} m at {:.3g} Hz), master "
      "{} (axis {}, amplitude {:.3g} m)\n",
      s.oscillation.detected ? "SUSTAINED" : "none", s.oscillation_axis, s.oscillation.amplitude_m,
      s.oscillation.frequency_hz, s.master_oscillation.detected ? "SUSTAINED" : "none",
      s.master_oscillation_axis, s.master_oscillation.amplitude_m);
  out << fmt::format("  analyser predicts: {} (minimum damping ratio {:.4f})\n",
                     j["predicted"]["verdict"].get<std::string>(),
                     j["predicted"]["min_damping_ratio"].get<double>());
  out << fmt::format("  max penetration: master {:.4g} m, slave {:.4g} m\n",
                     s.max_penetration_master_m, s.max_penetration_slave_m);
  out << fmt::format("  final positions (m): master {}, slave {}\n",
                     j["final"]["master_position_m"].dump(), j["final"]["slave_position_m"].dump());
  out << fmt::format("  tracking error rms {:.4g} m; force error rms {:.4g} N\n",
                     s.tracking_error_rms_m, s.force_error_rms_N);
  if (s.fault) out << "  a control law latched a fault\n";
}

}  // namespace

json axes_analysis_json(const stability::AxesAnalysis& r, const TeleopAxesParams& p) {
  json modes = json::array();
  for (const stability::Mode& m : r.spectrum.modes) modes.push_back(mode_json(m));
  json planes = json::array();
  for (std::size_t i = 0; i < r.plane_limits.size(); ++i) {
    const stability::PlaneLimit& l = r.plane_limits[i];
    planes.push_back(plane_json(l, p, r.limiting_plane && *r.limiting_plane == i));
  }
  json limiting = nullptr;
  if (r.limiting_plane) {
    const stability::PlaneLimit& l = r.plane_limits[*r.limiting_plane];
    limiting = {{"side", side_name(l.side)}, {"index", l.plane}};
  }
  return {{"verdict", stability::to_string(r.verdict)},
          {"invalid_reason", r.invalid_reason.empty() ? json(nullptr) : json(r.invalid_reason)},
          {"stable", r.verdict == stability::Verdict::kStable},
          {"axes", p.axes},
          {"spectral_radius", r.spectral_radius},
          {"stability_margin", r.stability_margin},
          {"min_damping_ratio", r.min_damping_ratio},
          {"required_damping_ratio", p.analysis.required_damping_ratio},
          {"meets_required_damping_ratio",
           r.verdict == stability::Verdict::kStable &&
               r.min_damping_ratio >= p.analysis.required_damping_ratio},
          {"worst_human", humans_json(reported(r.worst_human, p))},
          {"spectral_radius_human", humans_json(reported(r.radius_human, p))},
          {"structure", stability::to_string(r.structure)},
          {"decoupled", r.decoupled},
          {"humans_evaluated", r.humans_evaluated},
          {"band_exhaustive", r.band_exhaustive},
          {"sample_rate_hz", p.sample_rate_hz},
          {"round_trip_delay_samples", p.round_trip_delay_samples},
          {"planes", planes},
          {"limiting_plane", limiting},
          {"eigenvalues", modes}};
}

int run_analyze_axes(const config::LoadedConfig& cfg, const AnalyzeOptions& o, std::ostream& out,
                     std::ostream& err) {
  try {
    check_analyze_options(o, config::configured_axes(cfg.config));
  } catch (const UsageError& e) {
    err << "teleopctl analyze: " << e.what() << "\n" << analyze_usage();
    return kExitUsage;
  }
  const TeleopAxesParams p = config::to_axes_params(cfg);
  stability::AxesAnalysisOptions options;
  options.plane_limits = true;
  const stability::AxesAnalysis r = stability::analyze_axes(p, options);
  if (o.json) {
    out << axes_analysis_json(r, p).dump(2) << "\n";
  } else {
    print_analysis(cfg, r, p, out);
  }
  return verdict_exit_code(r.verdict);
}

int run_simulate_axes(const config::LoadedConfig& cfg, const SimulateOptions& o, std::ostream& out,
                      std::ostream& err) {
  try {
    check_simulate_options(o, config::configured_axes(cfg.config));
  } catch (const UsageError& e) {
    err << "teleopctl simulate: " << e.what() << "\n" << simulate_usage();
    return kExitUsage;
  }
  // A session file's log times start at the wall clock of the run (before simulating).
  const std::int64_t start_ns = o.log_start_ns ? *o.log_start_ns : supervisor::wall_clock_ns();
  const scene::AxesSceneSetup setup = config::to_axes_scene_setup(cfg);
  const bool session = o.out_path && is_mcap_path(*o.out_path);
  scene::AxesSimulationResult r;
  {
    ProgressLine progress(err, "simulate", !o.json && stderr_is_terminal());
    const scene::Progress update = [&](double f) { progress.update(f); };
    r = session ? simulate_axes_session(*o.out_path, cfg, setup, start_ns, update)
                : scene::simulate_axes(setup, update);
  }
  const scene::AxesSimulationSummary& s = r.summary;
  const json j = simulation_json(cfg, setup, r);
  if (o.json) {
    out << j.dump(2) << "\n";
  } else {
    print_simulation(cfg, s, j, out);
  }
  if (o.out_path && !session) write_csv(*o.out_path, r);
  if (o.plot_path) write_plot(*o.plot_path, cfg.source_name, r);
  if (s.fault) return 5;
  return s.oscillation.detected || s.master_oscillation.detected ? 3 : 0;
}

}  // namespace teleop::ctl
