#include "common/scene/lockstep_axes.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>

#include "common/control/law_axes.hpp"
#include "common/control/velocity_estimator.hpp"

namespace teleop::scene {

namespace {

using Clock = std::chrono::steady_clock;
using control::AxisVector;

// A unilateral spring on one side: pushes -k (n^T x - p) n where n^T x > p.
struct Spring {
  const Eigen::VectorXd* normal;
  double offset_m;
  double stiffness_N_per_m;
  int side;  // 0: master law plane, 1: slave law plane, 2: slave environment
  int index;
};

std::vector<Spring> springs_of(const TeleopAxesParams& p,
                               const std::vector<sim::ContactPlane>& env) {
  std::vector<Spring> s;
  auto add = [&](const Eigen::VectorXd& n, double off, double k, int side, int index) {
    if (k > 0.0) s.push_back({&n, off, k, side, index});
  };
  for (std::size_t j = 0; j < p.master_planes.size(); ++j) {
    const PlaneFixtureParams& f = p.master_planes[j];
    add(f.normal, f.offset_m, f.stiffness_N_per_m, 0, static_cast<int>(j));
  }
  for (std::size_t j = 0; j < p.slave_planes.size(); ++j) {
    const PlaneFixtureParams& f = p.slave_planes[j];
    add(f.normal, f.offset_m, f.stiffness_N_per_m, 1, static_cast<int>(j));
  }
  for (std::size_t j = 0; j < env.size(); ++j) {
    add(env[j].normal, env[j].offset_m, env[j].stiffness_N_per_m, 2, static_cast<int>(j));
  }
  return s;
}

// The linear equations of the loop at rest with the springs of `mask` engaged, z = [x_m; x_s]:
//   F - K_h x_m - beta K_pm (x_m - x_s/alpha) - beta K_fm F_e - F_mVF = 0
//   K_ps (alpha x_m - x_s) - F_sVF - F_e = 0
// F_e = sum over engaged environment planes of k (n^T x_s - p) n, the force on the environment.
std::optional<Eigen::VectorXd> solve_engaged(const TeleopAxesParams& p,
                                             const Eigen::VectorXd& push_N,
                                             const std::vector<Spring>& springs, unsigned mask) {
  const int n = p.axes;
  const double alpha = p.scaling.position;
  const double beta = p.scaling.force;
  const Eigen::MatrixXd zero = Eigen::MatrixXd::Zero(n, n);
  const Eigen::MatrixXd kh =
      p.human.kind == HumanKind::kFixed ? p.human.fixed.stiffness_N_per_m : zero;
  Eigen::MatrixXd km = zero;  // master law planes
  Eigen::MatrixXd ks = zero;  // slave law planes and environment
  Eigen::MatrixXd ke = zero;  // environment alone (F_e)
  Eigen::VectorXd bm = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd bs = Eigen::VectorXd::Zero(n);
  Eigen::VectorXd be = Eigen::VectorXd::Zero(n);
  for (std::size_t j = 0; j < springs.size(); ++j) {
    if ((mask & (1U << j)) == 0) continue;
    const Spring& s = springs[j];
    const Eigen::MatrixXd nnt = s.stiffness_N_per_m * (*s.normal) * s.normal->transpose();
    const Eigen::VectorXd kpn = s.stiffness_N_per_m * s.offset_m * (*s.normal);
    if (s.side == 0) {
      km += nnt;
      bm += kpn;
    } else {
      ks += nnt;
      bs += kpn;
      if (s.side == 2) {
        ke += nnt;
        be += kpn;
      }
    }
  }
  const GainsAxes& g = p.gains;
  const Eigen::MatrixXd kfm = g.kfm.size() == n * n ? g.kfm : zero;
  Eigen::MatrixXd a(2 * n, 2 * n);
  a.topLeftCorner(n, n) = kh + beta * g.kpm + km;
  a.topRightCorner(n, n) = -beta / alpha * g.kpm + beta * kfm * ke;
  a.bottomLeftCorner(n, n) = alpha * g.kps;
  a.bottomRightCorner(n, n) = -(g.kps + ks);
  Eigen::VectorXd b(2 * n);
  b.head(n) = push_N + bm + beta * kfm * be;
  b.tail(n) = -bs;
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(a);
  if (!lu.isInvertible()) return std::nullopt;
  Eigen::VectorXd z = lu.solve(b);
  if (!z.allFinite()) return std::nullopt;
  return z;
}

bool consistent(const Eigen::VectorXd& z, int n, const std::vector<Spring>& springs,
                unsigned mask) {
  for (std::size_t j = 0; j < springs.size(); ++j) {
    const Spring& s = springs[j];
    const Eigen::VectorXd x = s.side == 0 ? z.head(n) : z.tail(n);
    const bool inside = s.normal->dot(x) > s.offset_m;
    if (inside != ((mask & (1U << j)) != 0)) return false;
  }
  return true;
}

void check_setup(const AxesSceneSetup& s) {
  const int n = s.teleop.axes;
  if (n < 1 || n > kMaxAxes) {
    throw std::invalid_argument("axes: must be 1-" + std::to_string(kMaxAxes));
  }
  if (!(s.duration_s > 0.0) || !std::isfinite(s.duration_s)) {
    throw std::invalid_argument("scene.duration_s must be > 0");
  }
  if (!(s.teleop.sample_rate_hz > 0.0) || !std::isfinite(s.teleop.sample_rate_hz)) {
    throw std::invalid_argument("sample_rate_hz must be > 0");
  }
  if (s.push_direction.size() != n || !s.push_direction.allFinite() ||
      !(s.push_direction.norm() > 0.0)) {
    throw std::invalid_argument("scene.push_direction: must have " + std::to_string(n) +
                                " finite entries, not all 0");
  }
  s.push_profile.validate();
  if (s.equilibrium_perturbation_m &&
      (s.equilibrium_perturbation_m->size() != n || !s.equilibrium_perturbation_m->allFinite())) {
    throw std::invalid_argument("scene.equilibrium_perturbation_m: must have " + std::to_string(n) +
                                " finite entries");
  }
}

sim::PlantAxesParams plant_of(const DeviceAxesParams& device, const HumanModelAxes* human,
                              const std::vector<sim::ContactPlane>& planes) {
  sim::PlantAxesParams p;
  p.device = device;
  if (human != nullptr && human->kind == HumanKind::kFixed) p.human = human->fixed;
  p.planes = planes;
  return p;
}

long decimation(double rate_hz, double output_rate_hz) {
  if (output_rate_hz <= 0.0 || output_rate_hz >= rate_hz) return 1;
  return std::max(1L, std::lround(rate_hz / output_rate_hz));
}

// The deepest n^T x - p over the stiff planes (0 outside every one).
double penetration(const std::vector<PlaneFixtureParams>& planes, const AxisVector& x) {
  double d = 0.0;
  for (const PlaneFixtureParams& f : planes) {
    if (f.stiffness_N_per_m <= 0.0) continue;
    d = std::max(d, f.normal.dot(x) - f.offset_m);
  }
  return d;
}

// The smallest sustained oscillation reported. The sensors here are ideal, so there is no encoder
// dither to ignore (the one-axis simulator's 10 um floor with ideal sensors): a slave held in a
// wedge of two planes by an unstable loop buzzes in a limit cycle of a few micrometres (the
// contacts bound the growth), and a hand feels a vibration of about 1 um at 100-300 Hz.
constexpr double kOscillationFloor_m = 1e-6;

// The worst axis's oscillation: a detected one before any other, then the larger amplitude.
std::pair<Oscillation, int> worst_axis(const std::vector<std::vector<double>>& series,
                                       double period_s, double window_s) {
  Oscillation worst;
  int axis = 0;
  for (std::size_t i = 0; i < series.size(); ++i) {
    const Oscillation o = detect_oscillation(series[i], period_s, window_s, kOscillationFloor_m);
    const bool better = (o.detected && !worst.detected) ||
                        (o.detected == worst.detected && o.amplitude_m > worst.amplitude_m);
    if (i == 0 || better) {
      worst = o;
      axis = static_cast<int>(i);
    }
  }
  return {worst, axis};
}

// Both laws joined as LockstepLaws (lockstep.cpp) joins the one-axis laws.
class AxesLaws {
 public:
  AxesLaws(const control::LawAxesParams& law, double t_s, int delay, const AxisVector& master_x0,
           const AxisVector& slave_x0)
      : master_(law), slave_(law), delay_(delay) {
    const int n = law.axes;
    velocity_.reserve(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i) {
      velocity_.emplace_back(t_s, law.velocity_cutoff_hz);
      velocity_.back().reset(slave_x0(i));
    }
    master_.reset(master_x0);
    slave_.reset(slave_x0);
    control::PeerStateAxes initial;
    initial.position_m = master_x0;
    initial.velocity_m_per_s = AxisVector::Zero(n);
    initial.force_N = AxisVector::Zero(n);
    initial.valid = true;
    in_flight_.assign(static_cast<std::size_t>(delay) + 1, initial);
    slave_state_.position_m = slave_x0;
    slave_state_.velocity_m_per_s = AxisVector::Zero(n);
    slave_state_.force_N = AxisVector::Zero(n);
  }

