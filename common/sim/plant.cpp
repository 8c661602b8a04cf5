#include "common/sim/plant.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include "common/sim/switch_search.hpp"

namespace teleop::sim {

namespace {

using Mat4 = std::array<std::array<long double, 4>, 4>;

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 c{};
  for (std::size_t i = 0; i < 4; ++i) {
    for (std::size_t k = 0; k < 4; ++k) {
      for (std::size_t j = 0; j < 4; ++j) {
        c[i][j] += a[i][k] * b[k][j];
      }
    }
  }
  return c;
}

long double max_abs(const Mat4& a) {
  long double m = 0.0L;
  for (const auto& row : a) {
    for (const long double e : row) m = std::max(m, std::fabs(e));
  }
  return m;
}

// exp(A) by scaling to ||A|| <= 1/4, a Taylor series to long double round-off, then squaring
// (as in stability/zoh.cpp, one size up for the ramp input).
Mat4 expm(const Mat4& a) {
  long double norm = 0.0L;
  for (const auto& row : a) {
    long double sum = 0.0L;
    for (const long double e : row) sum += std::fabs(e);
    norm = std::max(norm, sum);
  }
  int squarings = 0;
  if (norm > 0.25L) squarings = static_cast<int>(std::ceil(std::log2(norm / 0.25L)));
  const long double scale = std::ldexp(1.0L, -squarings);
  Mat4 scaled{};
  Mat4 result{};
  Mat4 term{};
  for (std::size_t i = 0; i < 4; ++i) {
    for (std::size_t j = 0; j < 4; ++j) scaled[i][j] = a[i][j] * scale;
    result[i][i] = 1.0L;
    term[i][i] = 1.0L;
  }
  for (int n = 1; n < 40; ++n) {
    term = multiply(term, scaled);
    for (auto& row : term) {
      for (long double& e : row) e /= static_cast<long double>(n);
    }
    for (std::size_t i = 0; i < 4; ++i) {
      for (std::size_t j = 0; j < 4; ++j) result[i][j] += term[i][j];
    }
    if (max_abs(term) <= 1e-22L * max_abs(result)) break;
  }
  for (int i = 0; i < squarings; ++i) result = multiply(result, result);
  return result;
}

// The augmented state [x, v, g, g'] of M x'' + B x' + K x = g(t), g linear in t. Stored as
// increments driven by the net force n = g - K x (e00 = 1 - K e02 and e10 = -K e12 exactly: a
// device held at x by g = K x stays there), so that a device leaving rest or a wall moves by
// what the small net force does, not by the rounding of K x against g.
Plant::Propagator propagator(double mass_kg, double damping_Ns_per_m, double stiffness_N_per_m,
                             double tau_s) {
  const long double m = mass_kg;
  const long double t = tau_s;
  Mat4 a{};
  a[0][1] = t;
  a[1][0] = -static_cast<long double>(stiffness_N_per_m) / m * t;
  a[1][1] = -static_cast<long double>(damping_Ns_per_m) / m * t;
  a[1][2] = t / m;
  a[2][3] = t;
  const Mat4 e = expm(a);
  Plant::Propagator p;
  for (std::size_t j = 0; j < 3; ++j) {
    p.x[j] = static_cast<double>(e[0][j + 1]);
    p.v[j] = static_cast<double>(e[1][j + 1]);
  }
  return p;
}

struct Next {
  double x;
  double v;
};

// net: the net force at the start (everything but damping), ramp: its input slope.
inline Next propagate(const Plant::Propagator& p, double x, double v, double net,
                      double ramp) noexcept {
  return {x + (p.x[0] * v + p.x[1] * net + p.x[2] * ramp),
          p.v[0] * v + p.v[1] * net + p.v[2] * ramp};
}

// Builds the message only on failure: validate() runs on the RT path when the malicious user
// changes impedance, and must not allocate there.
void require(bool ok, const char* field, const char* what) {
  if (!ok) throw std::invalid_argument(std::string("plant: ") + field + " " + what);
}

constexpr std::uint64_t kTicksPerPeriod = std::uint64_t{1} << Plant::kTickBits;

}  // namespace

