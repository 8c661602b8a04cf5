#include "common/scene/lockstep.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/control/velocity_estimator.hpp"

namespace teleop::scene {

namespace {

using Clock = std::chrono::steady_clock;

std::chrono::nanoseconds period_of(double rate_hz) {
  return std::chrono::nanoseconds(static_cast<long long>(std::llround(1e9 / rate_hz)));
}

void check(device::Status status, const char* what) {
  if (!status.ok()) {
    throw std::invalid_argument(std::string(what) + ": " + status.message);
  }
}

// Rows are kept at the output rate; the oscillation detector gets every sample.
struct Recorder {
  std::vector<double> rows;
  std::size_t columns{0};
  long every{1};
  void add(long step, std::initializer_list<double> values) {
    if (step % every != 0) return;
    rows.insert(rows.end(), values.begin(), values.end());
  }
};

long decimation(double rate_hz, double output_rate_hz) {
  if (output_rate_hz <= 0.0 || output_rate_hz >= rate_hz) return 1;
  return std::max(1L, std::lround(rate_hz / output_rate_hz));
}

double rms(double sum_sq, long n) {
  return n > 0 ? std::sqrt(sum_sq / static_cast<double>(n)) : 0.0;
}

// A limit cycle of a count or two of the encoder (peak to peak) is quantisation, not
// instability: the threshold is 1.5 counts of amplitude.
double oscillation_threshold(const device::SimDeviceConfig& c) {
  if (!c.quantize_position) return 1e-5;
  const double count_m = 2.0 * std::numbers::pi * c.encoder.metres_per_radian /
                         (c.encoder.counts_per_rev * c.encoder.transmission_ratio);
  return std::max(1e-5, 1.5 * count_m);
}

// The two laws joined as the nodes join them. The states each side sends: its position and
// its own filtered velocity, computed here from the same samples so that both laws see the
// peer's state of the same sample (a zero round trip is the paper's model); the configured
// round trip delays the master's.
class LockstepLaws {
 public:
  LockstepLaws(const control::LawParams& law, double t_s, int delay, double master_x0,
               double slave_x0)
      : master_law_(law),
        slave_law_(law),
        slave_velocity_(t_s, law.velocity_cutoff_hz),
        delay_(delay),
        in_flight_(static_cast<std::size_t>(delay) + 1,
                   control::PeerState{master_x0, 0.0, 0.0, false, true}) {
    master_law_.reset(master_x0);
    slave_law_.reset(slave_x0);
    slave_velocity_.reset(slave_x0);
  }

  // Step k: the master's command, then the slave's.
  std::pair<control::Command, control::Command> step(long k, const device::Sample& ms,
                                                     const device::Sample& ss) {
    const double fe_measured = ss.force_N;
    // The slave's state of this sample (its position and filtered velocity, as its law computes
    // them) reaches the master at once; the master's own outgoing state, with its clutch offset
    // and validity, goes through the round trip to the slave.
    const control::PeerState slave_state{ss.position_m, slave_velocity_.step(ss.position_m),
                                         fe_measured, false, !slave_law_.faulted()};
    const control::Command cm = master_law_.step(ms.position_m, slave_state);
    in_flight_[static_cast<std::size_t>(k % (delay_ + 1))] = master_law_.peer_state();
    const control::PeerState& master_delayed =
        in_flight_[static_cast<std::size_t>((k + 1) % (delay_ + 1))];
    const control::Command cs = slave_law_.step(ss.position_m, fe_measured, master_delayed);
    return {cm, cs};
  }

 private:
  control::MasterLaw master_law_;
  control::SlaveLaw slave_law_;
  control::VelocityEstimator slave_velocity_;
  int delay_;
  std::vector<control::PeerState> in_flight_;
};

// What a bilateral run measures, sample by sample, into its summary.
class BilateralMetrics {
 public:
  BilateralMetrics(const TeleopParams& teleop, long steps)
      : alpha_(teleop.scaling.position),
        beta_(teleop.scaling.force),
        mf_(teleop.master_fixture),
        sf_(teleop.slave_fixture) {
    xm_series_.reserve(static_cast<std::size_t>(steps));
    xs_series_.reserve(static_cast<std::size_t>(steps));
  }

