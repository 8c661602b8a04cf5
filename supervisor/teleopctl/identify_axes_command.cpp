#include "supervisor/teleopctl/identify_axes_command.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <limits>
#include <nlohmann/json.hpp>
#include <ostream>
#include <stdexcept>
#include <utility>

#include "supervisor/teleopctl/cli_args.hpp"
#include "supervisor/teleopctl/csv_table.hpp"
#include "supervisor/teleopctl/identify_rules.hpp"

namespace teleop::ctl {

namespace {

using nlohmann::json;

// As the one-axis command: a fit explaining less of the force is not trusted, on the whole or on
// any axis; a motion over fewer steps of the position's resolution is refused (exit 4).
using identify_rules::kExitNotIdentified;
using identify_rules::kMinRangeSteps;
using identify_rules::kPoorFit;

[[nodiscard]] Eigen::MatrixXd matrix_of(const std::vector<std::vector<double>>& columns) {
  Eigen::MatrixXd m(static_cast<Eigen::Index>(columns.front().size()),
                    static_cast<Eigen::Index>(columns.size()));
  for (std::size_t j = 0; j < columns.size(); ++j) {
    for (std::size_t k = 0; k < columns[j].size(); ++k) {
      m(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(j)) = columns[j][k];
    }
  }
  return m;
}

[[nodiscard]] stability::SeriesAxes read_run(const IdentifyAxesArgs& a, const std::string& file) {
  const Csv csv = read_csv(file);
  std::vector<std::vector<double>> x;
  std::vector<std::vector<double>> f;
  std::vector<std::vector<double>> h;
  for (std::size_t i = 0; i < a.position.size(); ++i) {
    const std::string axis = fmt::format("axis {}", i);
    x.push_back(column(csv, file, a.position[i], ("position of " + axis).c_str()));
    f.push_back(evaluate(csv, file, a.force[i], ("force of " + axis).c_str()));
    if (!a.held_force.empty()) {
      h.push_back(evaluate(csv, file, a.held_force[i], ("held force of " + axis).c_str()));
    }
  }
  stability::SeriesAxes s;
  s.position_m = matrix_of(x);
  s.force_N = matrix_of(f);
  if (!h.empty()) s.held_force_N = matrix_of(h);
  if (a.rate_hz > 0.0) {
    s.period_s = 1.0 / a.rate_hz;
  } else {
    s.time_s = column(csv, file, a.time, "time (or give --rate)");
  }
  return s;
}

// identify_axes's errors name "run N": the file behind it too.
[[nodiscard]] stability::IdentifyAxesResult fit(const IdentifyAxesArgs& a,
                                                const std::vector<stability::SeriesAxes>& runs) {
  try {
    return stability::identify_axes(runs, a.options);
  } catch (const std::invalid_argument& e) {
    std::string message = e.what();
    for (std::size_t i = a.files.size(); i-- > 0;) {
      const std::string tag = fmt::format("run {}", i + 1);
      const std::size_t at = message.find(tag);
      if (at != std::string::npos) {
        message.replace(at, tag.size(), fmt::format("run {} ({})", i + 1, a.files[i]));
        break;
      }
    }
    throw std::runtime_error(message);
  }
}

// Each axis's motion over the runs (identify_rules.hpp).
using AxisMotion = identify_rules::Motion;

[[nodiscard]] std::vector<AxisMotion> motion(const std::vector<stability::SeriesAxes>& runs) {
  const Eigen::Index n = runs.front().position_m.cols();
  std::vector<AxisMotion> out;
  for (Eigen::Index i = 0; i < n; ++i) {
    std::vector<std::vector<double>> positions;
    for (const stability::SeriesAxes& s : runs) {
      positions.emplace_back(s.position_m.col(i).begin(), s.position_m.col(i).end());
    }
    out.push_back(identify_rules::motion_of(positions));
  }
  return out;
}

struct Verdict {
  std::vector<std::string> refused{};  // too little excitation: exit 4
  std::string unphysical{};            // no device has these parameters: exit 1
  [[nodiscard]] bool identified() const { return refused.empty() && unphysical.empty(); }
};

[[nodiscard]] Verdict judge(const stability::IdentifyAxesResult& r,
                            const std::vector<AxisMotion>& m) {
  Verdict v;
  for (std::size_t i = 0; i < m.size(); ++i) {
    if (m[i].quantised() && m[i].steps() < kMinRangeSteps) {
      v.refused.push_back(fmt::format(
          "axis {} moved over {:.3g} mm, {:.1f} steps of its resolution ({:.4g} mm): fewer than "
          "{:g}, so quantisation dominates its accelerations",
          i, m[i].range_m * 1e3, m[i].steps(), m[i].step_m * 1e3, kMinRangeSteps));
    }
  }
  if (r.r_squared < kPoorFit) {
    v.refused.push_back(fmt::format(
        "r^2 = {:.3f} is below {}: the mass-damper model explains the forces poorly (too little "
        "excitation, friction, contact, a missing force column?)",
        r.r_squared, kPoorFit));
  }
  for (Eigen::Index i = 0; i < r.axis_r_squared.size(); ++i) {
    if (r.axis_r_squared(i) < kPoorFit) {
      v.refused.push_back(
          fmt::format("axis {}: r^2 = {:.3f} is below {}", i, r.axis_r_squared(i), kPoorFit));
    }
  }
  if (!r.mass_positive_definite) {
    v.unphysical =
        "the fitted mass matrix is not positive definite, which no device has: check the forces' "
        "signs and columns";
  } else if ((r.damping_Ns_per_m.diagonal().array() < 0.0).any()) {
    v.unphysical =
        "the fitted damping is negative on an axis, which no passive device has: check the "
        "forces' signs and columns";
  }
  return v;
}

// A list as --set takes one whole: comma-separated values.
[[nodiscard]] std::string list_of(const Eigen::MatrixXd& m, bool row_major_all) {
  std::string s;
  if (row_major_all) {
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      for (Eigen::Index j = 0; j < m.cols(); ++j) {
        s += fmt::format("{}{:.4g}", s.empty() ? "" : ",", m(i, j));
      }
    }
  } else {
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      s += fmt::format("{}{:.4g}", i > 0 ? "," : "", m(i, i));
    }
  }
  return s;
}

