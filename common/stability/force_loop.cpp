#include "common/stability/force_loop.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <initializer_list>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "common/stability/routh_hurwitz.hpp"

namespace teleop::stability {
namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();
// Limits beyond this are reported as absent: no device renders a 1e9 N/m or 1e9 Ns/m
// environment, and the search needs a finite end.
constexpr double kSearchMax = 1e9;
constexpr double kBisectionTolerance = 1e-9;  // relative
// Lowest point of the fallback geometric scan; the crossing candidates reach below it.
constexpr double kScanStart = 1e-6;
// Margin on the first-order root error estimate, so that only a clear disagreement between
// the roots and the Routh array overrides the array.
constexpr double kRootSafety = 1e3;

[[nodiscard]] std::string str(double value) {
  std::ostringstream os;
  os << value;
  return os.str();
}

[[nodiscard]] std::invalid_argument field_error(const char* field, const std::string& what) {
  return std::invalid_argument(std::string("force_loop.") + field + " must be " + what);
}

void require_finite(const char* field, double value) {
  if (!std::isfinite(value)) throw field_error(field, "finite, got " + str(value));
}

void require_positive(const char* field, double value) {
  require_finite(field, value);
  if (!(value > 0.0)) throw field_error(field, "> 0, got " + str(value));
}

void require_non_negative(const char* field, double value) {
  require_finite(field, value);
  if (!(value >= 0.0)) throw field_error(field, ">= 0, got " + str(value));
}

// Descending coefficients with absolute error bounds for the Routh array.
struct Coefficients {
  std::vector<double> value{};
  std::vector<double> error{};
};

// Each coefficient is a sum of products of at most three inputs (T = 1/rate is itself rounded):
// at most four roundings per term and four in the sum. The bound is relative to the magnitudes
// that formed it, which is what matters when the terms cancel near a stability boundary.
void push_sum(Coefficients& c, std::initializer_list<double> terms) {
  double sum = 0.0;
  double magnitude = 0.0;
  for (const double term : terms) {
    sum += term;
    magnitude += std::abs(term);
  }
  c.value.push_back(sum);
  c.error.push_back(8.0 * kEps * magnitude);
}

// The loop's parameters in the paper's symbols: mass M, damping B, gains K_p and K_i, the
// environment's K_v and B_v, the sample period T.
struct Symbols {
  double m, b, kp, ki, kv, bv, t;
};

[[nodiscard]] Symbols symbols(const ForceLoopParams& p) {
  return {p.mass_kg,
          p.damping_Ns_per_m,
          p.kp,
          p.ki,
          p.environment_stiffness_N_per_m,
          p.environment_damping_Ns_per_m,
          1.0 / p.sample_rate_hz};
}

// Expanded by hand from (M s^2 + B s)(2 + T s) [* s] + (K_p [s] + K_i)(K_v + B_v s)(2 - T s).
// Does not validate; may contain non-finite values for absurd inputs.
[[nodiscard]] Coefficients build(const ForceLoopParams& p) {
  const auto [m, b, kp, ki, kv, bv, t] = symbols(p);
  Coefficients c;
  if (ki > 0.0) {
    push_sum(c, {m * t});
    push_sum(c, {2.0 * m, b * t, -kp * bv * t});
    push_sum(c, {2.0 * b, 2.0 * kp * bv, -kp * kv * t, -ki * bv * t});
    push_sum(c, {2.0 * kp * kv, 2.0 * ki * bv, -ki * kv * t});
    push_sum(c, {2.0 * ki * kv});
  } else {
    push_sum(c, {m * t});
    push_sum(c, {2.0 * m, b * t, -kp * bv * t});
    push_sum(c, {2.0 * b, 2.0 * kp * bv, -kp * kv * t});
    push_sum(c, {2.0 * kp * kv});
  }
  return c;
}

[[nodiscard]] bool all_finite(const std::vector<double>& values) {
  return std::all_of(values.begin(), values.end(), [](double v) { return std::isfinite(v); });
}

// The roots' own verdict: a root counts as signed only when its real part exceeds a first-order
// error estimate, eps * sum |a_i| |r|^i / |p'(r)| (large near repeated roots, as it should be).
[[nodiscard]] Verdict roots_verdict(const std::vector<double>& a,
                                    const std::vector<std::complex<double>>& roots) {
  bool uncertain = false;
  for (const std::complex<double>& r : roots) {
    std::complex<double> value{0.0, 0.0};
    std::complex<double> derivative{0.0, 0.0};
    double magnitude = 0.0;
    const double modulus = std::abs(r);
    for (const double ai : a) {
      derivative = derivative * r + value;
      value = value * r + ai;
      magnitude = magnitude * modulus + std::abs(ai);
    }
    const double slope = std::abs(derivative);
    const double bound = slope > 0.0 ? kRootSafety * kEps * magnitude / slope
                                     : std::numeric_limits<double>::infinity();
    if (r.real() > bound) return Verdict::kUnstable;
    if (r.real() >= -bound) uncertain = true;
  }
  return uncertain ? Verdict::kUncertain : Verdict::kStable;
}

// The Routh array decides; the roots can only veto it. Near the boundary the roots are the less
// accurate of the two, so their doubt does not override a definite array.
[[nodiscard]] Verdict reconcile(Verdict routh, Verdict roots) {
  if (routh == Verdict::kUncertain || roots == Verdict::kUncertain || routh == roots) {
    return routh;
  }
  return Verdict::kUncertain;
}

struct Limit {
  std::optional<double> value{};
  std::string reason{};
};

// ---- P controller: the paper's closed forms -------------------------------------------------

[[nodiscard]] Limit p_kv_limit(const ForceLoopParams& p) {
  const auto [m, b, kp, ki, kv, bv, t] = symbols(p);
  const double a2 = 2.0 * m + b * t - kp * bv * t;  // eq. 14 is a2 > 0
  if (!(a2 > 0.0)) {
    return {std::nullopt, "B_v = " + str(bv) +
                              " Ns/m is not below eq. 14's bound (2M + B T)/(K_p T) = " +
                              str((2.0 * m + b * t) / (kp * t)) + " Ns/m: unstable for every K_v"};
  }
  const double damping = b + kp * bv;
  if (!(damping > 0.0)) {
    return {std::nullopt, "B + K_p B_v = " + str(damping) +
                              " Ns/m is not positive: a_1 < 0, unstable for every K_v > 0"};
  }
  // Eq. 15 in factored form, Nom_p = 2 a2 (B + K_p B_v) and Denom_p = K_p T (a2 + 2M): the
  // printed expanded sums cancel near eq. 14's bound.
  return {2.0 * a2 * damping / (kp * t * (a2 + 2.0 * m)), ""};
}

[[nodiscard]] Limit p_bv_limit(const ForceLoopParams& p) {
  const auto [m, b, kp, ki, kv, bv, t] = symbols(p);
  if (!(kv > 0.0)) {
    return {std::nullopt,
            "K_v = " + str(kv) + " N/m: a_0 = 2 K_p K_v is not positive, no B_v is stable"};
  }
  // Nom_p - K_v Denom_p = a2 a1 - a3 a0 as a concave quadratic in B_v, q(B_v) = -qa B_v^2 +
  // qb B_v + qc. With a3, a0 > 0 the cubic is stable iff a2 > 0 (eq. 14) and q > 0 (eq. 15).
  const double qa = 2.0 * kp * kp * t;
  const double qb = 4.0 * kp * m + kv * kp * kp * t * t;
  const double qc = 4.0 * b * m + 2.0 * b * b * t - kv * kp * t * (4.0 * m + b * t);
  const double eq14 = (2.0 * m + b * t) / (kp * t);
  const double discriminant = qb * qb + 4.0 * qa * qc;
  if (!(discriminant > 0.0)) {
    return {std::nullopt, "K_v = " + str(kv) + " N/m violates eq. 15 for every B_v"};
  }
  // The larger root; qb > 0, so no cancellation. The smaller from the product of the roots,
  // -qc/qa, for the same reason. q(eq. 14 bound) = -a3 a0 < 0, so eq. 14 never binds when
  // B_v = 0 is stable; the min only guards rounding.
  const double upper = (qb + std::sqrt(discriminant)) / (2.0 * qa);
  if (!(eq14 > 0.0 && qc > 0.0)) {
    const double lower = -qc / (qa * upper);
    const double top = std::min(upper, eq14);
    return {
        std::nullopt,
        "unstable at B_v = 0 with K_v = " + str(kv) + " N/m, so no stable range [0, B_v]" +
            (lower < top ? "; stable only for B_v in (" + str(lower) + ", " + str(top) + ") Ns/m"
                         : "")};
  }
  return {std::min(upper, eq14), ""};
}

// ---- PI controller: complete Routh-Hurwitz, searched ----------------------------------------

enum class Axis { kStiffness, kDamping };

[[nodiscard]] ForceLoopParams with_value(ForceLoopParams p, Axis axis, double x) {
  (axis == Axis::kStiffness ? p.environment_stiffness_N_per_m : p.environment_damping_Ns_per_m) = x;
  return p;
}

[[nodiscard]] bool stable_at(const ForceLoopParams& p, Axis axis, double x) {
  const Coefficients c = build(with_value(p, axis, x));
  // Overflow cannot be certified stable.
  if (!all_finite(c.value) || !all_finite(c.error)) return false;
  return routh_hurwitz(c.value, c.error) == Verdict::kStable;
}

using PolyX = std::vector<double>;  // ascending powers of the swept parameter

[[nodiscard]] PolyX mul(const PolyX& a, const PolyX& b) {
  PolyX out(a.size() + b.size() - 1, 0.0);
  for (std::size_t i = 0; i < a.size(); ++i) {
    for (std::size_t j = 0; j < b.size(); ++j) out[i + j] += a[i] * b[j];
  }
  return out;
}

[[nodiscard]] PolyX sub(PolyX a, const PolyX& b) {
  if (a.size() < b.size()) a.resize(b.size(), 0.0);
  for (std::size_t i = 0; i < b.size(); ++i) a[i] -= b[i];
  return a;
}

// Values of the swept parameter where a root may cross the imaginary axis: at s = 0 (a_0 = 0),
// through infinity (a_n = 0) or in a pair +-jw, where the Hurwitz determinant D_(n-1) vanishes
// (Orlando: D_(n-1) is proportional to the product of all pairwise root sums). Stability is
// constant between consecutive candidates, so probing each gap makes the scan exact.
[[nodiscard]] std::vector<double> crossing_candidates(const ForceLoopParams& p, Axis axis) {
  // The coefficients are affine in K_v and in B_v.
  const std::vector<double> at0 = build(with_value(p, axis, 0.0)).value;
  const std::vector<double> at1 = build(with_value(p, axis, 1.0)).value;
  if (!all_finite(at0) || !all_finite(at1)) return {};
  const std::size_t n = at0.size() - 1;
  std::vector<PolyX> a(n + 1);  // a[k]: coefficient of s^k
  for (std::size_t k = 0; k <= n; ++k) a[k] = {at0[n - k], at1[n - k] - at0[n - k]};

  std::vector<PolyX> conditions{a[0], a[n]};
  if (n == 3) {
    conditions.push_back(sub(mul(a[2], a[1]), mul(a[3], a[0])));
  } else if (n == 4) {
    const PolyX a1a1 = mul(a[1], a[1]);
    conditions.push_back(
        sub(sub(mul(mul(a[3], a[2]), a[1]), mul(a[4], a1a1)), mul(mul(a[3], a[3]), a[0])));
  }
  std::vector<double> candidates;
  for (const PolyX& condition : conditions) {
    if (!all_finite(condition) ||
        std::all_of(condition.begin(), condition.end(), [](double v) { return v == 0.0; })) {
      continue;
    }
    const std::vector<double> descending(condition.rbegin(), condition.rend());
    for (const std::complex<double>& r : polynomial_roots(descending)) {
      // Generous on "real": an extra candidate costs one probe, a missed one a wrong limit.
      if (std::abs(r.imag()) <= 1e-6 * std::abs(r) && r.real() > 0.0 && r.real() < kSearchMax) {
        candidates.push_back(r.real());
      }
    }
  }
  std::sort(candidates.begin(), candidates.end());
  return candidates;
}

[[nodiscard]] Limit search_limit(const ForceLoopParams& p, Axis axis) {
  const bool stiffness = axis == Axis::kStiffness;
  const std::string name = stiffness ? "K_v" : "B_v";
  const std::string unit = stiffness ? " N/m" : " Ns/m";

  // A geometric scan, with every gap between crossing candidates probed so that no unstable
  // window can fall between two scan points.
  std::vector<double> grid;
  if (!stiffness) grid.push_back(0.0);  // B_v's range is [0, B_v]; K_v's is (0, K_v]
  for (double x = kScanStart; x < kSearchMax; x *= 2.0) grid.push_back(x);
  grid.push_back(kSearchMax);
  double previous = 0.0;
  for (const double c : crossing_candidates(p, axis)) {
    grid.push_back(previous + (c - previous) / 2.0);
    grid.push_back(c);
    previous = c;
  }
  std::sort(grid.begin(), grid.end());
  grid.erase(std::unique(grid.begin(), grid.end()), grid.end());
  if (stiffness) {
    grid.erase(std::remove_if(grid.begin(), grid.end(), [](double x) { return !(x > 0.0); }),
               grid.end());
  }

  // Bisection keeps the stable side, so a reported limit is itself a stable value.
  const auto boundary = [&](double stable_x, double unstable_x) {
    while (std::abs(unstable_x - stable_x) >
           kBisectionTolerance * std::max(std::abs(stable_x), std::abs(unstable_x))) {
      const double mid = stable_x + (unstable_x - stable_x) / 2.0;
      (stable_at(p, axis, mid) ? stable_x : unstable_x) = mid;
    }
    return stable_x;
  };
  const auto first_where = [&](std::size_t from, bool stable) {
    while (from < grid.size() && stable_at(p, axis, grid[from]) != stable) ++from;
    return from;
  };

  const std::size_t first_stable = first_where(0, true);
  const std::size_t end =
      first_stable < grid.size() ? first_where(first_stable + 1, false) : grid.size();
  if (first_stable == 0) {
    if (end == grid.size()) {
      return {std::nullopt, "stable for every " + name + " up to " + str(kSearchMax) + unit +
                                ": no finite " + name + " limit"};
    }
    return {boundary(grid[end - 1], grid[end]), ""};
  }
  // Not stable at the start of the range: no limit in the sense asked for, but the user who
  // configured an unstable point wants to know where a stable range is, if anywhere.
  const std::string start =
      stiffness ? "unstable already for small K_v (K_v = " + str(grid.front()) +
                      " N/m), so no stable range (0, K_v]"
                : "unstable at B_v = 0 with K_v = " + str(p.environment_stiffness_N_per_m) +
                      " N/m, so no stable range [0, B_v]";
  if (first_stable == grid.size()) {
    return {std::nullopt, start + "; no stable " + name + " up to " + str(kSearchMax) + unit};
  }
  const double lower = boundary(grid[first_stable], grid[first_stable - 1]);
  const std::string upper =
      end < grid.size() ? str(boundary(grid[end - 1], grid[end])) : str(kSearchMax) + "+";
  return {std::nullopt, start + "; the first stable range is " + name + " in (" + str(lower) +
                            ", " + upper + ")" + unit};
}

}  // namespace

