#include "common/sim/human.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

namespace teleop::sim {

namespace {

void require(bool ok, const std::string& field, const char* what) {
  if (!ok) throw std::invalid_argument(field + " " + what);
}

}  // namespace

ForceProfile ForceProfile::constant(double value_N) {
  return {.kind = ProfileKind::kConstant, .value_N = value_N};
}

ForceProfile ForceProfile::ramp(double from_N, double to_N, double start_s, double duration_s) {
  return {.kind = ProfileKind::kRamp,
          .value_N = from_N,
          .to_N = to_N,
          .start_s = start_s,
          .duration_s = duration_s};
}

ForceProfile ForceProfile::sinusoid(double offset_N, double amplitude_N, double frequency_hz,
                                    double phase_rad) {
  return {.kind = ProfileKind::kSinusoid,
          .value_N = offset_N,
          .amplitude_N = amplitude_N,
          .frequency_hz = frequency_hz,
          .phase_rad = phase_rad};
}

ForceProfile ForceProfile::trace(std::vector<double> times_s, std::vector<double> values_N) {
  return {
      .kind = ProfileKind::kTrace, .times_s = std::move(times_s), .values_N = std::move(values_N)};
}

void ForceProfile::validate() const {
  const auto finite = [](double v) { return std::isfinite(v); };
  switch (kind) {
    case ProfileKind::kConstant:
      require(finite(value_N), "profile.value_N", "must be finite");
      break;
    case ProfileKind::kRamp:
      require(finite(value_N), "profile.value_N", "must be finite");
      require(finite(to_N), "profile.to_N", "must be finite");
      require(finite(start_s), "profile.start_s", "must be finite");
      require(finite(duration_s) && duration_s >= 0.0, "profile.duration_s",
              "must be >= 0 and finite");
      break;
    case ProfileKind::kSinusoid:
      require(finite(value_N), "profile.value_N", "must be finite");
      require(finite(amplitude_N), "profile.amplitude_N", "must be finite");
      require(finite(frequency_hz) && frequency_hz >= 0.0, "profile.frequency_hz",
              "must be >= 0 and finite");
      require(finite(phase_rad), "profile.phase_rad", "must be finite");
      break;
    case ProfileKind::kTrace:
      require(!times_s.empty(), "profile.times_s", "must not be empty");
      require(times_s.size() == values_N.size(), "profile.values_N",
              "must have as many entries as profile.times_s");
      for (std::size_t i = 0; i < times_s.size(); ++i) {
        require(finite(times_s[i]), "profile.times_s[" + std::to_string(i) + "]", "must be finite");
        require(finite(values_N[i]), "profile.values_N[" + std::to_string(i) + "]",
                "must be finite");
        if (i > 0) {
          require(times_s[i] > times_s[i - 1], "profile.times_s[" + std::to_string(i) + "]",
                  "must be strictly increasing");
        }
      }
      break;
  }
}

double ForceProfile::at(double t_s) const noexcept {
  switch (kind) {
    case ProfileKind::kConstant:
      return value_N;
    case ProfileKind::kRamp:
      if (t_s < start_s) return value_N;
      if (t_s >= start_s + duration_s) return to_N;
      return value_N + (to_N - value_N) * (t_s - start_s) / duration_s;
    case ProfileKind::kSinusoid:
      return value_N +
             amplitude_N * std::sin(2.0 * std::numbers::pi * frequency_hz * t_s + phase_rad);
    case ProfileKind::kTrace: {
      if (times_s.empty()) return 0.0;
      if (t_s <= times_s.front()) return values_N.front();
      if (t_s >= times_s.back()) return values_N.back();
      const auto hi = std::upper_bound(times_s.begin(), times_s.end(), t_s);
      const auto i = static_cast<std::size_t>(hi - times_s.begin());
      const double t0 = times_s[i - 1];
      const double t1 = times_s[i];
      return values_N[i - 1] + (values_N[i] - values_N[i - 1]) * (t_s - t0) / (t1 - t0);
    }
  }
  return 0.0;
}

MaliciousUser::MaliciousUser(const MaliciousUserParams& params) : params_(params) {
  const HumanBand& band = params.band;
  const int n = band.points_per_axis;
  require(n >= 2, "malicious_user.band.points_per_axis", "must be >= 2");
  require(std::isfinite(params.force_level_N), "malicious_user.force_level_N", "must be finite");
  require(std::isfinite(params.dwell_s) && params.dwell_s > 0.0, "malicious_user.dwell_s",
          "must be positive and finite");
  const double f = params.force_level_N;
  struct Axis {
    const char* name;
    double lo;
    double hi;
  };
  const Axis axes[3] = {
      {"mass_kg", band.mass_kg.lower.at(f), band.mass_kg.upper.at(f)},
      {"damping_Ns_per_m", band.damping_Ns_per_m.lower.at(f), band.damping_Ns_per_m.upper.at(f)},
      {"stiffness_N_per_m", band.stiffness_N_per_m.lower.at(f),
       band.stiffness_N_per_m.upper.at(f)}};
  for (const Axis& a : axes) {
    require(std::isfinite(a.lo) && std::isfinite(a.hi) && a.lo >= 0.0 && a.hi >= a.lo,
            std::string("malicious_user.band.") + a.name,
            "must give 0 <= lower <= upper at the force level");
  }
  const auto value = [&](const Axis& a, int i) {
    return a.lo + (a.hi - a.lo) * static_cast<double>(i) / static_cast<double>(n - 1);
  };
  const auto make = [&](int i, int j, int k) {
    return HumanImpedance{value(axes[0], i), value(axes[1], j), value(axes[2], k)};
  };
  const int ends[2] = {0, n - 1};
  for (const int i : ends) {
    for (const int j : ends) {
      for (const int k : ends) schedule_.push_back(make(i, j, k));
    }
  }
  const auto corner = [&](int i) { return i == 0 || i == n - 1; };
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < n; ++k) {
        if (corner(i) && corner(j) && corner(k)) continue;
        schedule_.push_back(make(i, j, k));
      }
    }
  }
}

