#include "supervisor/teleopctl/analyze_command.hpp"

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <ostream>

#include "common/config/axes_config.hpp"
#include "common/config/config_loader.hpp"
#include "common/stability/analyzer.hpp"
#include "common/stability/force_loop.hpp"
#include "supervisor/teleopctl/analyze_plots.hpp"
#include "supervisor/teleopctl/axes_commands.hpp"
#include "supervisor/teleopctl/json_output.hpp"
#include "supervisor/teleopctl/progress_line.hpp"
#include "supervisor/teleopctl/svg_plot.hpp"

namespace teleop::ctl {

namespace {

using nlohmann::json;
using stability::Side;

std::string fmt_opt(const std::optional<double>& v, const char* unit) {
  return v ? fmt::format("{:.6g} {}", *v, unit) : std::string("none");
}

std::string human_text(const std::optional<stability::HumanSample>& h, HumanKind kind) {
  if (!h) {
    return kind == HumanKind::kNone ? "none configured"
                                    : "n/a (the human does not enter this loop)";
  }
  std::string s =
      fmt::format("m_h = {:.4g} kg, b_h = {:.4g} Ns/m, k_h = {:.4g} N/m", h->impedance.mass_kg,
                  h->impedance.damping_Ns_per_m, h->impedance.stiffness_N_per_m);
  if (h->has_force) s += fmt::format(" at grip force {:.4g} N", h->force_N);
  return s;
}

// The loaded configuration with extra assignments applied, as engine parameters.
TeleopParams params_with(const config::LoadedConfig& base, const std::vector<std::string>& sets) {
  config::LoadedConfig c = base;
  for (const std::string& s : sets) config::apply_override(c, s);
  return config::to_teleop_params(c);
}

std::string number_text(double v) { return fmt::format("{}", v); }

int run_force_loop(const config::LoadedConfig& cfg, const AnalyzeOptions& o, std::ostream& out) {
  const ForceLoopParams p = config::to_force_loop_params(cfg);
  const stability::ForceLoopResult r = stability::analyze_force_loop(p);
  if (o.json) {
    out << force_loop_json(r, p).dump(2) << "\n";
  } else {
    out << fmt::format("force loop ({} controller, T = {:.6g} s, M = {:.4g} kg, B = {:.4g} Ns/m)\n",
                       r.proportional_integral ? "PI" : "P", 1.0 / p.sample_rate_hz, p.mass_kg,
                       p.damping_Ns_per_m);
    out << fmt::format("  B_v limit, eq. 14 (any K_v):           {}\n",
                       fmt_opt(r.bv_limit_eq14_Ns_per_m, "Ns/m"));
    out << fmt::format("  B_v limit at the configured K_v:       {}\n",
                       fmt_opt(r.bv_limit_Ns_per_m, "Ns/m"));
    out << fmt::format("  K_v limit at the configured B_v{}: {}\n",
                       r.proportional_integral ? " (R-H)" : " (eq. 15)",
                       fmt_opt(r.kv_limit_N_per_m, "N/m"));
    if (!r.limit_reason.empty()) out << "  note: " << r.limit_reason << "\n";
    out << fmt::format("  environment K_v = {:.6g} N/m, B_v = {:.6g} Ns/m: {}\n",
                       p.environment_stiffness_N_per_m, p.environment_damping_Ns_per_m,
                       stability::to_string(r.verdict));
    out << "  closed-loop roots (s):";
    for (const auto& root : r.roots)
      out << fmt::format(" {:.6g}{:+.6g}i", root.real(), root.imag());
    out << "\n";
  }
  if (r.verdict == stability::Verdict::kInvalid) return kExitError;
  if (r.verdict == stability::Verdict::kUnstable) return kExitUnstable;
  if (r.verdict == stability::Verdict::kUncertain) return kExitUncertain;
  return kExitStable;
}

}  // namespace

LimitsDocument limits_document(const config::LoadedConfig& cfg, Side side,
                               const std::vector<double>& rates_hz,
                               const std::optional<Sweep>& sweep,
                               const std::function<void(std::size_t, std::size_t)>& progress) {
  const char* side_name = side == Side::kMaster ? "master" : "slave";
  const TeleopParams base = config::to_teleop_params(cfg);
  std::vector<double> rates = rates_hz;
  if (rates.empty()) rates.push_back(base.sample_rate_hz);
  std::vector<std::optional<double>> sweep_values{std::nullopt};
  if (sweep) {
    sweep_values.clear();
    for (const double v : sweep->values()) sweep_values.emplace_back(v);
  }

  LimitsDocument d;
  json limits = json::array();
  const std::size_t points = sweep_values.size() * rates.size();
  std::size_t done = 0;
  for (const auto& sv : sweep_values) {
    for (const double rate : rates) {
      std::vector<std::string> sets{"sample_rate_hz=" + number_text(rate)};
      if (sv) sets.push_back(sweep->path + "=" + number_text(*sv));
      const TeleopParams p = params_with(cfg, sets);
      const stability::StiffnessLimit l = stability::max_stable_stiffness(p, side);
      d.any_invalid = d.any_invalid || l.invalid;
      json j = limit_json(l, side, rate);
      if (sv) j[sweep->path] = *sv;
      limits.push_back(j);
      if (progress) progress(++done, points);
    }
  }
  d.document = json{{"side", side_name},
                    {"swept", sweep ? json(sweep->path) : json(nullptr)},
                    {"required_damping_ratio", base.analysis.required_damping_ratio},
                    {"stiffness_tolerance_N_per_m", base.analysis.stiffness_tolerance_N_per_m},
                    {"limits", limits}};
  return d;
}

namespace {

int run_limits(const config::LoadedConfig& cfg, const AnalyzeOptions& o, std::ostream& out,
               std::ostream& err) {
  const Side side = *o.max_stiffness_side;
  const char* side_name = side == Side::kMaster ? "master" : "slave";
  const TeleopParams base = config::to_teleop_params(cfg);
  // A big sweep takes seconds: its progress on a terminal.
  ProgressLine progress(err, "analyze --max-stiffness", !o.json && stderr_is_terminal());
  const LimitsDocument d =
      limits_document(cfg, side, o.rates_hz, o.sweep,
                      [&](std::size_t done, std::size_t points) { progress.update(done, points); });
  const json& limits = d.document["limits"];
  const bool any_invalid = d.any_invalid;

  if (o.json) {
    out << d.document.dump(2) << "\n";
  } else {
    out << fmt::format(
        "maximum stable {} fixture stiffness (required damping ratio {:g}, tolerance {:g} N/m, "
        "{} fixture held at {:g} N/m)\n",
        side_name, base.analysis.required_damping_ratio, base.analysis.stiffness_tolerance_N_per_m,
        side == Side::kMaster ? "slave" : "master",
        side == Side::kMaster ? base.slave_fixture.stiffness_N_per_m
                              : base.master_fixture.stiffness_N_per_m);
    for (const json& j : limits) {
      std::string row = fmt::format("  {:>8g} Hz", j["sample_rate_hz"].get<double>());
      if (o.sweep)
        row += fmt::format("  {} = {:<8g}", o.sweep->path, j[o.sweep->path].get<double>());
      const json& k = j["max_stable_stiffness_N_per_m"];
      row += k.is_null() ? std::string("  none") : fmt::format("  {:>12.6g} N/m", k.get<double>());
      if (j.contains("passivity_limit_N_per_m")) {
        row += j["passivity_limit_N_per_m"].is_null()
                   ? std::string("  (not passive at any stiffness)")
                   : fmt::format("  (passivity bound {:.6g} N/m)",
                                 j["passivity_limit_N_per_m"].get<double>());
      }
      if (j.contains("reason")) row += "  — " + j["reason"].get<std::string>();
      out << row << "\n";
    }
  }
  if (o.plot_path) {
    LimitsPlot plot{side_name, o.sweep ? o.sweep->path : std::string(), o.rates_hz.size() <= 1,
                    limits};
    plot.subtitle = fmt::format(
        "worst case over the human model; required damping ratio {:g}; {} fixture held at "
        "{:g} N/m",
        base.analysis.required_damping_ratio, side == Side::kMaster ? "slave" : "master",
        side == Side::kMaster ? base.slave_fixture.stiffness_N_per_m
                              : base.master_fixture.stiffness_N_per_m);
    write_svg(*o.plot_path, limits_chart(plot));
  }
  return any_invalid ? kExitError : kExitStable;
}

int run_single(const config::LoadedConfig& cfg, const AnalyzeOptions& o, std::ostream& out) {
  const TeleopParams p = config::to_teleop_params(cfg);
  const stability::AnalysisResult r = stability::analyze(p);
  if (o.json) {
    out << analysis_json(r, p).dump(2) << "\n";
  } else {
    out << fmt::format("{}: {}\n", cfg.source_name, stability::to_string(r.verdict));
    if (r.verdict == stability::Verdict::kInvalid) {
      out << "  the model cannot be analysed: " << r.invalid_reason << "\n";
    }
    out << fmt::format(
        "  loop: {} at {:g} Hz, round trip {} samples, fixtures master {:g} N/m, "
        "slave {:g} N/m\n",
        stability::to_string(r.structure), p.sample_rate_hz, p.round_trip_delay_samples,
        p.master_fixture.stiffness_N_per_m, p.slave_fixture.stiffness_N_per_m);
    out << fmt::format("  spectral radius {:.6f}, minimum damping ratio {:.4f} (required {:g})\n",
                       r.spectral_radius, r.min_damping_ratio, p.analysis.required_damping_ratio);
    out << fmt::format("  worst human ({} evaluated): {}\n", r.humans_evaluated,
                       human_text(r.worst_human, p.human.kind));
    out << "  eigenvalues of the worst case:\n";
    out << "            z                          |z|         s (rad/s)                    zeta\n";
    for (const stability::Mode& m : r.spectrum.modes) {
      if (m.structural) {
        out << "    0 (structural: held input or unused controller memory)\n";
        continue;
      }
      out << fmt::format("    {:+.6f} {:+.6f}i   {:.6f}   {:+11.2f} {:+11.2f}i   {:+.4f}\n",
                         m.z.real(), m.z.imag(), std::abs(m.z), m.s.real(), m.s.imag(),
                         m.damping_ratio);
    }
  }
  if (o.plot_path) write_svg(*o.plot_path, z_plane_chart(p, r));
  return verdict_exit_code(r.verdict);
}

}  // namespace

int verdict_exit_code(stability::Verdict v) {
  switch (v) {
    case stability::Verdict::kStable:
      return kExitStable;
    case stability::Verdict::kUnstable:
      return kExitUnstable;
    case stability::Verdict::kUncertain:
      return kExitUncertain;
    case stability::Verdict::kInvalid:
      return kExitError;
  }
  return kExitError;
}

Sweep parse_sweep(const std::string& spec) {
  const std::size_t eq = spec.find('=');
  if (eq == std::string::npos || eq == 0) {
    throw UsageError(fmt::format("--sweep '{}': expected PATH=FROM:TO:STEP", spec));
  }
  const std::vector<std::string> range = split(spec.substr(eq + 1), ':');
  if (range.size() != 3) {
    throw UsageError(fmt::format("--sweep '{}': expected PATH=FROM:TO:STEP", spec));
  }
  Sweep s{spec.substr(0, eq), parse_number(range[0], "--sweep FROM"),
          parse_number(range[1], "--sweep TO"), parse_number(range[2], "--sweep STEP")};
  if (s.step <= 0.0 || s.to < s.from) {
    throw UsageError(fmt::format("--sweep '{}': need STEP > 0 and TO >= FROM", spec));
  }
  if ((s.to - s.from) / s.step > 10000.0) {
    throw UsageError(fmt::format("--sweep '{}': more than 10000 points", spec));
  }
  return s;
}

nlohmann::json analysis_document(const config::LoadedConfig& cfg) {
  const TeleopParams p = config::to_teleop_params(cfg);
  return analysis_json(stability::analyze(p), p);
}

nlohmann::json force_loop_document(const config::LoadedConfig& cfg) {
  const ForceLoopParams p = config::to_force_loop_params(cfg);
  return force_loop_json(stability::analyze_force_loop(p), p);
}

std::vector<double> Sweep::values() const {
  std::vector<double> v;
  const auto count = static_cast<long>(std::floor((to - from) / step + 1e-9));
  for (long i = 0; i <= count; ++i) v.push_back(from + static_cast<double>(i) * step);
  return v;
}

std::string analyze_usage() {
  return "usage: teleopctl analyze CONFIG [--set PATH=VALUE]... [--json] [--plot FILE.svg]\n"
         "       teleopctl analyze CONFIG --max-stiffness slave|master [--rates R1,R2,...]\n"
         "                         [--sweep PATH=FROM:TO:STEP] [--json] [--plot FILE.svg]\n"
         "       teleopctl analyze CONFIG --force-loop [--json]\n";
}

AnalyzeOptions parse_analyze_args(const std::vector<std::string>& args) {
  AnalyzeOptions o;
  parse_file_command_args(args, {o.config_path, o.overrides, o.json}, [&](ArgCursor& c) {
    const std::string& a = c.arg();
    auto value = [&](const char* flag) -> const std::string& { return c.value(flag); };
    if (a == "--max-stiffness") {
      const std::string& side = value("--max-stiffness");
      if (side == "slave") {
        o.max_stiffness_side = Side::kSlave;
      } else if (side == "master") {
        o.max_stiffness_side = Side::kMaster;
      } else {
        throw UsageError(fmt::format("--max-stiffness takes 'slave' or 'master', not '{}'", side));
      }
    } else if (a == "--rates") {
      for (const std::string& r : split(value("--rates"), ',')) {
        const double hz = parse_number(r, "--rates");
        if (!(hz > 0.0)) throw UsageError(fmt::format("--rates: {} Hz is not positive", r));
        o.rates_hz.push_back(hz);
      }
    } else if (a == "--sweep") {
      o.sweep = parse_sweep(value("--sweep"));
    } else if (a == "--force-loop") {
      o.force_loop = true;
    } else if (a == "--plot") {
      o.plot_path = svg_plot_path(value("--plot"));
    } else {
      return false;
    }
    return true;
  });
  if (o.config_path.empty()) throw UsageError("missing CONFIG");
  if (o.force_loop && o.max_stiffness_side) {
    throw UsageError("--force-loop and --max-stiffness are separate analyses: give one");
  }
  if (o.force_loop && o.plot_path) {
    throw UsageError("--force-loop has no plot: its roots are printed (--json for all of them)");
  }
  if (!o.max_stiffness_side && (!o.rates_hz.empty() || o.sweep)) {
    throw UsageError("--rates and --sweep go with --max-stiffness");
  }
  return o;
}

int run_analyze(const AnalyzeOptions& o, std::ostream& out, std::ostream& err) {
  return run_guarded("analyze", err, [&] {
    // Parsed with the overrides; the typed builder each analysis calls (to_teleop_params,
    // to_force_loop_params) validates it, once.
    const config::LoadedConfig cfg = config::parse_config_file(o.config_path, o.overrides);
    if (o.force_loop) return run_force_loop(cfg, o, out);
    // Several task-space axes: the n-axis analysis (axes_commands.cpp).
    if (config::configured_axes(cfg.config) > 1) return run_analyze_axes(cfg, o, out, err);
    if (cfg.config.has_force_loop() && !cfg.config.has_gains()) {
      // A force-loop file analysed as a teleoperator: say which analysis it is for.
      err << "teleopctl analyze: " << cfg.source_name
          << " describes a force loop (force_loop) and no teleoperator (no gains): analyse it "
             "with 'teleopctl analyze "
          << o.config_path << " --force-loop'\n";
      return kExitError;
    }
    if (o.max_stiffness_side) return run_limits(cfg, o, out, err);
    return run_single(cfg, o, out);
  });
}

}  // namespace teleop::ctl
