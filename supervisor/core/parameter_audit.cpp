#include "supervisor/core/parameter_audit.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace teleop::supervisor {

namespace {

constexpr std::size_t kFields = 9;
constexpr std::array<const char*, kFields> kNames = {"gains.kpm",
                                                     "gains.kps",
                                                     "gains.kdm",
                                                     "gains.kds",
                                                     "gains.kvm",
                                                     "gains.kvs",
                                                     "gains.kfm",
                                                     "master_fixture_stiffness_N_per_m",
                                                     "slave_fixture_stiffness_N_per_m"};

std::array<double, kFields> values_of(const ApprovedParameters& p) {
  const Gains& g = p.gains;
  return {g.kpm,
          g.kps,
          g.kdm,
          g.kds,
          g.kvm,
          g.kvs,
          g.kfm,
          p.master_fixture_N_per_m,
          p.slave_fixture_N_per_m};
}

std::array<double, kFields> values_of(const v1::ActiveParameters& a) {
  const v1::Gains& g = a.gains();
  return {g.kpm(),
          g.kps(),
          g.kdm(),
          g.kds(),
          g.kvm(),
          g.kvs(),
          g.kfm(),
          a.master_fixture_stiffness_n_per_m(),
          a.slave_fixture_stiffness_n_per_m()};
}

// The node computes its values from the ones sent (a ramp's last step is exact: w = 1), so
// equality is all but exact; the tolerance only absorbs rounding of a + 1 * (b - a).
bool same(double a, double b) {
  return std::abs(a - b) <= 1e-9 * std::max({1.0, std::abs(a), std::abs(b)});
}

bool same(const std::array<double, kFields>& a, const std::array<double, kFields>& b) {
  for (std::size_t i = 0; i < kFields; ++i) {
    if (!same(a[i], b[i])) return false;
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
  const std::array<double, kFields> v = values_of(active);
  const double progress = active.ramp_progress();
  // NaN progress is neither settled nor ramping sensibly: judged as a ramp, whose bounds no
  // non-finite value meets.
  const bool settled = progress >= 1.0;
  if (settled && it != approved_.end()) {
    // The change's own values, or a later approved change's (a newer target taken into a ramp
    // under way reaches the law with the older change number).
    for (auto later = it; later != approved_.end(); ++later) {
      if (same(v, values_of(later->second))) return out;
    }
    const std::array<double, kFields> want = values_of(it->second);
    for (std::size_t i = 0; i < kFields; ++i) {
      if (same(v[i], want[i])) continue;
      out.push_back(ParameterMismatch{kNames[i], v[i], want[i], id,
                                      fmt::format("{} {} in force under change {} (approved {})",
                                                  kNames[i], v[i], id, want[i])});
    }
    return out;
  }
  // Ramping (or an unknown change): each value within the range of approved values.
  for (std::size_t i = 0; i < kFields; ++i) {
    double lo = values_of(approved_.begin()->second)[i];
    double hi = lo;
    for (const auto& [approved_id, p] : approved_) {
      const double x = values_of(p)[i];
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    const double x = v[i];
    if (std::isfinite(x) && (x >= lo || same(x, lo)) && (x <= hi || same(x, hi))) continue;
    const double nearest = std::isfinite(x) && x < lo ? lo : hi;
    out.push_back(ParameterMismatch{
        kNames[i], x, nearest, id,
        fmt::format("{} {} in force (ramp {:.2f}) outside every approved value [{}, {}]", kNames[i],
                    x, progress, lo, hi)});
  }
  return out;
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