  void add(const device::SimTruth& mt, const device::SimTruth& st, SimulationSummary& sum) {
    const double xm = mt.state.position_m;
    const double xs = st.state.position_m;
    const double fh = mt.output.human_force_N;
    const double fe = st.output.environment_force_N;
    xm_series_.push_back(xm);
    xs_series_.push_back(xs);
    if (mf_.stiffness_N_per_m > 0.0) {
      sum.max_penetration_master_m = std::max(sum.max_penetration_master_m, xm - mf_.position_m);
    }
    if (sf_.stiffness_N_per_m > 0.0) {
      sum.max_penetration_slave_m = std::max(sum.max_penetration_slave_m, xs - sf_.position_m);
    }
    const double track = alpha_ * xm - xs;
    const double ferr = fh - beta_ * fe;
    track_sq_ += track * track;
    force_sq_ += ferr * ferr;
    sum.force_error_peak_N = std::max(sum.force_error_peak_N, std::abs(ferr));
    const bool slave_free = !st.output.in_contact &&
                            !(sf_.stiffness_N_per_m > 0.0 && xs > sf_.position_m) &&
                            !(mf_.stiffness_N_per_m > 0.0 && xm > mf_.position_m);
    if (slave_free) sum.parasitic_force_peak_N = std::max(sum.parasitic_force_peak_N, std::abs(fh));
  }

  // The errors' RMS and both sides' oscillation, once the run is over.
  void finish(SimulationSummary& sum, long steps, double t_s,
              const device::SimDeviceConfig& master_cfg,
              const device::SimDeviceConfig& slave_cfg) const {
    sum.steps = steps;
    sum.duration_s = static_cast<double>(steps) * t_s;
    sum.tracking_error_rms_m = rms(track_sq_, steps);
    sum.force_error_rms_N = rms(force_sq_, steps);
    const double window = std::min(1.0, 0.25 * sum.duration_s);
    sum.oscillation = detect_oscillation(xs_series_, t_s, window, oscillation_threshold(slave_cfg));
    sum.master_oscillation =
        detect_oscillation(xm_series_, t_s, window, oscillation_threshold(master_cfg));
  }

