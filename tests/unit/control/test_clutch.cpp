// Clutch (indexing) while moving. Both loops run free: each side gets the other's state of
// the previous sample. The positions and the environment force are smooth prescribed
// signals, so any step in a command comes from the law, not from its inputs.
//
// The bound on |F(k) - F(k-1)|, from the documented law (master_law.hpp, slave_law.hpp):
//  - motion: each term's gain times the one-sample change of its signal (triangle
//    inequality on the law). While clutched the published/held positions change by 0, else
//    by the master's own change, so |dx_ref| <= |dx_m|;
//  - fade: the coupling weight w (master), the reference-velocity weight u and the
//    mismatch weight m (slave) change by 1/N per sample (N = clutch_fade_s / T), times the
//    largest value what they multiply reaches:
//      master: beta [K_pm E + K_dm (2 V_m + V_s / alpha) + K_fm F_max] / N
//              (w multiplies the coupling and, once more, the velocity reference)
//      slave:  [K_ds alpha V_m + K_ps |delta|] / N   (delta: start-up mismatch)
//    with E the largest |x_ref - x_s/alpha|, V the largest |v|, F_max the largest |F_e|.
// A law that switched the coupling in one sample would exceed it (checked below).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "common/control/master_law.hpp"
#include "common/control/slave_law.hpp"
#include "tests/unit/control/control_test_util.hpp"

