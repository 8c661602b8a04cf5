#include "supervisor/core/stability_guard_axes.hpp"

#include <fmt/core.h>
#include <google/protobuf/descriptor.h>

#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

#include "common/config/parameter_space.hpp"
#include "common/stability/discrete_model_axes.hpp"
#include "supervisor/core/stability_guard.hpp"
#include "teleop/v1/config.pb.h"

namespace teleop::supervisor {

namespace {

namespace pb = google::protobuf;
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;
using stability::Side;

const char* side_name(Side s) { return s == Side::kMaster ? "master" : "slave"; }

const pb::FieldDescriptor* field(const pb::Descriptor* d, const char* name) {
  return d->FindFieldByName(name);
}

std::string at(const std::string& path, Eigen::Index i) { return fmt::format("{}[{}]", path, i); }
std::string at(const std::string& path, Eigen::Index i, Eigen::Index j) {
  return fmt::format("{}[{},{}]", path, i, j);
}

// The one parameter space's verdict on one value, as "path: problem" (empty when acceptable).
std::string check(const pb::FieldDescriptor* f, const std::string& path, double value) {
  std::string why;
  if (f == nullptr) {
    if (!std::isfinite(value)) why = fmt::format("must be finite, got {}", value);
  } else {
    why = config::check_value(f, value);
  }
  return why.empty() ? why : path + ": " + why;
}

// A matrix: the diagonal by `diagonal`'s rule, the rest by `off`'s (for a rule with a sign,
// off-diagonal entries by their magnitude).
std::string check_matrix(const Mat& m, const std::string& path, const pb::FieldDescriptor* diagonal,
                         const pb::FieldDescriptor* off) {
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    for (Eigen::Index j = 0; j < m.cols(); ++j) {
      const double v = m(i, j);
      std::string why = i == j ? check(diagonal, at(path, i, j), v)
                               : check(off, at(path, i, j), off == diagonal ? std::abs(v) : v);
      if (!why.empty()) return why;
    }
  }
  return {};
}

std::string check_vector(const Vec& v, const std::string& path, const pb::FieldDescriptor* f) {
  for (Eigen::Index i = 0; i < v.size(); ++i) {
    if (std::string why = check(f, at(path, i), v(i)); !why.empty()) return why;
  }
  return {};
}

std::string check_device(const DeviceAxesParams& d, const std::string& path) {
  const pb::Descriptor* dd = v1::Device::descriptor();
  if (auto why = check_matrix(d.mass_kg, path + ".mass_kg", field(dd, "mass_kg"),
                              field(dd, "mass_matrix_kg"));
      !why.empty())
    return why;
  if (auto why = check_vector(d.damping_Ns_per_m, path + ".damping_Ns_per_m",
                              field(dd, "damping_Ns_per_m_per_axis"));
      !why.empty())
    return why;
  return check_vector(d.coulomb_N, path + ".coulomb_N", field(dd, "coulomb_N_per_axis"));
}

std::string check_planes(const std::vector<PlaneFixtureParams>& planes, const std::string& side) {
  const pb::Descriptor* pd = v1::Plane::descriptor();
  for (std::size_t i = 0; i < planes.size(); ++i) {
    const std::string path = fmt::format("{}[{}]", side, i);
    const PlaneFixtureParams& p = planes[i];
    if (auto why = check_vector(p.normal, path + ".normal", field(pd, "normal")); !why.empty())
      return why;
    if (auto why = check(field(pd, "offset_m"), path + ".offset_m", p.offset_m); !why.empty())
      return why;
    if (auto why =
            check(field(pd, "stiffness_N_per_m"), path + ".stiffness_N_per_m", p.stiffness_N_per_m);
        !why.empty())
      return why;
  }
  return {};
}

std::string check_gains(const GainsAxes& g) {
  const pb::Descriptor* gd = v1::Gains::descriptor();
  const std::pair<const Mat*, const char*> parts[] = {
      {&g.kpm, "kpm"}, {&g.kps, "kps"}, {&g.kdm, "kdm"}, {&g.kds, "kds"},
      {&g.kvm, "kvm"}, {&g.kvs, "kvs"}, {&g.kfm, "kfm"}};
  for (const auto& [m, name] : parts) {
    const std::string n(name);
    if (auto why = check_matrix(*m, "gains." + n, field(gd, (n + "_per_axis").c_str()),
                                field(gd, (n + "_matrix").c_str()));
        !why.empty())
      return why;
  }
  return {};
}

std::string check_human(const HumanModelAxes& h) {
  const pb::Descriptor* hd = v1::HumanImpedance::descriptor();
  const std::pair<const Mat*, const char*> fixed[] = {
      {&h.fixed.mass_kg, "mass_kg"},
      {&h.fixed.damping_Ns_per_m, "damping_Ns_per_m"},
      {&h.fixed.stiffness_N_per_m, "stiffness_N_per_m"}};
  for (const auto& [m, name] : fixed) {
    const pb::FieldDescriptor* f = field(hd, name);
    if (auto why = check_matrix(*m, std::string("human.fixed.") + name, f, f); !why.empty())
      return why;
  }
  const pb::FieldDescriptor* levels = field(v1::HumanBand::descriptor(), "force_levels_N");
  const pb::Descriptor* ld = v1::LinearBound::descriptor();
  for (std::size_t a = 0; a < h.band_per_axis.size(); ++a) {
    const HumanBand& b = h.band_per_axis[a];
    const std::string path = fmt::format("human.band_per_axis[{}]", a);
    for (std::size_t i = 0; i < b.force_levels_N.size(); ++i) {
      if (auto why =
              check(levels, fmt::format("{}.force_levels_N[{}]", path, i), b.force_levels_N[i]);
          !why.empty())
        return why;
    }
    const std::pair<const ParameterBand*, const char*> parts[] = {
        {&b.mass_kg, "mass_kg"},
        {&b.damping_Ns_per_m, "damping_Ns_per_m"},
        {&b.stiffness_N_per_m, "stiffness_N_per_m"}};
    for (const auto& [band, name] : parts) {
      for (const auto& [bound, bound_name] :
           {std::pair{&band->lower, "lower"}, std::pair{&band->upper, "upper"}}) {
        const std::string p = fmt::format("{}.{}.{}", path, name, bound_name);
        if (auto why = check(field(ld, "intercept"), p + ".intercept", bound->intercept);
            !why.empty())
          return why;
        if (auto why = check(field(ld, "slope_per_N"), p + ".slope_per_N", bound->slope_per_N);
            !why.empty())
          return why;
      }
    }
  }
  return {};
}

// ---------------------------------------------------------------------------------------------
// What differs between two configurations: `live` the fields a parameter change may set (gains
// and plane stiffnesses), `fixed` the rest.

struct Diff {
  std::vector<std::string> live{};
  std::vector<std::string> fixed{};
  bool gains_changed{false};
};

void diff_matrix(const Mat& a, const Mat& b, const std::string& path,
                 std::vector<std::string>& out) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) {
    out.push_back(fmt::format("{} ({}x{} -> {}x{})", path, a.rows(), a.cols(), b.rows(), b.cols()));
    return;
  }
  for (Eigen::Index i = 0; i < a.rows(); ++i) {
    for (Eigen::Index j = 0; j < a.cols(); ++j) {
      if (!(a(i, j) == b(i, j))) {
        out.push_back(a.cols() == 1
                          ? fmt::format("{}: {:g} -> {:g}", at(path, i), a(i), b(i))
                          : fmt::format("{}: {:g} -> {:g}", at(path, i, j), a(i, j), b(i, j)));
      }
    }
  }
}