  // `coupled` false: the master's state reaches the slave as not valid (a master disarmed or
  // idle in a recording); `clutched`: the master indexes.
  void step(long k, const AxisVector& xm, const AxisVector& xs, const AxisVector& fe,
            control::CommandAxes& cm, control::CommandAxes& cs, bool coupled = true,
            bool clutched = false) {
    slave_state_.position_m = xs;
    for (Eigen::Index i = 0; i < xs.size(); ++i) {
      slave_state_.velocity_m_per_s(i) = velocity_[static_cast<std::size_t>(i)].step(xs(i));
    }
    slave_state_.force_N = fe;
    slave_state_.valid = !slave_.faulted();
    master_.set_clutch(clutched);
    cm = master_.step(xm, slave_state_);
    control::PeerStateAxes& sent = in_flight_[static_cast<std::size_t>(k % (delay_ + 1))];
    sent = master_.peer_state();
    sent.valid = sent.valid && coupled;
    received_ = &in_flight_[static_cast<std::size_t>((k + 1) % (delay_ + 1))];
    cs = slave_.step(xs, fe, *received_);
  }
  // After step(): the master's own filtered velocity, the slave's, and what the slave received.
  [[nodiscard]] AxisVector master_velocity() const { return master_.peer_state().velocity_m_per_s; }
  [[nodiscard]] const AxisVector& slave_velocity() const { return slave_state_.velocity_m_per_s; }
  [[nodiscard]] const control::PeerStateAxes& received() const { return *received_; }