namespace teleop::control {
namespace {

constexpr double kT = 1e-3;
constexpr int kSamples = 1300;
constexpr int kEngage = 620;   // set_clutch(true) before this master step (moving fast)
constexpr int kRelease = 950;  // set_clutch(false) before this master step (moving fast)
constexpr double kFade_s = 0.02;
constexpr double kN = kFade_s / kT;

[[nodiscard]] LawParams clutch_params(double fade_s) {
  LawParams p;
  p.period_s = kT;
  p.gains = {
      .kpm = 400.0, .kps = 500.0, .kdm = 4.0, .kds = 5.0, .kvm = 1.0, .kvs = 1.5, .kfm = 0.5};
  p.scaling = {.position = 1.5, .force = 0.8};
  p.master_fixture = {800.0, 0.012};
  p.slave_fixture = {1000.0, 0.02};
  p.velocity_cutoff_hz = 100.0;
  p.clutch_fade_s = fade_s;
  return p;
}

// The test's own filtered backward difference (docs/architecture.md §2.4), at rest on the
// first sample.
[[nodiscard]] std::vector<double> filtered_velocity(const std::vector<double>& x, double fc) {
  const double a = 1.0 - std::exp(-2.0 * std::numbers::pi * fc * kT);
  std::vector<double> v(x.size(), 0.0);
  for (std::size_t k = 1; k < x.size(); ++k)
    v[k] = v[k - 1] + a * ((x[k] - x[k - 1]) / kT - v[k - 1]);
  return v;
}

struct ClutchRun {
  std::vector<double> xm, xs, fe, vm, vs;
  std::vector<Command> master, slave;
  std::vector<double> slave_reference, master_offset;
  std::vector<PeerState> master_sent;
};

[[nodiscard]] ClutchRun simulate(const LawParams& p) {
  ClutchRun r;
  const double two_pi = 2.0 * std::numbers::pi;
  for (int k = 0; k < kSamples; ++k) {
    const double t = k * kT;
    r.xm.push_back(0.015 * std::sin(two_pi * 1.5 * t));
    r.xs.push_back(1.5 * 0.015 * std::sin(two_pi * 1.5 * (t - 0.01)) +
                   0.002 * std::sin(two_pi * 0.7 * t));
    r.fe.push_back(1.0 + 0.5 * std::sin(two_pi * 2.0 * t));
  }
  r.vm = filtered_velocity(r.xm, p.velocity_cutoff_hz);
  r.vs = filtered_velocity(r.xs, p.velocity_cutoff_hz);

  MasterLaw master(p);
  SlaveLaw slave(p);
  PeerState to_slave;   // invalid until the master has stepped once
  PeerState to_master;  // invalid until the slave has stepped once
  for (int k = 0; k < kSamples; ++k) {
    if (k == kEngage) master.set_clutch(true);
    if (k == kRelease) master.set_clutch(false);
    const std::size_t i = static_cast<std::size_t>(k);
    r.master.push_back(master.step(r.xm[i], to_master));
    r.slave.push_back(slave.step(r.xs[i], r.fe[i], to_slave));
    to_slave = master.peer_state();
    to_master = slave.peer_state();
    r.master_sent.push_back(to_slave);
    r.slave_reference.push_back(slave.reference_m());
    r.master_offset.push_back(master.offset_m());
  }
  return r;
}

struct Excess {
  double master{0.0};
  double slave{0.0};
  int master_at{-1};
  int slave_at{-1};
};

// Largest |dF| - bound over the run, per side (<= 0: within the bound everywhere).
[[nodiscard]] Excess excess_over_bound(const LawParams& p, const ClutchRun& r) {
  const Gains& g = p.gains;
  const double alpha = p.scaling.position;
  const double beta = p.scaling.force;
  const double kmvf = p.master_fixture.stiffness_N_per_m;
  const double ksvf = p.slave_fixture.stiffness_N_per_m;
  const std::size_t n = r.xm.size();

  // Documented clutch bookkeeping: x_hold is the last published unclutched position (the
  // master's position one sample before the engage), offset = x_m(release) - x_hold.
  const double hold = r.xm[kEngage - 1];
  const double offset = r.xm[kRelease] - hold;
  double e_max = 0.0;
  double vm_max = 0.0;
  double vs_max = 0.0;
  double fe_max = 0.0;
  for (std::size_t k = 1; k < n; ++k) {
    const double xs_seen = r.xs[k - 1] / alpha;
    const double xref = static_cast<int>(k) < kEngage    ? r.xm[k]
                        : static_cast<int>(k) < kRelease ? hold
                                                         : r.xm[k] - offset;
    e_max = std::max(e_max, std::abs(xref - xs_seen));
    vm_max = std::max(vm_max, std::abs(r.vm[k]));
    vs_max = std::max(vs_max, std::abs(r.vs[k]));
    fe_max = std::max(fe_max, std::abs(r.fe[k]));
  }
  // The slave's reference at start-up begins at its own position (no master state at k = 0).
  const double delta = std::abs(r.xs[0] - alpha * r.xm[0]);
  const double fade_m =
      beta * (g.kpm * e_max + g.kdm * (2.0 * vm_max + vs_max / alpha) + g.kfm * fe_max) / kN;
  const double fade_s = (g.kds * alpha * vm_max + g.kps * delta) / kN;

  Excess out;
  for (std::size_t k = 1; k < n; ++k) {
    const double dxm = std::abs(r.xm[k] - r.xm[k - 1]);
    const double dvm = std::abs(r.vm[k] - r.vm[k - 1]);
    const double dxs = std::abs(r.xs[k] - r.xs[k - 1]);
    const double dvs = std::abs(r.vs[k] - r.vs[k - 1]);
    // What each side sees of the other is one sample old.
    const double dxm_seen = k >= 2 ? std::abs(r.xm[k - 1] - r.xm[k - 2]) : 0.0;
    const double dvm_seen = k >= 2 ? std::abs(r.vm[k - 1] - r.vm[k - 2]) : 0.0;
    const double dxs_seen = k >= 2 ? std::abs(r.xs[k - 1] - r.xs[k - 2]) : 0.0;
    const double dvs_seen = k >= 2 ? std::abs(r.vs[k - 1] - r.vs[k - 2]) : 0.0;
    const double dfe_seen = k >= 2 ? std::abs(r.fe[k - 1] - r.fe[k - 2]) : 0.0;

    const double motion_m = beta * (g.kpm * (dxm + dxs_seen / alpha) +
                                    g.kdm * (dvm + dvs_seen / alpha) + g.kfm * dfe_seen) +
                            g.kvm * dvm + kmvf * dxm;
    const double motion_s = g.kps * (alpha * dxm_seen + dxs) + g.kds * (alpha * dvm_seen + dvs) +
                            g.kvs * dvs + ksvf * dxs;
    const double slack = 1e-9;
    const double em =
        std::abs(r.master[k].force_N - r.master[k - 1].force_N) - (motion_m + fade_m + slack);
    const double es =
        std::abs(r.slave[k].force_N - r.slave[k - 1].force_N) - (motion_s + fade_s + slack);
    if (em > out.master || out.master_at < 0) {
      out.master = std::max(out.master, em);
      out.master_at = static_cast<int>(k);
    }
    if (es > out.slave || out.slave_at < 0) {
      out.slave = std::max(out.slave, es);
      out.slave_at = static_cast<int>(k);
    }
  }
  return out;
}

TEST(Clutch, NoJumpBeyondMotionAtEngageOrReleaseWhileMoving) {
  const LawParams p = clutch_params(kFade_s);
  const ClutchRun r = simulate(p);
  // Moving fast at both transitions: more than 0.1 m/s.
  EXPECT_GT(std::abs(r.vm[kEngage]), 0.1);
  EXPECT_GT(std::abs(r.vm[kRelease]), 0.1);
  const Excess e = excess_over_bound(p, r);
  EXPECT_LE(e.master, 0.0) << "at sample " << e.master_at;
  EXPECT_LE(e.slave, 0.0) << "at sample " << e.slave_at;
}

TEST(Clutch, SwitchingInOneSampleWouldBreakTheBound) {
  // The same bound for a law with no fade: the coupling drops in one sample at the engage.
  const LawParams p = clutch_params(0.0);
  const ClutchRun r = simulate(p);
  const Excess e = excess_over_bound(clutch_params(kFade_s), r);
  EXPECT_GT(e.master, 0.0);
  EXPECT_GT(e.slave, 0.0);
}

TEST(Clutch, MasterFeelsNoCouplingAndSlaveHoldsWhileClutched) {
  const LawParams p = clutch_params(kFade_s);
  const Gains& g = p.gains;
  const ClutchRun r = simulate(p);
  const double alpha = p.scaling.position;
  const double hold = r.xm[kEngage - 1];
  for (int k = kEngage; k < kRelease; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    EXPECT_TRUE(r.master_sent[i].clutched);
    EXPECT_EQ(r.master_sent[i].position_m, hold);
    // The slave holds alpha * x_hold from the first sample that sees the clutch.
    EXPECT_NEAR(r.slave_reference[i], alpha * hold, 1e-15) << k;
    if (k < kEngage + static_cast<int>(kN) + 2) continue;  // fades done
    const double own_m = g.kvm * r.vm[i] + p.master_fixture.stiffness_N_per_m *
                                               std::max(0.0, r.xm[i] - p.master_fixture.position_m);
    EXPECT_NEAR(r.master[i].force_N, own_m, 1e-9) << k;
    const double hold_s =
        g.kps * (alpha * hold - r.xs[i]) - (g.kds + g.kvs) * r.vs[i] -
        p.slave_fixture.stiffness_N_per_m * std::max(0.0, r.xs[i] - p.slave_fixture.position_m);
    EXPECT_NEAR(r.slave[i].force_N, hold_s, 1e-9) << k;
  }
}

TEST(Clutch, ReleaseAbsorbsTheOffsetAndTheLawResumes) {
  const LawParams p = clutch_params(kFade_s);
  const Gains& g = p.gains;
  const ClutchRun r = simulate(p);
  const double alpha = p.scaling.position;
  const double beta = p.scaling.force;
  const double hold = r.xm[kEngage - 1];
  const double offset = r.xm[kRelease] - hold;
  EXPECT_GT(std::abs(offset), 1e-3);  // the master really moved while clutched
  // The published position continues from x_hold: no jump of the slave's reference.
  EXPECT_NEAR(r.master_sent[kRelease].position_m, hold, 1e-15);
  EXPECT_FALSE(r.master_sent[kRelease].clutched);
  for (int k = kRelease; k < kSamples; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    EXPECT_NEAR(r.master_offset[i], offset, 1e-15);
    EXPECT_NEAR(r.master_sent[i].position_m, r.xm[i] - offset, 1e-15);
  }
  for (int k = kRelease + static_cast<int>(kN) + 3; k < kSamples; ++k) {
    const std::size_t i = static_cast<std::size_t>(k);
    const double fam =
        beta * (g.kpm * (r.xm[i] - offset - r.xs[i - 1] / alpha) +
                g.kdm * (r.vm[i] - r.vs[i - 1] / alpha) + g.kfm * r.fe[i - 1]) +
        g.kvm * r.vm[i] +
        p.master_fixture.stiffness_N_per_m * std::max(0.0, r.xm[i] - p.master_fixture.position_m);
    EXPECT_NEAR(r.master[i].force_N, fam, 1e-9) << k;
    const double fas =
        g.kps * (alpha * (r.xm[i - 1] - offset) - r.xs[i]) +
        g.kds * (alpha * r.vm[i - 1] - r.vs[i]) - g.kvs * r.vs[i] -
        p.slave_fixture.stiffness_N_per_m * std::max(0.0, r.xs[i] - p.slave_fixture.position_m);
    EXPECT_NEAR(r.slave[i].force_N, fas, 1e-9) << k;
  }
}

TEST(Clutch, EngagedAtStartAlignsMasterToSlave) {
  // Start clutched: the slave holds where it is; on release the master's published position
  // is the slave's / alpha, so the slave's reference does not move.
  LawParams p = clutch_params(kFade_s);
  MasterLaw master(p);
  SlaveLaw slave(p);
  master.set_clutch(true);
  const double alpha = p.scaling.position;
  const double xs0 = 0.004;
  PeerState to_slave;
  PeerState to_master;
  double xm = 0.05;  // far from the slave in master coordinates
  for (int k = 0; k < 50; ++k) {
    xm += 1e-5;
    const Command cm = master.step(xm, to_master);
    const Command cs = slave.step(xs0, 0.0, to_slave);
    EXPECT_NEAR(cs.force_N, 0.0, 1e-12);
    EXPECT_NEAR(cm.force_N,
                p.gains.kvm * master.velocity_m_per_s() + 800.0 * std::max(0.0, xm - 0.012), 1e-9);
    to_slave = master.peer_state();
    to_master = slave.peer_state();
  }
  master.set_clutch(false);
  for (int k = 0; k < 5; ++k) {
    static_cast<void>(master.step(xm, to_master));
    static_cast<void>(slave.step(xs0, 0.0, to_slave));
    to_slave = master.peer_state();
    to_master = slave.peer_state();
    EXPECT_NEAR(to_slave.position_m, xs0 / alpha, 1e-15);
    EXPECT_NEAR(slave.reference_m(), xs0, 1e-15);
  }
}

TEST(Clutch, LinkLossHoldsTheSlaveAndFadesTheMaster) {
  const LawParams p = clutch_params(kFade_s);
  MasterLaw master(p);
  SlaveLaw slave(p);
  PeerState lost;  // valid = false
  for (int k = 0; k < 100; ++k) {
    static_cast<void>(master.step(0.001, test::peer(0.0)));
    static_cast<void>(slave.step(0.0, 0.0, test::peer(0.001)));
  }
  EXPECT_EQ(master.coupling_weight(), 1.0);
  for (int k = 0; k < 30; ++k) {
    static_cast<void>(master.step(0.001 + k * 1e-5, lost));
    static_cast<void>(slave.step(0.0, 0.0, lost));
    EXPECT_TRUE(slave.holding());
    EXPECT_NEAR(slave.reference_m(), 1.5 * 0.001, 1e-15);
  }
  EXPECT_EQ(master.coupling_weight(), 0.0);
  EXPECT_EQ(slave.reference_weight(), 0.0);
}

}  // namespace
}  // namespace teleop::control