const char* to_string(SteppingMethod method) noexcept {
  switch (method) {
    case SteppingMethod::kSubSteps:
      return "substeps";
    case SteppingMethod::kEventLocation:
      return "event_location";
  }
  return "unknown";
}

Plant::Plant(const PlantParams& params, std::chrono::nanoseconds period)
    : params_(params), period_s_(std::chrono::duration<double>(period).count()) {
  validate();
  rebuild();
}

void Plant::validate() const {
  const auto finite_nonneg = [](double v) { return std::isfinite(v) && v >= 0.0; };
  require(std::isfinite(period_s_) && period_s_ > 0.0, "period", "must be positive");
  require(std::isfinite(params_.device.mass_kg) && params_.device.mass_kg > 0.0, "device.mass_kg",
          "must be positive and finite");
  require(finite_nonneg(params_.device.damping_Ns_per_m), "device.damping_Ns_per_m",
          "must be >= 0 and finite");
  require(finite_nonneg(params_.coulomb_friction_N), "coulomb_friction_N",
          "must be >= 0 and finite");
  require(finite_nonneg(params_.human.mass_kg), "human.mass_kg", "must be >= 0 and finite");
  require(finite_nonneg(params_.human.damping_Ns_per_m), "human.damping_Ns_per_m",
          "must be >= 0 and finite");
  require(finite_nonneg(params_.human.stiffness_N_per_m), "human.stiffness_N_per_m",
          "must be >= 0 and finite");
  const Environment& env = params_.environment;
  require(std::isfinite(env.position_m), "environment.position_m", "must be finite");
  if (env.kind == EnvironmentKind::kTissue) {
    require(finite_nonneg(env.stiffness_N_per_m), "environment.stiffness_N_per_m",
            "must be >= 0 and finite");
    require(finite_nonneg(env.damping_Ns_per_m), "environment.damping_Ns_per_m",
            "must be >= 0 and finite");
  }
  require(params_.substeps >= 1 && params_.substeps <= (1 << 20), "substeps",
          "must be in [1, 2^20]");
}

void Plant::rebuild() {
  const Environment& env = params_.environment;
  const int modes = tissue() ? 2 : 1;
  for (int c = 0; c < modes; ++c) {
    ModeCache& cache = cache_[static_cast<std::size_t>(c)];
    const bool contact = c == 1;
    cache.mass_kg = params_.device.mass_kg + params_.human.mass_kg;
    cache.damping_Ns_per_m = params_.device.damping_Ns_per_m + params_.human.damping_Ns_per_m +
                             (contact ? env.damping_Ns_per_m : 0.0);
    cache.stiffness_N_per_m =
        params_.human.stiffness_N_per_m + (contact ? env.stiffness_N_per_m : 0.0);
    const double m = cache.mass_kg;
    const double b = cache.damping_Ns_per_m;
    const double k = cache.stiffness_N_per_m;
    if (params_.method == SteppingMethod::kSubSteps) {
      cache.substep = propagator(m, b, k, period_s_ / params_.substeps);
    } else {
      for (std::size_t level = 0; level <= kTickBits; ++level) {
        cache.dyadic[level] = propagator(m, b, k, std::ldexp(period_s_, -static_cast<int>(level)));
      }
      // |lambda| <= B/M + sqrt(K/M): chunks short enough that an event predicate (a linear
      // function of the state) does not cross twice unseen except for grazing.
      const double fastest = b / m + std::sqrt(k / m);
      int level = 0;
      while (level < kTickBits && fastest * std::ldexp(period_s_, -level) > 0.25) ++level;
      cache.guard_level = level;
    }
  }
}