 private:
  control::MasterLawAxes master_;
  control::SlaveLawAxes slave_;
  std::vector<control::VelocityEstimator> velocity_{};
  int delay_;
  std::vector<control::PeerStateAxes> in_flight_{};
  control::PeerStateAxes slave_state_{};
  const control::PeerStateAxes* received_{nullptr};
};

void observe(const AxesCycleObserver& observer, long k, const AxisVector& xm, const AxisVector& xs,
             const AxisVector& fh, const AxisVector& fe, const AxesLaws& laws,
             const control::CommandAxes& cm, const control::CommandAxes& cs) {
  const AxisVector vm = laws.master_velocity();
  observer(AxesCycleView{k, xm, xs, fh, fe, vm, laws.slave_velocity(), cm, cs, laws.received()});
}

std::vector<std::string> columns_of(int n) {
  std::vector<std::string> c{"time_s"};
  for (const char* name : {"master_position_m", "slave_position_m", "master_force_N",
                           "slave_force_N", "human_force_N", "environment_force_N"}) {
    for (int i = 0; i < n; ++i) c.push_back(std::string(name) + "[" + std::to_string(i) + "]");
  }
  return c;
}

}  // namespace

AxesEquilibrium static_equilibrium_axes(const TeleopAxesParams& params,
                                        const Eigen::VectorXd& push_N,
                                        const std::vector<sim::ContactPlane>& slave_environment) {
  const int n = params.axes;
  const std::vector<Spring> springs = springs_of(params, slave_environment);
  if (springs.size() > 16) throw std::invalid_argument("more than 16 stiff planes");
  const unsigned all = (1U << springs.size()) - 1U;
  std::vector<unsigned> masks;
  for (unsigned m = 0; m <= all; ++m) masks.push_back(m);
  std::stable_sort(masks.begin(), masks.end(),
                   [](unsigned a, unsigned b) { return std::popcount(a) > std::popcount(b); });
  for (const unsigned mask : masks) {
    const std::optional<Eigen::VectorXd> z = solve_engaged(params, push_N, springs, mask);
    if (!z || !consistent(*z, n, springs, mask)) continue;
    AxesEquilibrium e;
    e.master_m = z->head(n);
    e.slave_m = z->tail(n);
    for (std::size_t j = 0; j < springs.size(); ++j) {
      if ((mask & (1U << j)) == 0) continue;
      const unsigned bit = 1U << springs[j].index;
      (springs[j].side == 0   ? e.master_planes
       : springs[j].side == 1 ? e.slave_planes
                              : e.environment_planes) |= bit;
    }
    return e;
  }
  throw std::invalid_argument(
      "no unique static equilibrium: nothing restores the position (no human stiffness, plane "
      "or coupling spring) on some axis");
}

AxesStart axes_start(const AxesSceneSetup& s) {
  const int n = s.teleop.axes;
  AxesStart start;
  start.law = s.law ? *s.law : control::from_teleop_axes_params(s.teleop);
  start.master_m = Eigen::VectorXd::Zero(n);
  start.slave_m = Eigen::VectorXd::Zero(n);
  if (s.equilibrium_perturbation_m) {
    const Eigen::VectorXd push0 = s.push_profile.at(0.0) * s.push_direction.normalized();
    const AxesEquilibrium eq = static_equilibrium_axes(s.teleop, push0, s.slave_environment);
    start.master_m = eq.master_m;
    start.slave_m = eq.slave_m + *s.equilibrium_perturbation_m;
    start.equilibrium = eq;
    start.law.clutch_fade_s = 0.0;  // coupled at the equilibrium already: no fade-in transient
  }
  return start;
}

AxesSimulationResult simulate_axes(const AxesSceneSetup& s, const Progress& progress,
                                   const AxesCycleObserver& observer) {
  check_setup(s);
  const int n = s.teleop.axes;
  const double rate = s.teleop.sample_rate_hz;
  const double t_s = 1.0 / rate;
  const auto period = std::chrono::nanoseconds(std::llround(1e9 / rate));
  const AxesStart start = axes_start(s);
  const AxisVector direction = s.push_direction.normalized();
  AxesSimulationSummary sum;
  sum.axes = n;
  const AxisVector xm0 = start.master_m;
  const AxisVector xs0 = start.slave_m;
  sum.equilibrium = start.equilibrium;
  sim::PlantAxes master(plant_of(s.teleop.master_device, &s.teleop.human, {}), period);
  sim::PlantAxes slave(plant_of(s.teleop.slave_device, nullptr, s.slave_environment), period);
  master.reset({xm0, AxisVector::Zero(n)});
  slave.reset({xs0, AxisVector::Zero(n)});
  AxesLaws laws(start.law, t_s, s.teleop.round_trip_delay_samples, xm0, xs0);

  const long steps = std::lround(s.duration_s * rate);
  const long every = decimation(rate, s.output_rate_hz);
  AxesSimulationResult out;
  out.columns = columns_of(n);
  std::vector<std::vector<double>> xm_series(static_cast<std::size_t>(n));
  std::vector<std::vector<double>> xs_series(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) {
    xm_series[static_cast<std::size_t>(i)].reserve(static_cast<std::size_t>(steps));
    xs_series[static_cast<std::size_t>(i)].reserve(static_cast<std::size_t>(steps));
  }
  const double alpha = s.teleop.scaling.position;
  const double beta = s.teleop.scaling.force;
  AxisVector push = AxisVector::Zero(n);
  const AxisVector none = AxisVector::Zero(n);
  double track_sq = 0.0;
  double force_sq = 0.0;
  control::CommandAxes cm;
  control::CommandAxes cs;
  const auto wall0 = Clock::now();
  for (long k = 0; k < steps; ++k) {
    if (progress && k % 1000 == 0) progress(static_cast<double>(k) / static_cast<double>(steps));
    const AxisVector xm = master.state().position_m;
    const AxisVector xs = slave.state().position_m;
    // The load cell reads the force on the environment (the one-axis plant's F_e >= 0 sign).
    const AxisVector fe = -slave.output().environment_force_N;
    laws.step(k, xm, xs, fe, cm, cs);
    if (observer) observe(observer, k, xm, xs, master.output().human_force_N, fe, laws, cm, cs);
    sum.fault = sum.fault || cm.flags.input_fault || cs.flags.input_fault;
    // The master is pushed by -F_am (F_h - F_am = Z_m X_m); the slave by +F_as.
    const AxisVector um = -cm.force_N;
    push = s.push_profile.at(static_cast<double>(k) * t_s) * direction;
    const sim::PlantAxesOutput& mo = master.step(um, push, none);
    const sim::PlantAxesOutput& so = slave.step(cs.force_N);
    const AxisVector& xm1 = master.state().position_m;
    const AxisVector& xs1 = slave.state().position_m;
    for (int i = 0; i < n; ++i) {
      xm_series[static_cast<std::size_t>(i)].push_back(xm1(i));
      xs_series[static_cast<std::size_t>(i)].push_back(xs1(i));
    }
    sum.max_penetration_master_m =
        std::max(sum.max_penetration_master_m, penetration(s.teleop.master_planes, xm1));
    sum.max_penetration_slave_m =
        std::max(sum.max_penetration_slave_m, penetration(s.teleop.slave_planes, xs1));
    track_sq += (alpha * xm1 - xs1).squaredNorm();
    force_sq += (mo.human_force_N + beta * so.environment_force_N).squaredNorm();
    if (k % every == 0) {
      out.rows.push_back(static_cast<double>(k + 1) * t_s);
      const std::array<const AxisVector*, 5> row{&xm1, &xs1, &cm.force_N, &cs.force_N,
                                                 &mo.human_force_N};
      for (const AxisVector* v : row) {
        for (int i = 0; i < n; ++i) out.rows.push_back((*v)(i));
      }
      for (int i = 0; i < n; ++i) out.rows.push_back(-so.environment_force_N(i));
    }
  }
  const auto wall1 = Clock::now();
  sum.steps = steps;
  sum.duration_s = static_cast<double>(steps) * t_s;
  const double denominator = steps > 0 ? static_cast<double>(steps) : 1.0;
  sum.tracking_error_rms_m = std::sqrt(track_sq / denominator);
  sum.force_error_rms_N = std::sqrt(force_sq / denominator);
  const double window = std::min(1.0, 0.25 * sum.duration_s);
  std::tie(sum.oscillation, sum.oscillation_axis) = worst_axis(xs_series, t_s, window);
  std::tie(sum.master_oscillation, sum.master_oscillation_axis) =
      worst_axis(xm_series, t_s, window);
  sum.wall_time_s = std::chrono::duration<double>(wall1 - wall0).count();
  sum.real_time_factor = sum.wall_time_s > 0.0 ? sum.duration_s / sum.wall_time_s : 0.0;
  out.summary = sum;
  if (progress) progress(1.0);
  return out;
}

AxesSlaveOutcomeMeter::AxesSlaveOutcomeMeter(int axes, double position_scaling,
                                             std::vector<PlaneFixtureParams> planes)
    : alpha_(position_scaling),
      planes_(std::move(planes)),
      positions_(static_cast<std::size_t>(std::max(axes, 0))) {}

void AxesSlaveOutcomeMeter::add(const Eigen::VectorXd& slave_m,
                                const std::optional<Eigen::VectorXd>& master_m) {
  for (std::size_t i = 0; i < positions_.size(); ++i) {
    positions_[i].push_back(slave_m(static_cast<Eigen::Index>(i)));
  }
  if (master_m) {
    sum_sq_ += (alpha_ * *master_m - slave_m).squaredNorm();
    ++tracked_;
  }
  max_penetration_m_ = std::max(max_penetration_m_, penetration(planes_, slave_m));
}

AxesSlaveOutcome AxesSlaveOutcomeMeter::finish(double period_s) const {
  AxesSlaveOutcome o;
  o.cycles = positions_.empty() ? 0 : positions_.front().size();
  o.tracking_rms_m = tracked_ > 0 ? std::sqrt(sum_sq_ / static_cast<double>(tracked_)) : 0.0;
  o.max_penetration_m = max_penetration_m_;
  const double duration_s = static_cast<double>(o.cycles) * period_s;
  if (o.cycles > 4) {
    std::tie(o.oscillation, o.oscillation_axis) =
        worst_axis(positions_, period_s, std::min(1.0, 0.25 * duration_s));
  }
  return o;
}

AxesResimulation resimulate_axes(const AxesResimulationSetup& setup,
                                 const std::vector<AxesMasterCycle>& master,
                                 const Progress& progress) {
  const int n = setup.law.axes;
  if (setup.master0_m.size() != n || setup.slave0_m.size() != n) {
    throw std::invalid_argument("resimulation: the start positions must have " + std::to_string(n) +
                                " entries");
  }
  const double t_s = 1.0 / setup.sample_rate_hz;
  const auto period = std::chrono::nanoseconds(std::llround(1e9 / setup.sample_rate_hz));
  sim::PlantAxes slave(plant_of(setup.slave_device, nullptr, setup.slave_environment), period);
  slave.reset({setup.slave0_m, AxisVector::Zero(n)});
  AxesLaws laws(setup.law, t_s, setup.round_trip_delay_samples, setup.master0_m, setup.slave0_m);
  AxesSlaveOutcomeMeter meter(n, setup.position_scaling, setup.slave_planes);
  AxesResimulation out;
  out.axes = n;
  out.slave_position_m.reserve(master.size() * static_cast<std::size_t>(n));
  out.slave_command_N.reserve(master.size() * static_cast<std::size_t>(n));
  control::CommandAxes cm;
  control::CommandAxes cs;
  for (std::size_t k = 0; k < master.size(); ++k) {
    if (progress && k % 1000 == 0) {
      progress(static_cast<double>(k) / static_cast<double>(master.size()));
    }
    if (master[k].position_m.size() != n) {
      throw std::invalid_argument("resimulation: master cycle " + std::to_string(k) + " has " +
                                  std::to_string(master[k].position_m.size()) + " axes, not " +
                                  std::to_string(n));
    }
    const AxisVector xm = master[k].position_m;
    const AxisVector xs = slave.state().position_m;
    const AxisVector fe = -slave.output().environment_force_N;
    laws.step(static_cast<long>(k), xm, xs, fe, cm, cs, master[k].coupled, master[k].clutched);
    out.outcome.fault = out.outcome.fault || cs.flags.input_fault;
    for (int i = 0; i < n; ++i) {
      out.slave_position_m.push_back(xs(i));
      out.slave_command_N.push_back(cs.force_N(i));
    }
    const control::PeerStateAxes& received = laws.received();
    const bool following = received.valid && !received.clutched;
    meter.add(xs, following ? std::optional<Eigen::VectorXd>(received.position_m) : std::nullopt);
    (void)slave.step(cs.force_N);
  }
  if (progress) progress(1.0);
  const bool fault = out.outcome.fault;
  out.outcome = meter.finish(t_s);
  out.outcome.fault = fault;
  return out;
}

}  // namespace teleop::scene
