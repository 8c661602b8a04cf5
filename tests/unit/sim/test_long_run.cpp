// An hour of simulated teleoperation at 1 kHz (issue 7, "The simulator"): no drift in the plant
// step over 3.6e6 periods (against closed forms in long double), energy bounded in a scene the
// analyser calls stable, and bit-identical results across runs.
//
// The hour is driven step by step here (the lockstep loop of common/scene/lockstep.cpp, on the
// same SimDevice, MasterLaw and SlaveLaw) rather than through scene::simulate, which keeps every
// sample: this keeps only running maxima, and it sees the velocities the energy needs.
//
// Runtime: ~1 s per simulated hour of teleoperation in RelWithDebInfo. Under AddressSanitizer
// (3-5x slower) the teleoperation tests run 10 simulated minutes instead of an hour, so that the
// determinism test (two runs) stays under 10 s; the plant-drift tests always run the full hour.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "common/config/config_loader.hpp"
#include "common/config/scene_loader.hpp"
#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "common/control/velocity_estimator.hpp"
#include "common/device/sim_device.hpp"
#include "common/scene/scene_setup.hpp"
#include "common/sim/plant.hpp"
#include "common/stability/analyzer.hpp"

#if defined(__SANITIZE_ADDRESS__)
#define TELEOP_LONG_RUN_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TELEOP_LONG_RUN_SANITIZED 1
#endif
#endif