template <typename T>
void Plant::change(T& field, T value) {
  T old = std::move(field);
  field = std::move(value);
  try {
    validate();
  } catch (...) {
    field = std::move(old);
    throw;
  }
  rebuild();
}

void Plant::set_human_impedance(const HumanImpedance& human) { change(params_.human, human); }

void Plant::set_period(std::chrono::nanoseconds period) {
  change(period_s_, std::chrono::duration<double>(period).count());
}

void Plant::set_method(SteppingMethod method, int substeps) {
  PlantParams next = params_;
  next.method = method;
  next.substeps = substeps;
  change(params_, std::move(next));
}

void Plant::reset(const PlantState& state) noexcept {
  state_ = state;
  output_ = {};
}

bool Plant::tissue() const noexcept { return params_.environment.kind == EnvironmentKind::kTissue; }

bool Plant::wall() const noexcept {
  return params_.environment.kind == EnvironmentKind::kRigidWall;
}

bool Plant::tissue_contact(double x, double v) const noexcept {
  if (!tissue()) return false;
  const Environment& env = params_.environment;
  const double depth = x - env.position_m;
  return depth > 0.0 && env.stiffness_N_per_m * depth + env.damping_Ns_per_m * v > 0.0;
}

double Plant::net_force(double x, double tau, bool contact, const Input& in) const noexcept {
  const Environment& env = params_.environment;
  return in.actuator_N + in.exogenous_N + in.slope_N_per_s * tau -
         params_.human.stiffness_N_per_m * x -
         (contact ? env.stiffness_N_per_m * (x - env.position_m) : 0.0);
}

Plant::Mode Plant::classify(double tau, const Input& in) noexcept {
  Mode mode;
  double& x = state_.position_m;
  double& v = state_.velocity_m_per_s;
  const double fc = params_.coulomb_friction_N;
  if (wall()) {
    const double pw = params_.environment.position_m;
    if (x > pw || (x == pw && v >= 0.0)) {
      // Perfectly plastic impact: the velocity into the wall is lost.
      x = pw;
      v = 0.0;
      mode.at_wall = true;
    }
  }
  if (v == 0.0 && (fc > 0.0 || mode.at_wall)) {
    mode.contact = tissue_contact(x, 0.0);
    const double p = net_force(x, tau, mode.contact, in);
    const double upper = mode.at_wall ? std::numeric_limits<double>::infinity() : fc;
    if (p >= -fc && p <= upper) {
      mode.resting = true;
      return mode;
    }
    mode.at_wall = false;
    mode.sign = fc > 0.0 ? (p > 0.0 ? 1 : -1) : 0;
    return mode;
  }
  mode.sign = fc > 0.0 ? (v > 0.0 ? 1 : -1) : 0;
  mode.contact = tissue_contact(x, v);
  return mode;
}

bool Plant::valid(const Mode& mode, double x, double v) const noexcept {
  if (mode.sign != 0 && static_cast<double>(mode.sign) * v <= 0.0) return false;
  if (tissue() && tissue_contact(x, v) != mode.contact) return false;
  // On the wall moving away is fine: a device leaving it starts at x = p_w exactly.
  const double pw = params_.environment.position_m;
  if (wall() && (x > pw || (x == pw && v > 0.0))) return false;
  return true;
}

double Plant::net_drive(const Mode& mode, double x, double tau, const Input& in) const noexcept {
  return net_force(x, tau, mode.contact, in) -
         static_cast<double>(mode.sign) * params_.coulomb_friction_N;
}

double Plant::acceleration(const Mode& mode, double x, double v, double tau,
                           const Input& in) const noexcept {
  const ModeCache& cache = cache_[mode.contact ? 1 : 0];
  return (net_drive(mode, x, tau, in) - cache.damping_Ns_per_m * v) / cache.mass_kg;
}