 private:
  double alpha_;
  double beta_;
  FixtureParams mf_;
  FixtureParams sf_;
  std::vector<double> xm_series_{};
  std::vector<double> xs_series_{};
  double track_sq_{0.0};
  double force_sq_{0.0};
};

void set_wall_time(SimulationSummary& sum, Clock::time_point wall0, Clock::time_point wall1) {
  sum.wall_time_s = std::chrono::duration<double>(wall1 - wall0).count();
  sum.real_time_factor = sum.wall_time_s > 0.0 ? sum.duration_s / sum.wall_time_s : 0.0;
}

SimulationResult simulate_bilateral(const SceneSetup& s, const Progress& progress) {
  const double rate = s.teleop.sample_rate_hz;
  const double t_s = 1.0 / rate;
  const auto period = period_of(rate);
  device::SimDeviceConfig master_cfg = s.master;
  device::SimDeviceConfig slave_cfg = s.slave;
  master_cfg.period = period;
  slave_cfg.period = period;
  control::LawParams law = s.law;
  SimulationSummary sum;
  sum.kind = "bilateral";
  if (s.equilibrium_perturbation_m) {
    const Equilibrium eq = static_equilibrium(s.teleop, s.equilibrium_push_N);
    master_cfg.initial_position_m = eq.master_m;
    slave_cfg.initial_position_m = eq.slave_m + *s.equilibrium_perturbation_m;
    sum.equilibrium_master_m = eq.master_m;
    sum.equilibrium_slave_m = eq.slave_m;
    law.clutch_fade_s = 0.0;  // already coupled at the equilibrium: no fade-in transient
  }
  device::SimDevice master(master_cfg);
  device::SimDevice slave(slave_cfg);
  check(master.configure(), "master device");
  check(slave.configure(), "slave device");
  check(master.activate(), "master device");
  check(slave.activate(), "slave device");
  LockstepLaws laws(law, t_s, s.teleop.round_trip_delay_samples, master_cfg.initial_position_m,
                    slave_cfg.initial_position_m);

  const long steps = std::lround(s.duration_s * rate);
  Recorder rec;
  rec.every = decimation(rate, s.output_rate_hz);
  SimulationResult out;
  out.columns = {"time_s",          "master_position_m", "slave_position_m",
                 "master_sensed_m", "slave_sensed_m",    "master_force_N",
                 "slave_force_N",   "human_force_N",     "environment_force_N"};
  BilateralMetrics metrics(s.teleop, steps);
  const auto wall0 = Clock::now();
  for (long k = 0; k < steps; ++k) {
    if (progress && k % 1000 == 0) progress(static_cast<double>(k) / static_cast<double>(steps));
    device::Sample ms{};
    device::Sample ss{};
    (void)master.read(ms);
    (void)slave.read(ss);
    const auto [cm, cs] = laws.step(k, ms, ss);
    sum.fault = sum.fault || cm.flags.input_fault || cs.flags.input_fault;
    // The master is pushed by -F_am (F_h - F_am = Z_m X_m); the slave by +F_as.
    (void)master.write(device::Command{-cm.force_N});
    (void)slave.write(device::Command{cs.force_N});
    (void)master.advance(period);
    (void)slave.advance(period);
    const device::SimTruth mt = master.truth();
    const device::SimTruth st = slave.truth();
    metrics.add(mt, st, sum);
    rec.add(k, {mt.time_s, mt.state.position_m, st.state.position_m, ms.position_m, ss.position_m,
                cm.force_N, cs.force_N, mt.output.human_force_N, st.output.environment_force_N});
  }
  const auto wall1 = Clock::now();
  metrics.finish(sum, steps, t_s, master_cfg, slave_cfg);
  set_wall_time(sum, wall0, wall1);
  out.summary = sum;
  out.rows = std::move(rec.rows);
  return out;
}

SimulationResult simulate_force_device(const SceneSetup& s, const Progress& progress) {
  const ForceDeviceSetup& f = *s.force_device;
  const double t_s = f.controller.period_s;
  const auto period = std::chrono::nanoseconds(static_cast<long long>(std::llround(t_s * 1e9)));
  device::SimDeviceConfig cfg = f.device;
  cfg.period = period;
  cfg.initial_position_m = f.hand_position_m.at(0.0);
  device::SimDevice dev(cfg);
  check(dev.configure(), "force device");
  check(dev.activate(), "force device");
  control::VirtualEnvironmentRenderer renderer(f.controller, 0.0, f.environment);

  const long steps = std::lround(s.duration_s / t_s);
  Recorder rec;
  rec.every = decimation(1.0 / t_s, s.output_rate_hz);
  SimulationResult out;
  out.columns = {"time_s",       "device_position_m", "hand_position_m", "desired_force_N",
                 "felt_force_N", "sensed_force_N",    "average_force_N", "actuator_force_N"};
  SimulationSummary sum;
  sum.kind = "force_device";
  std::vector<double> x_series;
  x_series.reserve(static_cast<std::size_t>(steps));
  double track_sq = 0.0;
  double force_sq = 0.0;
  long contact_steps = 0;
  const auto wall0 = Clock::now();
  for (long k = 0; k < steps; ++k) {
    if (progress && k % 1000 == 0) progress(static_cast<double>(k) / static_cast<double>(steps));
    device::Sample smp{};
    (void)dev.read(smp);
    const control::ForceLoopCommand c = renderer.step(smp.position_m, smp.force_N);
    sum.fault = sum.fault || c.input_fault;
    // The actuator renders F_in against the hand: it pushes the device toward -x.
    (void)dev.write(device::Command{-c.force_N});
    (void)dev.advance(period);
    const device::SimTruth tr = dev.truth();
    const double x = tr.state.position_m;
    const double hand = f.hand_position_m.at(tr.time_s);
    const double felt = tr.output.human_force_N;
    const double desired = f.environment.force_N(x, tr.state.velocity_m_per_s);
    x_series.push_back(x - hand);  // an oscillation of the device about the hand's motion
    track_sq += (hand - x) * (hand - x);
    if (x > f.environment.position_m) {
      // The force error is the paper's: desired minus felt, in contact with the tissue.
      const double ferr = desired - felt;
      force_sq += ferr * ferr;
      ++contact_steps;
      sum.force_error_peak_N = std::max(sum.force_error_peak_N, std::abs(ferr));
    }
    if (x <= f.environment.position_m) {
      sum.parasitic_force_peak_N = std::max(sum.parasitic_force_peak_N, std::abs(felt));
    } else {
      sum.max_penetration_slave_m =
          std::max(sum.max_penetration_slave_m, x - f.environment.position_m);
    }
    rec.add(k, {tr.time_s, x, hand, desired, felt, smp.force_N, c.average_force_N, c.force_N});
  }
  const auto wall1 = Clock::now();
  sum.steps = steps;
  sum.duration_s = static_cast<double>(steps) * t_s;
  sum.tracking_error_rms_m = rms(track_sq, steps);
  sum.force_error_rms_N = rms(force_sq, contact_steps);
  // The hand drives the device: only a swing of more than a millimetre about the hand's own
  // motion counts (the grip's forced deflection under the parasitic force is far smaller).
  sum.oscillation = detect_oscillation(x_series, t_s, std::min(1.0, 0.25 * sum.duration_s), 1e-3);
  set_wall_time(sum, wall0, wall1);
  out.summary = sum;
  out.rows = std::move(rec.rows);
  return out;
}

}  // namespace

Equilibrium static_equilibrium(const TeleopParams& p, double push_N) {
  const Gains& g = p.gains;
  const double alpha = p.scaling.position;
  const double beta = p.scaling.force;
  const double kh = p.human.kind == HumanKind::kFixed ? p.human.fixed.stiffness_N_per_m : 0.0;
  // Try every engagement of the two unilateral fixtures; keep the consistent one.
  for (const int mask : {3, 1, 2, 0}) {
    const bool me = (mask & 1) != 0 && p.master_fixture.stiffness_N_per_m > 0.0;
    const bool se = (mask & 2) != 0 && p.slave_fixture.stiffness_N_per_m > 0.0;
    const double kmv = me ? p.master_fixture.stiffness_N_per_m : 0.0;
    const double ksv = se ? p.slave_fixture.stiffness_N_per_m : 0.0;
    // [kh + b Kpm + Kmv, -b Kpm / a] [xm]   [F + Kmv pm]
    // [Kps a,  -(Kps + Ksv)]         [xs] = [-Ksv ps]
    const double a11 = kh + beta * g.kpm + kmv;
    const double a12 = -beta * g.kpm / alpha;
    const double a21 = g.kps * alpha;
    const double a22 = -(g.kps + ksv);
    const double b1 = push_N + kmv * p.master_fixture.position_m;
    const double b2 = -ksv * p.slave_fixture.position_m;
    const double det = a11 * a22 - a12 * a21;
    if (std::abs(det) < 1e-12 * (std::abs(a11 * a22) + std::abs(a12 * a21) + 1e-300)) continue;
    Equilibrium e;
    e.master_m = (b1 * a22 - a12 * b2) / det;
    e.slave_m = (a11 * b2 - a21 * b1) / det;
    e.master_fixture_engaged = me;
    e.slave_fixture_engaged = se;
    const bool m_ok = p.master_fixture.stiffness_N_per_m <= 0.0 ||
                      (me == (e.master_m > p.master_fixture.position_m));
    const bool s_ok = p.slave_fixture.stiffness_N_per_m <= 0.0 ||
                      (se == (e.slave_m > p.slave_fixture.position_m));
    if (m_ok && s_ok) return e;
  }
  throw std::invalid_argument(
      "no unique static equilibrium: nothing restores the position (no human stiffness, "
      "fixture or coupling spring)");
}

SimulationResult simulate(const SceneSetup& setup, const Progress& progress) {
  if (!(setup.duration_s > 0.0)) throw std::invalid_argument("scene.duration_s must be > 0");
  SimulationResult r = setup.force_device ? simulate_force_device(setup, progress)
                                          : simulate_bilateral(setup, progress);
  if (progress) progress(1.0);
  return r;
}

}  // namespace teleop::scene