void diff_value(double a, double b, const std::string& path, std::vector<std::string>& out) {
  if (!(a == b)) out.push_back(fmt::format("{}: {:g} -> {:g}", path, a, b));
}

bool same_band(const HumanBand& a, const HumanBand& b) {
  auto same = [](const ParameterBand& x, const ParameterBand& y) {
    return x.lower.intercept == y.lower.intercept && x.lower.slope_per_N == y.lower.slope_per_N &&
           x.upper.intercept == y.upper.intercept && x.upper.slope_per_N == y.upper.slope_per_N;
  };
  return a.force_levels_N == b.force_levels_N && a.points_per_axis == b.points_per_axis &&
         same(a.mass_kg, b.mass_kg) && same(a.damping_Ns_per_m, b.damping_Ns_per_m) &&
         same(a.stiffness_N_per_m, b.stiffness_N_per_m);
}

void diff_planes(const std::vector<PlaneFixtureParams>& a, const std::vector<PlaneFixtureParams>& b,
                 const std::string& side, Diff& d) {
  if (a.size() != b.size()) {
    d.fixed.push_back(fmt::format("{} ({} planes -> {})", side, a.size(), b.size()));
    return;
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    const std::string path = fmt::format("{}[{}]", side, i);
    diff_matrix(a[i].normal, b[i].normal, path + ".normal", d.fixed);
    diff_value(a[i].offset_m, b[i].offset_m, path + ".offset_m", d.fixed);
    diff_value(a[i].stiffness_N_per_m, b[i].stiffness_N_per_m, path + ".stiffness_N_per_m", d.live);
  }
}

