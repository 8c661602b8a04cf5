#include "supervisor/teleopctl/analyze_plots.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <complex>
#include <limits>
#include <string_view>
#include <vector>

#include "common/config/parameter_space.hpp"
#include "teleop/v1/config.pb.h"

namespace teleop::ctl {

namespace {

using nlohmann::json;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The inset's half-height at most: five times the main plot's scale.
constexpr double kInsetMaxHalf = 0.3;
constexpr const char* kUnstableColour = "#d62728";

std::string upper(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return out;
}

// A window next to z = 1 (three quarters of it inside the unit circle, where stable modes
// are) sized to hold the eigenvalue nearest z = 1 with a margin: a 1 kHz loop's slow modes
// crowd there. None without eigenvalues.
std::optional<Inset> inset_near_one(const Series& cloud) {
  double nearest = std::numeric_limits<double>::infinity();
  for (const auto& [x, y] : cloud.points) nearest = std::min(nearest, std::hypot(1.0 - x, y));
  if (!std::isfinite(nearest)) return std::nullopt;
  const double want = std::max(1.3 * nearest, 1e-3);
  const double quantum = nice_step(want) / 4.0;
  const double half = std::min(kInsetMaxHalf, std::ceil(want / quantum) * quantum);
  return Inset{"near z = 1 (zoomed)", 1.0 - 1.5 * half, 1.0 + 0.5 * half, -half, half};
}

// The suffix convention of the configuration's names: "_N_per_m" -> "N/m".
std::string unit_from_name(std::string_view name) {
  static constexpr std::pair<std::string_view, std::string_view> kSuffixes[] = {
      {"_Ns_per_m", "Ns/m"},   {"_N_per_m", "N/m"}, {"_hz", "Hz"}, {"_ms", "ms"}, {"_us", "us"},
      {"_samples", "samples"}, {"_kg", "kg"},       {"_N", "N"},   {"_m", "m"},   {"_s", "s"}};
  for (const auto& [suffix, unit] : kSuffixes) {
    if (name.size() > suffix.size() && name.ends_with(suffix)) return std::string(unit);
  }
  return {};
}

// The field a dotted path of teleop.v1.SystemConfig names (nullptr when it names none).
const google::protobuf::FieldDescriptor* field_of(const std::string& path) {
  const google::protobuf::Descriptor* type = teleop::v1::SystemConfig::descriptor();
  const google::protobuf::FieldDescriptor* field = nullptr;
  std::size_t begin = 0;
  while (type != nullptr && begin <= path.size()) {
    const std::size_t end = std::min(path.find('.', begin), path.size());
    std::string segment = path.substr(begin, end - begin);
    segment = segment.substr(0, segment.find('['));
    field = type->FindFieldByName(segment);
    if (field == nullptr || end == path.size()) return field;
    type = field->message_type();
    begin = end + 1;
  }
  return nullptr;
}

std::optional<double> number_or_none(const json& j, const char* key) {
  if (!j.contains(key) || j[key].is_null()) return std::nullopt;
  return j[key].get<double>();
}

}  // namespace

std::string unit_of(const std::string& path) {
  std::string unit;
  if (const auto* field = field_of(path)) {
    if (const config::FieldRule* rule = config::rule_for(field)) unit = std::string(rule->unit);
  }
  if (unit.empty()) unit = unit_from_name(path.substr(path.rfind('.') + 1));
  return unit;
}

std::string axis_label_with_unit(const std::string& path) {
  const std::string unit = unit_of(path);
  return fmt::format("{} ({})", path, unit.empty() ? "dimensionless" : unit);
}

Chart z_plane_chart(const TeleopParams& p, const stability::AnalysisResult& r) {
  const stability::LoopEvaluator ev(p);
  bool any_force = false;
  double f_lo = std::numeric_limits<double>::infinity();
  double f_hi = -f_lo;
  for (std::size_t i = 0; i < ev.human_count(); ++i) {
    if (!ev.human(i).has_force) continue;
    any_force = true;
    f_lo = std::min(f_lo, ev.human(i).force_N);
    f_hi = std::max(f_hi, ev.human(i).force_N);
  }
  Series cloud{any_force ? "eigenvalue (colour: grip force)"
                         : (ev.human_count() > 1 ? "eigenvalue, each human" : "eigenvalue"),
               {},
               "#0072b2",
               false};
  cloud.marker = Marker::kCircle;
  Series unstable{"|z| > 1: unstable", {}, kUnstableColour, false};
  unstable.marker = Marker::kRing;
  unstable.kind = "unstable";
  // Drawn from the highest grip force down, so each level's markers stay visible.
  std::vector<std::size_t> order(ev.human_count());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return ev.human(a).force_N > ev.human(b).force_N;
  });
  for (const std::size_t i : order) {
    const stability::Spectrum s = ev.spectrum(i, p.master_fixture.stiffness_N_per_m,
                                              p.slave_fixture.stiffness_N_per_m, false);
    for (const stability::Mode& m : s.modes) {
      if (m.structural) continue;
      cloud.points.emplace_back(m.z.real(), m.z.imag());
      if (any_force) cloud.values.push_back(ev.human(i).force_N);
      if (std::abs(m.z) > 1.0) unstable.points.emplace_back(m.z.real(), m.z.imag());
    }
  }
  if (cloud.points.size() > 200) cloud.marker = Marker::kDot;
  Chart chart;
  chart.title =
      fmt::format("Closed-loop eigenvalues in the z-plane: {}", upper(to_string(r.verdict)));
  chart.subtitle = fmt::format(
      "{:g} Hz, round trip {} sample(s), fixtures master {:g} N/m, slave {:g} N/m; spectral "
      "radius {:.4f}",
      p.sample_rate_hz, p.round_trip_delay_samples, p.master_fixture.stiffness_N_per_m,
      p.slave_fixture.stiffness_N_per_m, r.spectral_radius);
  chart.x_label = "Re z";
  chart.unit_circle = true;
  chart.inset = inset_near_one(cloud);
  if (any_force) chart.colour_scale = ColourScale{"grip force of the human (N)", f_lo, f_hi};
  chart.notes.push_back(fmt::format("{} human(s), {} eigenvalues, {} with |z| > 1",
                                    ev.human_count(), cloud.points.size(), unstable.points.size()));
  Panel panel{"Im z", {std::move(cloud)}, false};
  if (!unstable.points.empty()) panel.series.push_back(std::move(unstable));
  chart.panels.push_back(std::move(panel));
  return chart;
}