bool Plant::may_hide_event(const Mode& mode, double tau0, double x0, double v0, double tau1,
                           double x1, double v1, const Input& in) const noexcept {
  const double dt = tau1 - tau0;
  const double a0 = acceleration(mode, x0, v0, tau0, in);
  const double a1 = acceleration(mode, x1, v1, tau1, in);
  if (mode.sign != 0) {
    const auto s = static_cast<double>(mode.sign);
    if (may_dip(s * v0, s * a0, s * v1, s * a1, dt)) return true;
  }
  // Over a guard interval the acceleration is (close to) monotone: if it keeps its sign the
  // velocity is monotone, so a position is monotone (the ends tell) or has one extremum
  // (may_dip is complete); only where the acceleration changes sign can a position turn twice,
  // and there the travel bound decides, |v| <= (|v0| + |v1| + a_max dt) / 2. Position bounds
  // alone would crawl: a device leaving a wall stays within an ulp of it for many ticks.
  const bool v_monotone = a0 * a1 >= 0.0;
  const double a_max = std::max(std::abs(a0), std::abs(a1));
  const double v_max = 0.5 * (std::abs(v0) + std::abs(v1) + a_max * dt);
  // g = p - x, so g' = -v.
  const auto gap_may_close = [&](double g0, double g1) {
    if (v_monotone) return v0 * v1 < 0.0 && may_dip(g0, -v0, g1, -v1, dt);
    return may_reach(g0, g1, v_max, dt);
  };
  const Environment& env = params_.environment;
  const double p = env.position_m;
  if (wall()) return gap_may_close(p - x0, p - x1);
  if (tissue()) {
    if (mode.contact) {
      const double k = env.stiffness_N_per_m;
      const double b = env.damping_Ns_per_m;
      const double c0 = k * (x0 - p) + b * v0;
      const double c1 = k * (x1 - p) + b * v1;
      const double d0 = k * v0 + b * a0;
      const double d1 = k * v1 + b * a1;
      if (v_monotone) return d0 * d1 < 0.0 && may_dip(c0, d0, c1, d1, dt);
      return may_reach(c0, c1, k * v_max + b * a_max, dt);
    }
    if (x0 <= p && x1 <= p) return gap_may_close(p - x0, p - x1);
  }
  return false;
}

void Plant::correct(const Mode& mode) noexcept {
  double& x = state_.position_m;
  double& v = state_.velocity_m_per_s;
  if (wall() && x > params_.environment.position_m) {
    x = params_.environment.position_m;
    v = 0.0;
  }
  if (mode.sign != 0 && static_cast<double>(mode.sign) * v < 0.0) v = 0.0;
}

const PlantOutput& Plant::step(double actuator_force_N, double exogenous_force_N,
                               double exogenous_slope_N_per_s) noexcept {
  const Input in{actuator_force_N, exogenous_force_N, exogenous_slope_N_per_s};
  output_.events = 0;
  output_.event_limit_hit = false;
  if (params_.method == SteppingMethod::kSubSteps) {
    step_substeps(in);
  } else {
    step_events(in);
  }
  finish(in);
  return output_;
}

void Plant::step_substeps(const Input& in) noexcept {
  const int n = params_.substeps;
  const double h = period_s_ / n;
  for (int j = 0; j < n; ++j) {
    const double tau = h * j;
    const Mode mode = classify(tau, in);
    if (mode.resting) continue;
    const double x = state_.position_m;
    const Next next = propagate(cache_[mode.contact ? 1 : 0].substep, x, state_.velocity_m_per_s,
                                net_drive(mode, x, tau, in), in.slope_N_per_s);
    state_.position_m = next.x;
    state_.velocity_m_per_s = next.v;
    correct(mode);
  }
}