Diff diff(const TeleopAxesParams& a, const TeleopAxesParams& b) {
  Diff d;
  diff_value(a.axes, b.axes, "axes", d.fixed);
  diff_value(a.sample_rate_hz, b.sample_rate_hz, "sample_rate_hz", d.fixed);
  for (const auto& [x, y, name] : {std::tuple{&a.master_device, &b.master_device, "master_device"},
                                   std::tuple{&a.slave_device, &b.slave_device, "slave_device"}}) {
    const std::string n(name);
    diff_matrix(x->mass_kg, y->mass_kg, n + ".mass_kg", d.fixed);
    diff_matrix(x->damping_Ns_per_m, y->damping_Ns_per_m, n + ".damping_Ns_per_m", d.fixed);
    diff_matrix(x->coulomb_N, y->coulomb_N, n + ".coulomb_N", d.fixed);
  }
  diff_planes(a.master_planes, b.master_planes, "master_planes", d);
  diff_planes(a.slave_planes, b.slave_planes, "slave_planes", d);
  const std::size_t before = d.live.size();
  const GainsAxes& g = a.gains;
  const GainsAxes& h = b.gains;
  diff_matrix(g.kpm, h.kpm, "gains.kpm", d.live);
  diff_matrix(g.kps, h.kps, "gains.kps", d.live);
  diff_matrix(g.kdm, h.kdm, "gains.kdm", d.live);
  diff_matrix(g.kds, h.kds, "gains.kds", d.live);
  diff_matrix(g.kvm, h.kvm, "gains.kvm", d.live);
  diff_matrix(g.kvs, h.kvs, "gains.kvs", d.live);
  diff_matrix(g.kfm, h.kfm, "gains.kfm", d.live);
  d.gains_changed = d.live.size() > before;
  diff_value(a.scaling.position, b.scaling.position, "scaling.position", d.fixed);
  diff_value(a.scaling.force, b.scaling.force, "scaling.force", d.fixed);
  diff_value(a.velocity_cutoff_hz, b.velocity_cutoff_hz, "velocity_cutoff_hz", d.fixed);
  diff_value(a.round_trip_delay_samples, b.round_trip_delay_samples, "round_trip_delay_samples",
             d.fixed);
  if (a.human.kind != b.human.kind) d.fixed.emplace_back("human.kind");
  diff_matrix(a.human.fixed.mass_kg, b.human.fixed.mass_kg, "human.fixed.mass_kg", d.fixed);
  diff_matrix(a.human.fixed.damping_Ns_per_m, b.human.fixed.damping_Ns_per_m,
              "human.fixed.damping_Ns_per_m", d.fixed);
  diff_matrix(a.human.fixed.stiffness_N_per_m, b.human.fixed.stiffness_N_per_m,
              "human.fixed.stiffness_N_per_m", d.fixed);
  bool same_bands = a.human.band_per_axis.size() == b.human.band_per_axis.size();
  for (std::size_t i = 0; same_bands && i < a.human.band_per_axis.size(); ++i) {
    same_bands = same_band(a.human.band_per_axis[i], b.human.band_per_axis[i]);
  }
  if (!same_bands) d.fixed.emplace_back("human.band_per_axis");
  return d;
}

std::string join(const std::vector<std::string>& parts) {
  std::string s;
  for (const std::string& p : parts) s += (s.empty() ? "" : ", ") + p;
  return s;
}

