#include "supervisor/core/parameter_audit.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace teleop::supervisor {

namespace {

using Named = std::vector<std::pair<std::string, double>>;

Named values_of(const ApprovedParameters& p) {
  if (p.axes > 0) return p.axes_values;
  const Gains& g = p.gains;
  return {{"gains.kpm", g.kpm},
          {"gains.kps", g.kps},
          {"gains.kdm", g.kdm},
          {"gains.kds", g.kds},
          {"gains.kvm", g.kvm},
          {"gains.kvs", g.kvs},
          {"gains.kfm", g.kfm},
          {"master_fixture_stiffness_N_per_m", p.master_fixture_N_per_m},
          {"slave_fixture_stiffness_N_per_m", p.slave_fixture_N_per_m}};
}

Named values_of(const v1::ActiveParameters& a) {
  if (a.axes() > 0) {
    return approved_axes(static_cast<int>(a.axes()), a.gains(), a.master_plane_stiffness_n_per_m(),
                         a.slave_plane_stiffness_n_per_m())
        .axes_values;
  }
  const v1::Gains& g = a.gains();
  ApprovedParameters p{Gains{g.kpm(), g.kps(), g.kdm(), g.kds(), g.kvm(), g.kvs(), g.kfm()},
                       a.master_fixture_stiffness_n_per_m(), a.slave_fixture_stiffness_n_per_m()};
  return values_of(p);
}

// The node computes its values from the ones sent (a ramp's last step is exact: w = 1), so
// equality is all but exact; the tolerance only absorbs rounding of a + 1 * (b - a).
bool same(double a, double b) {
  return std::abs(a - b) <= 1e-9 * std::max({1.0, std::abs(a), std::abs(b)});
}

bool same(const Named& a, const Named& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].first != b[i].first || !same(a[i].second, b[i].second)) return false;
  }
  return true;
}

}  // namespace

ParameterAudit::ParameterAudit(const ApprovedParameters& file_values) {
  approved_.emplace(0, file_values);
}

void ParameterAudit::approve(std::uint64_t change_id, const ApprovedParameters& p) {
  const auto it = approved_.find(change_id);
  if (it != approved_.end()) {
    if (same(values_of(it->second), values_of(p))) return;
    throw std::logic_error(
        fmt::format("parameter change {} was approved already with other values", change_id));
  }
  approved_.emplace(change_id, p);
}

void ParameterAudit::adopt(std::uint64_t change_id, const ApprovedParameters& p) {
  approved_[change_id] = p;
}

std::vector<ParameterMismatch> ParameterAudit::check(const v1::ActiveParameters& active,
                                                     std::uint64_t newest_seen) const {
  std::vector<ParameterMismatch> out;
  const std::uint64_t id = active.change_id();
  if (id < newest_seen) {
    out.push_back(ParameterMismatch{
        "change_id", static_cast<double>(id), static_cast<double>(newest_seen), id,
        fmt::format("change {} in force after change {}: change numbers only grow (an old "
                    "change replayed?)",
                    id, newest_seen)});
  }
  const auto it = approved_.find(id);
  if (it == approved_.end()) {
    out.push_back(ParameterMismatch{
        "change_id", static_cast<double>(id), static_cast<double>(newest()), id,
        fmt::format("change {} was never approved by this supervisor (newest approved: {})", id,
                    newest())});
  }
  const Named v = values_of(active);
  const double progress = active.ramp_progress();
  // The values named as the approved ones (the same axes and planes): else nothing compares.
  const Named first = values_of(approved_.begin()->second);
  bool comparable = v.size() == first.size();
  for (std::size_t i = 0; comparable && i < v.size(); ++i)
    comparable = v[i].first == first[i].first;
  if (!comparable) {
    out.push_back(ParameterMismatch{
        "axes", static_cast<double>(active.axes()),
        static_cast<double>(approved_.begin()->second.axes), id,
        fmt::format("{} values in force, {} approved (another number of axes or planes)", v.size(),
                    first.size())});
    return out;
  }
  // NaN progress is neither settled nor ramping sensibly: judged as a ramp, whose bounds no
  // non-finite value meets.
  const bool settled = progress >= 1.0;
  if (settled && it != approved_.end()) {
    // The change's own values, or a later approved change's (a newer target taken into a ramp
    // under way reaches the law with the older change number).
    for (auto later = it; later != approved_.end(); ++later) {
      if (same(v, values_of(later->second))) return out;
    }
    const Named want = values_of(it->second);
    for (std::size_t i = 0; i < v.size(); ++i) {
      if (same(v[i].second, want[i].second)) continue;
      const std::string& name = v[i].first;
      out.push_back(ParameterMismatch{name, v[i].second, want[i].second, id,
                                      fmt::format("{} {} in force under change {} (approved {})",
                                                  name, v[i].second, id, want[i].second)});
    }
    return out;
  }
  // Ramping (or an unknown change): each value within the range of approved values.
  for (std::size_t i = 0; i < v.size(); ++i) {
    double lo = first[i].second;
    double hi = lo;
    for (const auto& [approved_id, p] : approved_) {
      const double x = values_of(p)[i].second;
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    const double x = v[i].second;
    if (std::isfinite(x) && (x >= lo || same(x, lo)) && (x <= hi || same(x, hi))) continue;
    const double nearest = std::isfinite(x) && x < lo ? lo : hi;
    const std::string& name = v[i].first;
    out.push_back(ParameterMismatch{
        name, x, nearest, id,
        fmt::format("{} {} in force (ramp {:.2f}) outside every approved value [{}, {}]", name, x,
                    progress, lo, hi)});
  }
  return out;
}

ApprovedParameters approved_axes(
    int axes, const v1::Gains& gains,
    const google::protobuf::RepeatedField<double>& master_planes_N_per_m,
    const google::protobuf::RepeatedField<double>& slave_planes_N_per_m) {
  ApprovedParameters p;
  p.axes = axes;
  const std::array<std::pair<const char*, const google::protobuf::RepeatedField<double>*>, 7>
      matrices{{{"kpm", &gains.kpm_matrix()},
                {"kps", &gains.kps_matrix()},
                {"kdm", &gains.kdm_matrix()},
                {"kds", &gains.kds_matrix()},
                {"kvm", &gains.kvm_matrix()},
                {"kvs", &gains.kvs_matrix()},
                {"kfm", &gains.kfm_matrix()}}};
  for (const auto& [name, values] : matrices) {
    for (int r = 0; r < axes; ++r) {
      for (int c = 0; c < axes; ++c) {
        const int i = r * axes + c;
        // A matrix shorter than n x n: its missing elements read NaN, which no approval meets.
        const double x = i < values->size() ? values->Get(i) : std::nan("");
        p.axes_values.emplace_back(fmt::format("gains.{}[{},{}]", name, r, c), x);
      }
    }
  }
  for (const auto& [side, planes] :
       {std::pair{"master", &master_planes_N_per_m}, std::pair{"slave", &slave_planes_N_per_m}}) {
    for (int i = 0; i < planes->size(); ++i) {
      p.axes_values.emplace_back(fmt::format("{}.planes[{}].stiffness_N_per_m", side, i),
                                 planes->Get(i));
    }
  }
  return p;
}

std::string describe(const std::vector<ParameterMismatch>& m) {
  std::string out;
  for (const ParameterMismatch& x : m) {
    if (!out.empty()) out += "; ";
    out += x.why;
  }
  return out;
}

}  // namespace teleop::supervisor