void Plant::step_events(const Input& in) noexcept {
  const double tick_s = std::ldexp(period_s_, -kTickBits);
  const double fc = params_.coulomb_friction_N;
  const double ramp = in.slope_N_per_s;
  double& x = state_.position_m;
  double& v = state_.velocity_m_per_s;
  EventClock clock{.end = kTicksPerPeriod};
  std::uint64_t& t = clock.t;
  const std::uint64_t end = clock.end;
  int events = 0;
  const auto count_event = [&]() {
    ++events;
    if (events >= kMaxEventsPerStep) clock.frozen = true;
  };
  const auto seconds = [&](std::uint64_t ticks) { return static_cast<double>(ticks) * tick_s; };
  Next next{};
  Next past{};
  while (t < end) {
    const Mode mode = classify(seconds(t), in);
    if (mode.resting) {
      // P(tau) is linear within the step: leave rest when it first passes a friction bound.
      const double p = net_force(x, seconds(t), mode.contact, in);
      double wait_s = std::numeric_limits<double>::infinity();
      if (ramp > 0.0 && !mode.at_wall) {
        wait_s = (fc - p) / ramp;
      } else if (ramp < 0.0) {
        wait_s = (-fc - p) / ramp;
      }
      if (clock.frozen || !(wait_s < seconds(end - t))) break;
      const auto ticks = static_cast<std::uint64_t>(std::max(0.0, wait_s) / tick_s) + 1;
      t = std::min(end, t + ticks);
      count_event();
      continue;
    }
    const ModeCache& cache = cache_[mode.contact ? 1 : 0];
    const std::uint64_t guard = std::uint64_t{1} << (kTickBits - cache.guard_level);
    const SwitchSearchOps ops{
        [&](std::uint64_t t0, std::uint64_t size, Next& out) {  // advance
          const auto level = static_cast<std::size_t>(kTickBits - std::countr_zero(size));
          out = propagate(cache.dyadic[level], x, v, net_drive(mode, x, seconds(t0), in), ramp);
        },
        [&](std::uint64_t /*t1*/, const Next& s) { return valid(mode, s.x, s.v); },
        [&](std::uint64_t t0, std::uint64_t t1, const Next& s) {  // may_hide
          return may_hide_event(mode, seconds(t0), x, v, seconds(t1), s.x, s.v, in);
        },
        [&](const Next& s) {  // accept
          x = s.x;
          v = s.v;
        },
        [&]() { correct(mode); },  // on_frozen
        [&]() {                    // on_switch
          if (fc > 0.0 && mode.sign != 0 && static_cast<double>(mode.sign) * v <= 0.0) v = 0.0;
        }};
    if (advance_to_switch<kMaxWorkPerStep>(clock, guard, next, past, ops)) count_event();
  }
  output_.events = events;
  output_.event_limit_hit = clock.frozen;
  total_events_ += static_cast<std::uint64_t>(events);
}

void Plant::finish(const Input& in) noexcept {
  const Mode mode = classify(period_s_, in);
  const double x = state_.position_m;
  const double v = state_.velocity_m_per_s;
  const Environment& env = params_.environment;
  output_.resting = mode.resting;
  output_.in_contact = mode.contact || (mode.resting && mode.at_wall);
  if (mode.resting) {
    output_.acceleration_m_per_s2 = 0.0;
  } else {
    output_.acceleration_m_per_s2 = acceleration(mode, x, v, period_s_, in);
  }
  if (mode.contact) {
    output_.environment_force_N =
        std::max(0.0, env.stiffness_N_per_m * (x - env.position_m) + env.damping_Ns_per_m * v);
  } else if (mode.resting && mode.at_wall) {
    output_.environment_force_N = std::max(0.0, net_force(x, period_s_, false, in));
  } else {
    output_.environment_force_N = 0.0;
  }
  const HumanImpedance& h = params_.human;
  output_.human_force_N = in.exogenous_N + in.slope_N_per_s * period_s_ -
                          h.mass_kg * output_.acceleration_m_per_s2 - h.damping_Ns_per_m * v -
                          h.stiffness_N_per_m * x;
}

}  // namespace teleop::sim