// The plane or gain that decides a refusal: a plane above its limit, else the changed gains,
// else the plane closest to its limit (empty when there is none).
std::string decider(const AxesAssessment& a, const Diff& d) {
  for (const PlaneMargin& p : a.planes) {
    if (p.max_stable_N_per_m && p.stiffness_N_per_m > *p.max_stable_N_per_m) {
      return fmt::format("{} plane {} at {:g} N/m is above its limit {:g} N/m", side_name(p.side),
                         p.plane, p.stiffness_N_per_m, *p.max_stable_N_per_m);
    }
  }
  if (d.gains_changed) {
    std::vector<std::string> gains;
    for (const std::string& s : d.live) {
      if (s.starts_with("gains.")) gains.push_back(s);
    }
    return "with the gains changed (" + join(gains) + ")";
  }
  if (a.limiting_plane) return a.planes[*a.limiting_plane].describe();
  return {};
}

}  // namespace

std::optional<double> PlaneMargin::fraction_of_limit() const {
  if (!max_stable_N_per_m || !(*max_stable_N_per_m > 0.0)) return std::nullopt;
  return stiffness_N_per_m / *max_stable_N_per_m;
}

std::optional<double> PlaneMargin::margin() const {
  const std::optional<double> f = fraction_of_limit();
  if (!f) return std::nullopt;
  return 1.0 - *f;
}

std::string PlaneMargin::describe() const {
  const std::optional<double> f = fraction_of_limit();
  if (!f) {
    return fmt::format("{} plane {}: {:g} N/m, no finite limit ({})", side_name(side), plane,
                       stiffness_N_per_m, reason);
  }
  return fmt::format("{} plane {}: {:.0f} % of its limit ({:g} of {:g} N/m{})", side_name(side),
                     plane, 100.0 * *f, stiffness_N_per_m, *max_stable_N_per_m,
                     uncertain ? ", the limit within the numerical error" : "");
}

bool AxesAssessment::acceptable() const {
  return verdict == stability::Verdict::kStable && min_damping_ratio >= required_damping_ratio;
}

std::string check_axes_ranges(const TeleopAxesParams& p) {
  if (auto why = check(field(v1::SystemConfig::descriptor(), "sample_rate_hz"), "sample_rate_hz",
                       p.sample_rate_hz);
      !why.empty())
    return why;
  if (auto why = check_device(p.master_device, "master_device"); !why.empty()) return why;
  if (auto why = check_device(p.slave_device, "slave_device"); !why.empty()) return why;
  if (auto why = check_planes(p.master_planes, "master_planes"); !why.empty()) return why;
  if (auto why = check_planes(p.slave_planes, "slave_planes"); !why.empty()) return why;
  if (auto why = check_gains(p.gains); !why.empty()) return why;
  const pb::Descriptor* sd = v1::Scaling::descriptor();
  if (auto why = check(field(sd, "position"), "scaling.position", p.scaling.position); !why.empty())
    return why;
  if (auto why = check(field(sd, "force"), "scaling.force", p.scaling.force); !why.empty())
    return why;
  if (auto why = check(field(v1::VelocityFilter::descriptor(), "cutoff_hz"), "velocity_cutoff_hz",
                       p.velocity_cutoff_hz);
      !why.empty())
    return why;
  return check_human(p.human);
}

AxesAssessment assess_axes(const TeleopAxesParams& params, double required_damping_ratio,
                           const stability::AxesAnalysisOptions& options) {
  AxesAssessment out;
  out.required_damping_ratio = required_damping_ratio;
  if (!std::isfinite(required_damping_ratio)) {
    out.invalid_reason = "the required damping ratio must be finite";
    out.min_damping_ratio = std::nan("");
    return out;
  }
  TeleopAxesParams p = params;
  p.analysis.required_damping_ratio = required_damping_ratio;
  stability::AxesAnalysisOptions o = options;
  o.plane_limits = true;
  const stability::AxesAnalysis r = stability::analyze_axes(p, o);
  out.verdict = r.verdict;
  out.min_damping_ratio = r.min_damping_ratio;
  out.worst_human = r.worst_human;
  out.invalid_reason = r.invalid_reason;
  for (const stability::PlaneLimit& l : r.plane_limits) {
    PlaneMargin m;
    m.side = l.side;
    m.plane = l.plane;
    const auto& planes = l.side == Side::kMaster ? p.master_planes : p.slave_planes;
    m.stiffness_N_per_m = planes[l.plane].stiffness_N_per_m;
    m.max_stable_N_per_m = l.max_stable_stiffness_N_per_m;
    m.reason = l.reason;
    m.uncertain = l.uncertain;
    out.planes.push_back(std::move(m));
  }
  out.limiting_plane = r.limiting_plane;
  return out;
}