namespace teleop::sim {
namespace {

constexpr long kHourSteps = 3'600'000;  // one hour at 1 kHz
constexpr long double kTl = 1e-3L;      // the period, as the closed forms use it

#ifdef TELEOP_LONG_RUN_SANITIZED
constexpr double kTeleopDurationS = 600.0;  // sanitizers: 10 simulated minutes
#else
constexpr double kTeleopDurationS = 3600.0;
#endif

// --- Plant drift -------------------------------------------------------------------------------

// m x'' + b x' = F from rest, F held: the ZOH is exact for a constant input, so the plant must
// follow the closed form to rounding for the whole hour.
//   v(t) = F/b (1 - e^{-bt/m}),  x(t) = F/b t - F m/b^2 (1 - e^{-bt/m}).
// Tolerance 1e-9 relative for event location: each step rounds x (~7e3 m at the end) by at most
// half an ulp, 1.1e-16 relative; even if all 3.6e6 roundings added up in the same direction the
// error would be 3.6e6 * 1.1e-16 = 4e-10 relative. Sub-stepping makes 8 propagations per step,
// so its worst case is 8x that, 3.2e-9: tolerance 4e-9. v contracts by e^{-bT/m} ~ 0.987 per step,
// so its rounding does not accumulate at all (~1e-14). A drift (a propagator wrong in its 10th
// digit, time accumulated in float, a mode switch that should not happen) shows as 1e-7 or worse.
TEST(LongRunPlantDrift, ConstantForceOnAFreeMassDamperFollowsTheClosedFormForAnHour) {
  const double m = 0.036;  // the paper's slave paddle
  const double b = 0.49;
  const double f = 1.0;
  for (const SteppingMethod method : {SteppingMethod::kEventLocation, SteppingMethod::kSubSteps}) {
    PlantParams p;
    p.device = {m, b};
    p.method = method;
    p.substeps = 8;
    Plant plant(p, std::chrono::milliseconds(1));
    plant.reset({0.0, 0.0});
    const long double ml = m;
    const long double bl = b;
    const long double fl = f;
    double worst_x = 0.0;
    double worst_v = 0.0;
    for (long k = 1; k <= kHourSteps; ++k) {
      (void)plant.step(f);
      // Every 10 ms in the first second (the transient), every second after.
      if ((k <= 1000 && k % 10 == 0) || k % 1000 == 0) {
        const long double t = static_cast<long double>(k) * kTl;
        const long double decay = -std::expm1(-bl * t / ml);  // 1 - e^{-bt/m}
        const long double v = fl / bl * decay;
        const long double x = fl / bl * t - fl * ml / (bl * bl) * decay;
        worst_x =
            std::max(worst_x, static_cast<double>(std::fabs((plant.state().position_m - x) / x)));
        worst_v = std::max(
            worst_v, static_cast<double>(std::fabs((plant.state().velocity_m_per_s - v) / v)));
      }
    }
    const long double t_end = static_cast<long double>(kHourSteps) * kTl;
    const double x_end = static_cast<double>(fl / bl * t_end - fl * ml / (bl * bl));
    std::printf(
        "[%s] after 3600 s: x = %.15g m (closed form %.15g), worst relative error "
        "x %.3g, v %.3g\n",
        to_string(method), plant.state().position_m, x_end, worst_x, worst_v);
    const double tol = method == SteppingMethod::kEventLocation ? 1e-9 : 4e-9;
    EXPECT_LT(worst_x, tol) << to_string(method);
    EXPECT_LT(worst_v, tol) << to_string(method);
    EXPECT_EQ(plant.total_events(), 0U) << to_string(method);  // free space: no mode switches
  }
}

// M x'' + B x' + K x = 0 (paddle + the finger's stiffness, almost no damping) released from x0:
//   x = x0 e^{-st} (cos wd t + s/wd sin wd t),  v = -x0 (wn^2/wd) e^{-st} sin wd t,
// s = B/2M, wn^2 = K/M, wd^2 = wn^2 - s^2. 21 000 cycles in the hour, the envelope falls to
// e^{-0.87} = 0.42 only, so phase or amplitude drift would show. Errors are scaled by the
// envelope (x0 e^{-st}, and wn x0 e^{-st} for v); tolerance 1e-9: 3.6e6 steps of at most a couple
// of half-ulp roundings, all in the same direction, give 3.6e6 * 2.2e-16 / 0.42 = 1.9e-9 as an
// absolute worst case, and rounding errors are not that correlated (a random walk gives ~1e-12).
// The mechanical energy E = M v^2/2 + K x^2/2 of the unforced damped plant never increases:
// E_{k+1} <= E_k (1 + 1e-12) at every step (the step dissipates exactly the damper's work; the
// allowance covers rounding of E itself, ~1e-16, and of the step, with margin).
TEST(LongRunPlantDrift, LightlyDampedOscillationMatchesTheClosedFormAndNeverGainsEnergy) {
  const DeviceParams device{0.040, 2.5e-5};
  const HumanImpedance finger{0.012, 0.0, 70.0};
  const double x0 = 0.01;
  PlantParams p;
  p.device = device;
  p.human = finger;
  Plant plant(p, std::chrono::milliseconds(1));
  plant.reset({x0, 0.0});
  const long double mass = static_cast<long double>(device.mass_kg) + finger.mass_kg;
  const long double damping = device.damping_Ns_per_m;
  const long double k = finger.stiffness_N_per_m;
  const long double s = damping / (2.0L * mass);
  const long double wn2 = k / mass;
  const long double wd = std::sqrt(wn2 - s * s);
  const double md = static_cast<double>(mass);
  const double kd = static_cast<double>(k);
  auto energy = [&](const PlantState& st) {
    return 0.5 * md * st.velocity_m_per_s * st.velocity_m_per_s +
           0.5 * kd * st.position_m * st.position_m;
  };
  double e_prev = energy(plant.state());
  const double e0 = e_prev;
  double worst_gain = 0.0;  // largest (E_{k+1} - E_k) / E_k
  long gains = 0;
  double worst_x = 0.0;
  double worst_v = 0.0;
  for (long n = 1; n <= kHourSteps; ++n) {
    (void)plant.step(0.0);
    const double e = energy(plant.state());
    const double gain = (e - e_prev) / e_prev;
    worst_gain = std::max(worst_gain, gain);
    if (gain > 1e-12) ++gains;
    e_prev = e;
    if (n % 97 == 0 || n == kHourSteps) {  // 97: not a divisor of the ~168-step period
      const long double t = static_cast<long double>(n) * kTl;
      const long double env = x0 * std::exp(-s * t);
      const long double x = env * (std::cos(wd * t) + s / wd * std::sin(wd * t));
      const long double v = -env * wn2 / wd * std::sin(wd * t);
      worst_x =
          std::max(worst_x, static_cast<double>(std::fabs(plant.state().position_m - x) / env));
      worst_v =
          std::max(worst_v, static_cast<double>(std::fabs(plant.state().velocity_m_per_s - v) /
                                                (std::sqrt(wn2) * env)));
    }
  }
  const long double t_end = static_cast<long double>(kHourSteps) * kTl;
  const long double env_end = x0 * std::exp(-s * t_end);
  const long double x_end = env_end * (std::cos(wd * t_end) + s / wd * std::sin(wd * t_end));
  const long double v_end = -env_end * wn2 / wd * std::sin(wd * t_end);
  const double e_end = static_cast<double>(0.5L * mass * v_end * v_end + 0.5L * k * x_end * x_end);
  std::printf(
      "after 3600 s: worst error / envelope x %.3g, v %.3g; energy %.12g J of %.6g J "
      "(closed form %.12g J); largest one-step relative energy change %+.3g\n",
      worst_x, worst_v, energy(plant.state()), e0, e_end, worst_gain);
  EXPECT_NEAR(energy(plant.state()), e_end, 1e-9 * e_end);
  EXPECT_LT(worst_x, 1e-9);
  EXPECT_LT(worst_v, 1e-9);
  EXPECT_EQ(gains, 0) << "steps that gained energy; worst " << worst_gain;
}

// --- An hour of teleoperation ------------------------------------------------------------------

// examples/live.textproto: the paper's paddles at 1 kHz with a round trip of one sample and the
// slave's 1500 N/m forbidden-region fixture at 6 mm, which `teleopctl analyze` calls stable. The
// slave is put in free space (the scene's soft tissue is not part of the analysed loop), so the
// simulated loop is exactly the analysed one, switching between fixture off and on, plus the
// real hardware's encoder quantisation and actuator saturation.
// The human pushes 0.5 + 1.0 sin(2 pi 0.7 t) N: between -0.5 N (pulling the slave out of the
// fixture, 7 mm away) and 1.5 N (pressing it in), so the fixture is engaged and released 2520
// times an hour, each contact kicking both of the loop's modes (15 and 42 Hz).
scene::SceneSetup live_scene(double duration_s) {
  const config::LoadedConfig c =
      config::load_config_file(std::string(TELEOP_SOURCE_DIR) + "/examples/live.textproto",
                               {"scene.duration_s=" + std::to_string(duration_s)});
  scene::SceneSetup s = config::to_scene_setup(c);
  s.slave.plant.environment = Environment::free_space();
  s.master.human->profile = ForceProfile::sinusoid(0.5, 1.0, 0.7);
  return s;
}

constexpr double kPushPeakN = 1.5;  // the largest |F_h*|

struct Window {
  double max_energy_J{0.0};
  double max_abs_position_m{0.0};
};

struct RunResult {
  std::vector<Window> windows{};               // 10 simulated minutes each
  std::array<double, 4> final_state{};         // x_m, v_m, x_s, v_s
  std::uint64_t hash{1469598103934665603ULL};  // FNV-1a over every step's states and commands
  long steps{0};
  bool fault{false};
  bool event_limit_hit{false};
  double max_penetration_m{0.0};
};

void fnv(std::uint64_t& h, double v) {
  unsigned char bytes[sizeof v];
  std::memcpy(bytes, &v, sizeof v);
  for (const unsigned char c : bytes) {
    h ^= c;
    h *= 1099511628211ULL;
  }
}

// The lockstep loop of scene::simulate (bilateral), keeping running maxima only.
RunResult run(const scene::SceneSetup& s) {
  const double rate = s.teleop.sample_rate_hz;
  const double t_s = 1.0 / rate;
  const auto period = std::chrono::nanoseconds(std::llround(1e9 / rate));
  device::SimDeviceConfig mcfg = s.master;
  device::SimDeviceConfig scfg = s.slave;
  mcfg.period = period;
  scfg.period = period;
  device::SimDevice master(mcfg);
  device::SimDevice slave(scfg);
  EXPECT_TRUE(master.configure().ok());
  EXPECT_TRUE(slave.configure().ok());
  EXPECT_TRUE(master.activate().ok());
  EXPECT_TRUE(slave.activate().ok());
  control::MasterLaw master_law(s.law);
  control::SlaveLaw slave_law(s.law);
  master_law.reset(mcfg.initial_position_m);
  slave_law.reset(scfg.initial_position_m);
  control::VelocityEstimator slave_velocity(t_s, s.law.velocity_cutoff_hz);
  slave_velocity.reset(scfg.initial_position_m);
  const int delay = s.teleop.round_trip_delay_samples;
  std::vector<control::PeerState> in_flight(
      static_cast<std::size_t>(delay) + 1,
      control::PeerState{mcfg.initial_position_m, 0.0, 0.0, false, true});

  // Mechanical energy from the states: kinetic (the human's mass moves with the master),
  // the human's spring, the coupling spring and the fixture's spring when penetrated.
  const double mm = s.teleop.master_device.mass_kg + s.teleop.human.fixed.mass_kg;
  const double ms = s.teleop.slave_device.mass_kg;
  const double kh = s.teleop.human.fixed.stiffness_N_per_m;
  const double kp = s.teleop.gains.kps;
  const double alpha = s.teleop.scaling.position;
  const FixtureParams fx = s.teleop.slave_fixture;

  const long steps = std::lround(s.duration_s * rate);
  const long per_window = std::lround(600.0 * rate);
  RunResult r;
  r.steps = steps;
  for (long k = 0; k < steps; ++k) {
    device::Sample msmp{};
    device::Sample ssmp{};
    (void)master.read(msmp);
    (void)slave.read(ssmp);
    const control::PeerState slave_state{ssmp.position_m, slave_velocity.step(ssmp.position_m),
                                         ssmp.force_N, false, !slave_law.faulted()};
    const control::Command cm = master_law.step(msmp.position_m, slave_state);
    in_flight[static_cast<std::size_t>(k % (delay + 1))] = master_law.peer_state();
    const control::PeerState& master_delayed =
        in_flight[static_cast<std::size_t>((k + 1) % (delay + 1))];
    const control::Command cs = slave_law.step(ssmp.position_m, ssmp.force_N, master_delayed);
    r.fault = r.fault || cm.flags.input_fault || cs.flags.input_fault;
    (void)master.write(device::Command{-cm.force_N});
    (void)slave.write(device::Command{cs.force_N});
    (void)master.advance(period);
    (void)slave.advance(period);

    const device::SimTruth mt = master.truth();
    const device::SimTruth st = slave.truth();
    const double xm = mt.state.position_m;
    const double vm = mt.state.velocity_m_per_s;
    const double xs = st.state.position_m;
    const double vs = st.state.velocity_m_per_s;
    r.event_limit_hit = r.event_limit_hit || mt.output.event_limit_hit || st.output.event_limit_hit;
    const double pen = std::max(0.0, xs - fx.position_m);
    r.max_penetration_m = std::max(r.max_penetration_m, pen);
    const double coupling = alpha * xm - xs;
    const double e = 0.5 * mm * vm * vm + 0.5 * ms * vs * vs + 0.5 * kh * xm * xm +
                     0.5 * kp * coupling * coupling + 0.5 * fx.stiffness_N_per_m * pen * pen;
    if (k % per_window == 0) r.windows.emplace_back();
    Window& w = r.windows.back();
    w.max_energy_J = std::max(w.max_energy_J, e);
    w.max_abs_position_m = std::max({w.max_abs_position_m, std::abs(xm), std::abs(xs)});
    for (const double v : {xm, vm, xs, vs, cm.force_N, cs.force_N}) fnv(r.hash, v);
  }
  r.final_state = {master.truth().state.position_m, master.truth().state.velocity_m_per_s,
                   slave.truth().state.position_m, slave.truth().state.velocity_m_per_s};
  return r;
}

TEST(LongRunTeleop, EnergyStaysBoundedForAnHourWhereTheAnalyserSaysStable) {
  const scene::SceneSetup s = live_scene(kTeleopDurationS);
  ASSERT_EQ(s.teleop.sample_rate_hz, 1000.0);
  ASSERT_EQ(s.teleop.human.kind, HumanKind::kFixed);
  ASSERT_EQ(s.teleop.gains.kpm, s.teleop.gains.kps);  // one coupling spring
  // The premise, from the analyser (the fixture engaged; out of it the loop is the same with
  // K_sv = 0, checked too).
  EXPECT_EQ(stability::analyze(s.teleop).verdict, stability::Verdict::kStable);
  TeleopParams no_fixture = s.teleop;
  no_fixture.slave_fixture.stiffness_N_per_m = 0.0;
  EXPECT_EQ(stability::analyze(no_fixture).verdict, stability::Verdict::kStable);

  const auto wall0 = std::chrono::steady_clock::now();
  const RunResult r = run(s);
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  ASSERT_EQ(r.windows.size(), static_cast<std::size_t>(std::lround(kTeleopDurationS / 600.0)));
  std::printf("%.0f s simulated in %.2f s wall; max penetration %.4g m\n", kTeleopDurationS, wall,
              r.max_penetration_m);
  for (std::size_t i = 0; i < r.windows.size(); ++i) {
    std::printf("  minutes %3zu-%3zu: max energy %.6e J, max |x| %.4g m\n", 10 * i, 10 * (i + 1),
                r.windows[i].max_energy_J, r.windows[i].max_abs_position_m);
  }
  EXPECT_FALSE(r.fault);
  EXPECT_FALSE(r.event_limit_hit);
  EXPECT_GT(r.max_penetration_m, 0.0);  // it does press into the fixture
  const Window& first = r.windows.front();
#ifndef TELEOP_LONG_RUN_SANITIZED
  const Window& last = r.windows.back();
  // No growth: the forced response is periodic (0.7 Hz) once the start-up transient (gone in a
  // second: the slowest mode decays as e^{-18.8 t}) has passed, so every 10-minute window sees
  // the same orbit (420 periods, sampled at different phases) plus encoder and noise jitter.
  // 2% covers that jitter; a growing mode (|z| > 1 by even 1e-7 per step) would multiply the
  // energy by e^{2 * 1e-7 * 3e6} = 1.8 between the windows.
  EXPECT_LE(last.max_energy_J, first.max_energy_J * 1.02);
  // ... and still excited: not decayed to rest either.
  EXPECT_GE(last.max_energy_J, first.max_energy_J * 0.5);
#endif
  for (const Window& w : r.windows) EXPECT_LE(w.max_energy_J, first.max_energy_J * 1.02);
  // Positions stay physical: the largest quasi-static deflection is the peak push over the
  // human's stiffness, 1.5 N / 70 N/m = 21 mm (less with the fixture); 50 mm leaves room for
  // dynamic overshoot at 0.7 Hz, far below the 15 Hz mode, and is well inside the paddle's arc.
  const double static_m = kPushPeakN / s.teleop.human.fixed.stiffness_N_per_m;
  for (const Window& w : r.windows) {
    EXPECT_LT(w.max_abs_position_m, 0.05);
    EXPECT_GT(w.max_abs_position_m, 0.25 * static_m);  // it moves
  }
}

TEST(LongRunTeleop, TwoRunsOfTheSameSceneAreBitIdentical) {
  const scene::SceneSetup s = live_scene(kTeleopDurationS);
  const RunResult a = run(s);
  const RunResult b = run(s);
  ASSERT_EQ(a.steps, b.steps);
  std::printf("%ld steps; final x_m %.17g v_m %.17g x_s %.17g v_s %.17g; hash %016llx / %016llx\n",
              a.steps, a.final_state[0], a.final_state[1], a.final_state[2], a.final_state[3],
              static_cast<unsigned long long>(a.hash), static_cast<unsigned long long>(b.hash));
  EXPECT_EQ(std::memcmp(a.final_state.data(), b.final_state.data(), sizeof a.final_state), 0);
  EXPECT_EQ(a.hash, b.hash);  // every step, not only the last
  for (std::size_t i = 0; i < a.windows.size(); ++i) {
    EXPECT_EQ(std::memcmp(&a.windows[i], &b.windows[i], sizeof(Window)), 0) << "window " << i;
  }
}

}  // namespace
}  // namespace teleop::sim