// The fit in the n-axis configuration fields (docs/configuration.md): the mass matrix row-major,
// the diagonal damping per axis. A full damping matrix has no configuration field.
[[nodiscard]] std::vector<std::string> set_overrides(const std::string& side,
                                                     const stability::IdentifyAxesResult& r,
                                                     bool full_damping) {
  std::vector<std::string> out{
      fmt::format("{}.device.mass_matrix_kg={}", side, list_of(r.mass_kg, true))};
  if (!full_damping) {
    out.push_back(fmt::format("{}.device.damping_Ns_per_m_per_axis={}", side,
                              list_of(r.damping_Ns_per_m, false)));
  }
  return out;
}

[[nodiscard]] std::string set_line(const std::vector<std::string>& overrides) {
  std::string line;
  for (const std::string& o : overrides) line += (line.empty() ? "--set '" : " --set '") + o + "'";
  return line;
}

[[nodiscard]] json matrix_json(const Eigen::MatrixXd& m) {
  json rows = json::array();
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    json row = json::array();
    for (Eigen::Index j = 0; j < m.cols(); ++j) row.push_back(m(i, j));
    rows.push_back(row);
  }
  return rows;
}

struct Report {
  const IdentifyAxesArgs& args;
  const stability::IdentifyAxesResult& result;
  const std::vector<AxisMotion>& motion;
  const Verdict& verdict;
};

[[nodiscard]] const char* mass_name(stability::MassModel m) {
  return m == stability::MassModel::kCoupled ? "coupled" : "per-axis";
}
[[nodiscard]] const char* damping_name(stability::DampingModel d) {
  return d == stability::DampingModel::kFull ? "full" : "diagonal";
}

void print_json(const Report& p, std::ostream& out) {
  const stability::IdentifyAxesResult& r = p.result;
  const bool ok = p.verdict.identified();
  const bool full = p.args.options.damping == stability::DampingModel::kFull;
  std::vector<std::string> reasons = p.verdict.refused;
  if (!p.verdict.unphysical.empty()) reasons.push_back(p.verdict.unphysical);
  json axes = json::array();
  for (std::size_t i = 0; i < p.motion.size(); ++i) {
    const auto e = static_cast<Eigen::Index>(i);
    axes.push_back(
        {{"r_squared", r.axis_r_squared(e)},
         {"residual_rms_N", r.axis_residual_rms_N(e)},
         {"position_range_m", p.motion[i].range_m},
         {"position_step_m", p.motion[i].quantised() ? json(p.motion[i].step_m) : json(nullptr)}});
  }
  const json j = {
      {"device", p.args.device ? json(*p.args.device) : json(nullptr)},
      {"axes", p.motion.size()},
      {"mass_model", mass_name(p.args.options.mass)},
      {"damping_model", damping_name(p.args.options.damping)},
      {"identified", ok},
      {"reasons", reasons},
      {"mass_kg", ok ? matrix_json(r.mass_kg) : json(nullptr)},
      {"damping_Ns_per_m", ok ? matrix_json(r.damping_Ns_per_m) : json(nullptr)},
      {"mass_positive_definite", r.mass_positive_definite},
      {"r_squared", r.r_squared},
      {"residual_rms_N", r.residual_rms_N},
      {"samples", r.samples},
      {"parameters", r.parameters},
      {"condition_number", r.condition_number},
      {"per_axis", axes},
      {"files", p.args.files},
      {"set", ok && p.args.device ? json(set_overrides(*p.args.device, r, full)) : json(nullptr)}};
  out << j.dump(2) << "\n";
}