std::size_t MaliciousUser::index_at(double t_s) const noexcept {
  if (!(t_s > 0.0)) return 0;
  // A hair of slack so that t = k dwell computed as a sum of periods lands on visit k.
  const double visits = std::floor(t_s / params_.dwell_s + 1e-9);
  return static_cast<std::size_t>(std::fmod(visits, static_cast<double>(schedule_.size())));
}

HumanParams HumanParams::malicious_pushing(const HumanBand& band, double force_level_N,
                                           double dwell_s) {
  HumanParams p;
  p.profile = ForceProfile::constant(force_level_N);
  p.malicious = MaliciousUserParams{band, force_level_N, dwell_s};
  return p;
}

Human::Human(HumanParams params) : params_(std::move(params)) {
  params_.profile.validate();
  const HumanImpedance& z = params_.impedance;
  require(std::isfinite(z.mass_kg) && z.mass_kg >= 0.0, "human.impedance.mass_kg",
          "must be >= 0 and finite");
  require(std::isfinite(z.damping_Ns_per_m) && z.damping_Ns_per_m >= 0.0,
          "human.impedance.damping_Ns_per_m", "must be >= 0 and finite");
  require(std::isfinite(z.stiffness_N_per_m) && z.stiffness_N_per_m >= 0.0,
          "human.impedance.stiffness_N_per_m", "must be >= 0 and finite");
  if (params_.malicious) malicious_.emplace(*params_.malicious);
}

PeriodForce Human::exogenous(double t_s, double period_s) const noexcept {
  const double f0 = params_.profile.at(t_s);
  if (params_.sampling == ProfileSampling::kZeroOrderHold) return {f0, 0.0};
  return {f0, (params_.profile.at(t_s + period_s) - f0) / period_s};
}

HumanImpedance Human::impedance_at(double t_s) const noexcept {
  if (malicious_) return malicious_->impedance(malicious_->index_at(t_s));
  return params_.impedance;
}

std::optional<std::size_t> Human::malicious_index_at(double t_s) const noexcept {
  if (!malicious_) return std::nullopt;
  return malicious_->index_at(t_s);
}

}  // namespace teleop::sim