void validate_force_loop_params(const ForceLoopParams& params) {
  require_positive("mass_kg", params.mass_kg);
  require_finite("damping_Ns_per_m", params.damping_Ns_per_m);
  require_non_negative("kp", params.kp);
  require_non_negative("ki", params.ki);
  require_positive("sample_rate_hz", params.sample_rate_hz);
  require_finite("environment_stiffness_N_per_m", params.environment_stiffness_N_per_m);
  require_finite("environment_damping_Ns_per_m", params.environment_damping_Ns_per_m);
  if (params.sensor_average_samples < 1) {
    throw field_error("sensor_average_samples",
                      ">= 1, got " + std::to_string(params.sensor_average_samples));
  }
}

std::vector<double> characteristic_polynomial(const ForceLoopParams& params) {
  validate_force_loop_params(params);
  return build(params).value;
}

ForceLoopResult analyze_force_loop(const ForceLoopParams& params) {
  validate_force_loop_params(params);
  const Coefficients c = build(params);
  if (!all_finite(c.value) || !all_finite(c.error)) {
    throw std::invalid_argument(
        "force_loop: the characteristic polynomial overflows for these parameters");
  }

  ForceLoopResult result;
  result.proportional_integral = params.ki > 0.0;
  result.characteristic_polynomial = c.value;
  result.roots = polynomial_roots(c.value);
  result.verdict = reconcile(routh_hurwitz(c.value, c.error), roots_verdict(c.value, result.roots));
  result.stable = result.verdict == Verdict::kStable;

  if (params.kp == 0.0 && params.ki == 0.0) {
    // G_c = 0: the characteristic polynomial is the open loop's denominator, whose s = 0 pole
    // (the free device) is marginal whatever the environment.
    result.limit_reason =
        "kp = 0 and ki = 0: no force feedback, the force loop is open and sets no K_v or B_v "
        "limit";
    return result;
  }
  const Limit bv =
      result.proportional_integral ? search_limit(params, Axis::kDamping) : p_bv_limit(params);
  const Limit kv =
      result.proportional_integral ? search_limit(params, Axis::kStiffness) : p_kv_limit(params);
  result.bv_limit_Ns_per_m = bv.value;
  result.kv_limit_N_per_m = kv.value;
  if (params.kp > 0.0) {
    const double t = 1.0 / params.sample_rate_hz;
    result.bv_limit_eq14_Ns_per_m =
        (2.0 * params.mass_kg + params.damping_Ns_per_m * t) / (params.kp * t);
  }
  if (!bv.value) result.limit_reason = "B_v limit: " + bv.reason;
  if (!kv.value) {
    result.limit_reason +=
        (result.limit_reason.empty() ? "" : "; ") + std::string("K_v limit: ") + kv.reason;
  }
  return result;
}

}  // namespace teleop::stability