void print_matrix(const char* title, const Eigen::MatrixXd& m, std::ostream& out) {
  out << "  " << title << "\n";
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    out << "   ";
    for (Eigen::Index j = 0; j < m.cols(); ++j) out << fmt::format(" {:>11.4g}", m(i, j));
    out << "\n";
  }
}

void print_text(const Report& p, std::ostream& out) {
  const stability::IdentifyAxesResult& r = p.result;
  const IdentifyAxesArgs& a = p.args;
  const bool full = a.options.damping == stability::DampingModel::kFull;
  const std::string what = a.device ? *a.device + " device" : "device";
  out << (p.verdict.identified() ? "identified " + what + ": " : "NOT IDENTIFIED (" + what + "): ");
  out << fmt::format("{} axes ({} mass, {} damping), {} run{}, {} samples per axis\n",
                     p.motion.size(), mass_name(a.options.mass), damping_name(a.options.damping),
                     a.files.size(), a.files.size() == 1 ? "" : "s", r.samples);
  if (p.verdict.identified()) {
    print_matrix("mass matrix (kg)", r.mass_kg, out);
    if (full) {
      print_matrix("damping matrix (Ns/m)", r.damping_Ns_per_m, out);
    } else {
      out << "  damping per axis (Ns/m)";
      for (Eigen::Index i = 0; i < r.damping_Ns_per_m.rows(); ++i) {
        out << fmt::format(" {:.4g}", r.damping_Ns_per_m(i, i));
      }
      out << "\n";
    }
  }
  out << fmt::format("  r^2               {:.4f} (residual rms {:.3g} N); per axis", r.r_squared,
                     r.residual_rms_N);
  for (Eigen::Index i = 0; i < r.axis_r_squared.size(); ++i) {
    out << fmt::format(" {:.4f}", r.axis_r_squared(i));
  }
  out << fmt::format("\n  condition number  {:.3g} ({} parameters)\n", r.condition_number,
                     r.parameters);
  out << "  position range   ";
  for (const AxisMotion& m : p.motion) out << fmt::format(" {:.4g} mm", m.range_m * 1e3);
  out << "\n";
  if (!p.verdict.identified()) {
    for (const std::string& why : p.verdict.refused) out << "  not identified: " << why << "\n";
    if (!p.verdict.unphysical.empty()) out << "  not identified: " << p.verdict.unphysical << "\n";
    out << "  no parameters to use: drive every axis with its own force varying over 0.5-10 Hz\n"
           "  that moves it several millimetres\n";
    return;
  }
  for (const char* side : {"master", "slave"}) {
    if (a.device && *a.device != side) continue;
    out << fmt::format(
        "configuration for the {} (--set overrides; they replace the file's "
        "values):\n  {}\n",
        side, set_line(set_overrides(side, r, full)));
  }
  if (full) {
    out << "  (a full damping matrix has no configuration field: its diagonal is "
        << list_of(r.damping_Ns_per_m, false) << " Ns/m)\n";
  }
}

}  // namespace

int identify_axes(const IdentifyAxesArgs& a, std::ostream& out, std::ostream& err) {
  std::vector<stability::SeriesAxes> runs;
  for (const std::string& file : a.files) runs.push_back(read_run(a, file));
  return identify_axes_runs(a, runs, out, err);
}

int identify_axes_runs(const IdentifyAxesArgs& a, const std::vector<stability::SeriesAxes>& runs,
                       std::ostream& out, std::ostream& err) {
  const stability::IdentifyAxesResult r = fit(a, runs);
  const std::vector<AxisMotion> m = motion(runs);
  const Verdict v = judge(r, m);
  const Report report{a, r, m, v};
  if (a.json) {
    print_json(report, out);
  } else {
    print_text(report, out);
  }
  if (!v.refused.empty()) {
    err << "teleopctl identify: not identified, too little excitation: " << v.refused.front()
        << "\n";
    return kExitNotIdentified;
  }
  if (!v.unphysical.empty()) {
    err << "teleopctl identify: " << v.unphysical << "\n";
    return kExitError;
  }
  return kExitOk;
}

}  // namespace teleop::ctl