Chart limits_chart(const LimitsPlot& plot) {
  const bool against_swept = !plot.swept.empty() && plot.one_rate;
  Chart chart;
  chart.title = fmt::format("Maximum stable {} fixture stiffness against {}", plot.side,
                            against_swept ? plot.swept : std::string("the sample rate"));
  chart.subtitle = plot.subtitle;
  chart.x_label = against_swept ? axis_label_with_unit(plot.swept) : "sample rate (Hz)";
  // One curve per swept value (or one without a sweep), in the order --json lists them.
  std::vector<std::pair<std::optional<double>, std::vector<const json*>>> curves;
  for (const json& j : plot.limits) {
    const std::optional<double> v =
        plot.swept.empty() || against_swept ? std::nullopt : number_or_none(j, plot.swept.c_str());
    if (curves.empty() || curves.back().first != v)
      curves.emplace_back(v, std::vector<const json*>{});
    curves.back().second.push_back(&j);
  }
  Panel panel{"maximum stable stiffness (N/m)", {}, true};
  Series none{"no stable stiffness at any value", {}, "#000000", false};
  none.marker = Marker::kTriangle;
  none.kind = "no-limit";
  std::vector<Series> bounds;
  for (std::size_t c = 0; c < curves.size(); ++c) {
    const std::string name = curves[c].first ? fmt::format("{} = {:g} {}", plot.swept,
                                                           *curves[c].first, unit_of(plot.swept))
                                             : std::string();
    Series line{
        name.empty() ? fmt::format("{} fixture limit", plot.side) : name, {}, line_colour(c), true};
    line.marker = Marker::kCircle;
    Series bound{
        name.empty() ? "passivity bound" : "passivity bound, " + name, {}, line_colour(c), true};
    bound.dashed = true;
    bool any_bound = false;
    for (const json* j : curves[c].second) {
      const double x =
          against_swept ? (*j)[plot.swept].get<double>() : (*j)["sample_rate_hz"].get<double>();
      const std::optional<double> k = number_or_none(*j, "max_stable_stiffness_N_per_m");
      line.points.emplace_back(x, k.value_or(kNaN));
      if (!k) none.points.emplace_back(x, 0.0);
      const std::optional<double> pb = number_or_none(*j, "passivity_limit_N_per_m");
      any_bound = any_bound || pb.has_value();
      bound.points.emplace_back(x, pb.value_or(kNaN));
    }
    panel.series.push_back(std::move(line));
    if (any_bound) bounds.push_back(std::move(bound));
  }
  for (Series& b : bounds) panel.series.push_back(std::move(b));
  if (!none.points.empty()) panel.series.push_back(std::move(none));
  if (bounds.empty() && plot.side != "master") {
    chart.notes.push_back("passivity bound (Colgate-Schenkel): master side only");
  } else if (bounds.empty()) {
    const json& first = plot.limits.empty() ? json() : plot.limits.front();
    chart.notes.push_back(first.contains("passivity_reason")
                              ? "no passivity bound: " +
                                    first["passivity_reason"].get<std::string>()
                              : std::string("no passivity bound at these points"));
  }
  chart.panels.push_back(std::move(panel));
  return chart;
}

}  // namespace teleop::ctl