namespace {

stability::AxesAnalysis analyse(const TeleopAxesParams& params, double required,
                                const stability::AxesAnalysisOptions& options) {
  TeleopAxesParams p = params;
  p.analysis.required_damping_ratio = required;
  stability::AxesAnalysisOptions o = options;
  o.plane_limits = false;
  return stability::analyze_axes(p, o);
}

bool admissible(const stability::AxesAnalysis& r, double required) {
  return r.verdict == stability::Verdict::kStable && r.min_damping_ratio >= required;
}

// Plane `i` of `side` in `to`: its limit from the prediction, or computed when the prediction
// has none (a plane going to 0 is not in use there).
std::pair<std::optional<double>, std::string> limit_of(const AxesAssessment& end,
                                                       const TeleopAxesParams& to, Side side,
                                                       std::size_t i, double required,
                                                       const stability::AxesAnalysisOptions& o) {
  for (const PlaneMargin& m : end.planes) {
    if (m.side == side && m.plane == i) return {m.max_stable_N_per_m, m.reason};
  }
  TeleopAxesParams p = to;
  p.analysis.required_damping_ratio = required;
  const stability::PlaneLimit l = stability::plane_stiffness_limit(p, side, i, o);
  return {l.max_stable_stiffness_N_per_m, l.reason};
}

// `to` with every gain and plane stiffness a fraction `f` of the way from `from`.
TeleopAxesParams mix(const TeleopAxesParams& from, const TeleopAxesParams& to, double f) {
  TeleopAxesParams mid = to;
  auto m = [f](const Mat& a, const Mat& b) { return Mat(a + f * (b - a)); };
  mid.gains = {m(from.gains.kpm, to.gains.kpm), m(from.gains.kps, to.gains.kps),
               m(from.gains.kdm, to.gains.kdm), m(from.gains.kds, to.gains.kds),
               m(from.gains.kvm, to.gains.kvm), m(from.gains.kvs, to.gains.kvs),
               m(from.gains.kfm, to.gains.kfm)};
  for (const bool slave : {false, true}) {
    const auto& a = slave ? from.slave_planes : from.master_planes;
    auto& b = slave ? mid.slave_planes : mid.master_planes;
    for (std::size_t i = 0; i < b.size(); ++i) {
      b[i].stiffness_N_per_m =
          a[i].stiffness_N_per_m + f * (b[i].stiffness_N_per_m - a[i].stiffness_N_per_m);
    }
  }
  return mid;
}

// Why the ramp from `from` to `to` may leave the admissible region (empty when it cannot), as
// StabilityGuard::path_refusal for one axis: a plane's ramp exactly (its limit L is the first
// stiffness where a mode leaves the region, so [0, L] is admissible and nothing above L is
// reachable without crossing L: refused when it ends above L or starts above it); gains, and
// two planes changing together, at StabilityGuard::kGainRampPoints - 1 evenly spaced
// intermediate points (a resolution, not a proof). When what is in force is itself not
// admissible, the ramp is a rescue into the region and only its end point counts.
std::string ramp_refusal(const TeleopAxesParams& from, const TeleopAxesParams& to,
                         const AxesAssessment& end, bool gains_changed, double required,
                         const stability::AxesAnalysisOptions& options) {
  if (!admissible(analyse(from, required, options), required)) return {};
  int planes_changing = 0;
  for (const Side side : {Side::kMaster, Side::kSlave}) {
    const auto& pa = side == Side::kMaster ? from.master_planes : from.slave_planes;
    const auto& pb = side == Side::kMaster ? to.master_planes : to.slave_planes;
    for (std::size_t i = 0; i < pb.size(); ++i) {
      const double a = pa[i].stiffness_N_per_m;
      const double b = pb[i].stiffness_N_per_m;
      if (a == b) continue;
      ++planes_changing;
      if (!(std::max(a, b) > 0.0)) continue;
      const auto [limit, why] = limit_of(end, to, side, i, required, options);
      const std::string ramp =
          fmt::format("the {} plane {}'s ramp from {:g} to {:g} N/m", side_name(side), i, a, b);
      if (!limit) {
        if (why.starts_with("meets the requirement for every stiffness")) continue;
        return ramp + " cannot be shown admissible: " + why;
      }
      if (b > *limit) {
        return fmt::format(
            "{} passes {:g} N/m, where a mode leaves the admissible region (every stiffness up "
            "to there is admissible)",
            ramp, *limit);
      }
      if (a > *limit) {
        return fmt::format(
            "{} passes {:g} N/m: {:g} N/m lies in a stable window above an unstable one", ramp,
            *limit, a);
      }
    }
  }
  if (!gains_changed && planes_changing < 2) return {};
  constexpr int kPoints = StabilityGuard::kGainRampPoints;
  for (int i = 1; i < kPoints; ++i) {
    const double f = static_cast<double>(i) / kPoints;
    const stability::AxesAnalysis r = analyse(mix(from, to, f), required, options);
    if (!admissible(r, required)) {
      return fmt::format(
          "the ramp to the new values is {} {:.0f} % of the way (minimum damping ratio {:.4f})",
          stability::to_string(r.verdict), 100.0 * f, r.min_damping_ratio);
    }
  }
  return {};
}

}  // namespace

