// The n-axis simulator and the n-axis analyser agree (issue 18 "Done when"): 200 seeded random
// 3-axis teleoperators (coupled mass matrices, rotated gain and human matrices, tilted planes),
// simulated from their equilibrium inside the planes, settle when the analyser's minimum damping
// ratio is above 0.02 and oscillate when it is below -0.02. The simulator (law_axes, plant_axes)
// shares no code with the analyser (discrete_model_axes); each of them is checked on its own
// against the one-axis engine, closed forms and Eigen's matrix exponential. Here the simulator
// is also checked axis by axis against the one-axis simulator, and its equilibrium against the
// law's own forces.
#include <gtest/gtest.h>

#include <cstdio>

#include "agreement.hpp"
#include "agreement_axes.hpp"
#include "common/control/law_axes.hpp"

namespace teleop::scene::testing {
namespace {

TEST(AgreementAxes, SimulatorSettlesOrOscillatesAsTheAnalyserPredicts) {
  std::mt19937 rng(20261203);
  CampaignTally tally;
  for (int i = 0; i < 200; ++i) {
    const AxesCase c = random_axes_case(rng);
    const double z = c.min_damping_ratio;
    if (CampaignTally::in_band(z)) {
      ++tally.inside_band;
      continue;
    }
    const AxesOutcome o = run_axes_case(c);
    EXPECT_TRUE(tally.add(z, o.settled, o.sustained))
        << "case " << i << ": predicted zeta " << z << ", spectral radius " << c.spectral_radius
        << ", simulated amplitude " << o.amplitude_m << " m, sustained " << o.sustained
        << ", duration " << c.setup.duration_s;
  }
  tally.print();
  EXPECT_GE(tally.stable_cases, 40);
  EXPECT_GE(tally.unstable_cases, 40);
}

// With every matrix diagonal and the plane's normal along axis 0, the 3-axis loop is three
// one-axis loops: each axis's trajectory is the one-axis simulator's (lockstep.cpp, Plant,
// MasterLaw, SlaveLaw), from the same equilibrium and perturbation.
TEST(AgreementAxes, AnAxisAlignedLoopIsThreeOneAxisSimulations) {
  std::mt19937 rng(11);
  int compared = 0;
  for (int attempt = 0; attempt < 40 && compared < 3; ++attempt) {
    Case one[3] = {random_case(rng, true), random_case(rng, true), random_case(rng, true)};
    // One loop-wide setting for all three: rate, scaling, filter, round trip of the first.
    const TeleopParams& p0 = one[0].setup.teleop;
    TeleopAxesParams p;
    p.axes = 3;
    p.sample_rate_hz = p0.sample_rate_hz;
    p.scaling = p0.scaling;
    p.velocity_cutoff_hz = p0.velocity_cutoff_hz;
    p.round_trip_delay_samples = p0.round_trip_delay_samples;
    p.human.kind = HumanKind::kFixed;
    const auto zero = Eigen::MatrixXd::Zero(3, 3);
    p.master_device = {zero, Eigen::VectorXd::Zero(3), Eigen::VectorXd::Zero(3)};
    p.slave_device = p.master_device;
    p.gains = {zero, zero, zero, zero, zero, zero, zero};
    p.human.fixed = {zero, zero, zero};
    Eigen::VectorXd push(3);
    Eigen::VectorXd perturbation(3);
    for (int i = 0; i < 3; ++i) {
      TeleopParams& q = one[i].setup.teleop;
      q.sample_rate_hz = p.sample_rate_hz;
      q.scaling = p.scaling;
      q.velocity_cutoff_hz = p.velocity_cutoff_hz;
      q.round_trip_delay_samples = p.round_trip_delay_samples;
      q.master_fixture.stiffness_N_per_m = 0.0;
      if (i > 0) q.slave_fixture.stiffness_N_per_m = 0.0;
      one[i].setup.law = control::from_teleop_params(q);
      one[i].setup.duration_s = 2.0;
      one[i].setup.output_rate_hz = 0.0;
      p.master_device.mass_kg(i, i) = q.master_device.mass_kg;
      p.master_device.damping_Ns_per_m(i) = q.master_device.damping_Ns_per_m;
      p.slave_device.mass_kg(i, i) = q.slave_device.mass_kg;
      p.slave_device.damping_Ns_per_m(i) = q.slave_device.damping_Ns_per_m;
      for (auto [m, v] : {std::pair{&p.gains.kpm, q.gains.kpm},
                          {&p.gains.kps, q.gains.kps},
                          {&p.gains.kdm, q.gains.kdm},
                          {&p.gains.kds, q.gains.kds},
                          {&p.gains.kvm, q.gains.kvm},
                          {&p.gains.kvs, q.gains.kvs}}) {
        (*m)(i, i) = v;
      }
      p.human.fixed.mass_kg(i, i) = q.human.fixed.mass_kg;
      p.human.fixed.damping_Ns_per_m(i, i) = q.human.fixed.damping_Ns_per_m;
      p.human.fixed.stiffness_N_per_m(i, i) = q.human.fixed.stiffness_N_per_m;
      push(i) = one[i].setup.equilibrium_push_N;
      perturbation(i) = *one[i].setup.equilibrium_perturbation_m;
    }
    bool stable = true;
    for (const Case& k : one)
      stable = stable && stability::analyze(k.setup.teleop).min_damping_ratio > 0.05;
    if (!stable) continue;
    p.slave_planes.push_back({Eigen::Vector3d::UnitX(),
                              one[0].setup.teleop.slave_fixture.position_m,
                              one[0].setup.teleop.slave_fixture.stiffness_N_per_m});
    AxesSceneSetup s;
    s.teleop = p;
    s.push_direction = push.normalized();
    s.push_profile = sim::ForceProfile::constant(push.norm());
    s.equilibrium_perturbation_m = perturbation;
    s.duration_s = 2.0;
    const AxesSimulationResult r = simulate_axes(s);
    const std::size_t cols = r.columns.size();
    ASSERT_EQ(cols, 1U + 6U * 3U);
    for (int i = 0; i < 3; ++i) {
      const SimulationResult q = simulate(one[i].setup);
      const std::size_t qc = q.columns.size();
      ASSERT_EQ(q.rows.size() / qc, r.rows.size() / cols);
      double worst = 0.0;
      for (std::size_t k = 0; k < q.rows.size() / qc; ++k) {
        worst = std::max(worst, std::abs(q.rows[k * qc + 1] -
                                         r.rows[k * cols + 1 + static_cast<std::size_t>(i)]));
        worst = std::max(worst, std::abs(q.rows[k * qc + 2] -
                                         r.rows[k * cols + 4 + static_cast<std::size_t>(i)]));
      }
      // Positions of millimetres; the two plants' propagators agree to ~1e-15 per step.
      EXPECT_LT(worst, 1e-11) << "attempt " << attempt << " axis " << i;
    }
    ++compared;
  }
  EXPECT_EQ(compared, 3);
}

// The equilibrium balances the forces the laws themselves compute there: on the master,
// F - K_h x_m - F_am = 0; on the slave, F_as = 0 (no environment), with tilted planes engaged.
TEST(AgreementAxes, TheEquilibriumBalancesTheLawsForces) {
  std::mt19937 rng(5);
  for (int i = 0; i < 20; ++i) {
    const AxesCase c = random_axes_case(rng);
    const TeleopAxesParams& p = c.setup.teleop;
    const AxesEquilibrium eq =
        static_equilibrium_axes(p, c.setup.push_profile.at(0.0) * c.setup.push_direction);
    control::LawAxesParams law = control::from_teleop_axes_params(p);
    law.clutch_fade_s = 0.0;
    control::MasterLawAxes master(law);
    control::SlaveLawAxes slave(law);
    const control::AxisVector xm = eq.master_m;
    const control::AxisVector xs = eq.slave_m;
    const control::AxisVector zero = control::AxisVector::Zero(3);
    master.reset(xm);
    slave.reset(xs);
    control::CommandAxes cm;
    control::CommandAxes cs;
    for (int k = 0; k < 3 + p.round_trip_delay_samples; ++k) {
      control::PeerStateAxes s_state{xs, zero, zero, false, true};
      cm = master.step(xm, s_state);
      cs = slave.step(xs, zero, master.peer_state());
    }
    const Eigen::Vector3d master_net = c.setup.push_profile.at(0.0) * c.setup.push_direction -
                                       p.human.fixed.stiffness_N_per_m * eq.master_m -
                                       Eigen::Vector3d(cm.force_N);
    EXPECT_LT(master_net.norm(), 1e-9) << "case " << i;
    EXPECT_LT(Eigen::Vector3d(cs.force_N).norm(), 1e-9) << "case " << i;
    // The first slave plane is engaged: the push goes into it.
    EXPECT_TRUE((eq.slave_planes & 1U) != 0) << "case " << i;
  }
}

TEST(AgreementAxes, ABadSetupIsRefusedByName) {
  AxesSceneSetup s;
  s.teleop.axes = 3;
  s.teleop.sample_rate_hz = 1000.0;
  s.duration_s = 1.0;
  s.push_direction = Eigen::VectorXd::Ones(2);
  try {
    (void)simulate_axes(s);
    FAIL() << "a push of the wrong size was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("push_direction"), std::string::npos) << e.what();
  }
  s.push_direction = Eigen::VectorXd::Ones(3);
  s.duration_s = std::nan("");
  EXPECT_THROW((void)simulate_axes(s), std::invalid_argument);
}

}  // namespace
}  // namespace teleop::scene::testing