AxesDecision assess_axes_change(const TeleopAxesParams& current, const TeleopAxesParams& proposed,
                                const AxesGuardOptions& options) {
  AxesDecision d;
  const double required =
      options.required_damping_ratio.value_or(current.analysis.required_damping_ratio);
  d.prediction.required_damping_ratio = required;
  d.prediction.min_damping_ratio = std::nan("");
  // Nothing non-finite, misshapen or beyond the one parameter space's ceilings reaches the
  // analyser (1e308 is finite, and overflows the model).
  std::string why = stability::check_axes_params(proposed);
  if (why.empty()) why = check_axes_ranges(proposed);
  if (!why.empty()) {
    d.reason = "refused: " + why;
    d.prediction.invalid_reason = why;
    return d;
  }
  const Diff diffs = diff(current, proposed);
  d.changed = diffs.live;
  if (!diffs.fixed.empty()) {
    d.changed.insert(d.changed.end(), diffs.fixed.begin(), diffs.fixed.end());
    d.reason =
        "refused: only the gains and the planes' stiffnesses change live, not " + join(diffs.fixed);
    d.prediction.invalid_reason = d.reason;
    return d;
  }
  d.prediction = assess_axes(proposed, required, options.analysis);
  const AxesAssessment& a = d.prediction;
  const std::string who = decider(a, diffs);
  const std::string tail = who.empty() ? "" : "; " + who;
  using stability::Verdict;
  if (a.verdict == Verdict::kInvalid) {
    d.reason = "refused: the analyser cannot evaluate the model (" + a.invalid_reason + ")";
  } else if (a.verdict == Verdict::kUnstable) {
    d.reason = fmt::format(
        "refused: the analyser predicts an unstable teleoperator (minimum damping ratio {:.4f}, "
        "round trip {} samples){}",
        a.min_damping_ratio, proposed.round_trip_delay_samples, tail);
  } else if (a.verdict == Verdict::kUncertain) {
    d.reason =
        "refused: the analyser's verdict is uncertain (an eigenvalue within its error bound of "
        "the unit circle)" +
        tail;
  } else if (!(a.min_damping_ratio >= a.required_damping_ratio)) {  // NaN fails too
    d.reason = fmt::format(
        "refused: predicted minimum damping ratio {:.4f} is below the required {:.4f}{}",
        a.min_damping_ratio, a.required_damping_ratio, tail);
  } else if (const std::string ramp = ramp_refusal(current, proposed, a, diffs.gains_changed,
                                                   required, options.analysis);
             !ramp.empty()) {
    d.reason = "refused: " + ramp;
  } else {
    d.accepted = true;
    d.reason = fmt::format("accepted: predicted minimum damping ratio {:.4f} (required {:.4f})",
                           a.min_damping_ratio, a.required_damping_ratio);
    if (a.limiting_plane) d.reason += "; " + a.planes[*a.limiting_plane].describe();
  }
  return d;
}

}  // namespace teleop::supervisor
