#include "common/stability/discrete_model.hpp"

#include <cmath>
#include <numbers>

namespace teleop::stability {

const char* to_string(Structure s) {
  switch (s) {
    case Structure::kBilateral:
      return "bilateral";
    case Structure::kDecoupled:
      return "decoupled";
    case Structure::kSlaveOnly:
      return "slave_only";
    case Structure::kMasterOnly:
      return "master_only";
  }
  return "bilateral";
}

Structure structure_of(bool master_feels_slave, bool slave_follows_master, bool master_actuated,
                       bool slave_in_loop) {
  if (master_feels_slave && slave_follows_master) return Structure::kBilateral;
  if (master_actuated && slave_in_loop) return Structure::kDecoupled;
  if (master_actuated) return Structure::kMasterOnly;
  return Structure::kSlaveOnly;
}

DiscreteModel::DiscreteModel(const TeleopParams& params, bool master_wall_used,
                             bool slave_wall_used)
    : p_(params), period_s_(params.period_s()) {
  if (p_.velocity_cutoff_hz > 0.0) {
    filter_r_ = std::exp(-2.0 * std::numbers::pi * p_.velocity_cutoff_hz * period_s_);
    filter_a_ = -std::expm1(-2.0 * std::numbers::pi * p_.velocity_cutoff_hz * period_s_);
  }
  slave_plant_ =
      discretize_plant(p_.slave_device.mass_kg, p_.slave_device.damping_Ns_per_m, 0.0, period_s_);

  const Gains& g = p_.gains;
  const double beta = p_.scaling.force;
  // F_e is exogenous and constant about the equilibrium, so K_fm never closes a loop here.
  const bool master_feels_slave = beta != 0.0 && (g.kpm != 0.0 || g.kdm != 0.0);
  const bool slave_follows_master = g.kps != 0.0 || g.kds != 0.0;
  const bool master_actuated = master_feels_slave || g.kvm != 0.0 ||
                               p_.master_fixture.stiffness_N_per_m != 0.0 || master_wall_used;
  // A slave that does not follow the master is not part of the teleoperator (haptic-only use);
  // it is analysed only when its own fixture is what is asked about.
  const bool slave_in_loop = slave_follows_master || slave_wall_used ||
                             p_.slave_fixture.stiffness_N_per_m != 0.0 || !master_actuated;
  structure_ =
      structure_of(master_feels_slave, slave_follows_master, master_actuated, slave_in_loop);
}

ZohPlant DiscreteModel::master_plant(const HumanImpedance& human) const {
  return discretize_plant(p_.master_device.mass_kg + human.mass_kg,
                          p_.master_device.damping_Ns_per_m + human.damping_Ns_per_m,
                          human.stiffness_N_per_m, period_s_);
}

std::vector<ModelBlock> DiscreteModel::build(const ZohPlant& master_plant, double kmvf,
                                             double ksvf) const {
  return blocks_of<ModelBlock>(structure_, [&](bool with_master, bool with_slave) {
    return build_block(with_master, with_slave, master_plant, kmvf, ksvf);
  });
}

ModelBlock DiscreteModel::build_block(bool with_master, bool with_slave,
                                      const ZohPlant& master_plant, double kmvf,
                                      double ksvf) const {
  using Row = Eigen::RowVectorXd;
  const Gains& g = p_.gains;
  const double t = period_s_;
  const double alpha = p_.scaling.position;
  const double beta = p_.scaling.force;
  const int delay = (with_master && with_slave) ? p_.round_trip_delay_samples : 0;

  // Velocities are carried as v*T (metres) so that every plant state has the same scale.
  int n = 0;
  const int ixm = with_master ? n : -1;
  n += with_master ? 2 : 0;
  const int ixs = with_slave ? n : -1;
  n += with_slave ? 2 : 0;
  const int id0 = n;  // delayed master positions x_m(k-1) ... x_m(k-d)
  n += delay;

  // The velocity terms of each controller are filtered together: one filter (or one
  // backward-difference memory) state per controller, so the non-trivial modes number 6 + d.
  auto velocity_signals = [&](int size) {
    Row em = Row::Zero(size);
    Row es = Row::Zero(size);
    if (with_master) {
      em(ixm) += beta * g.kdm + g.kvm;
      if (with_slave) em(ixs) -= beta * g.kdm / alpha;
    }
    if (with_slave) {
      es(ixs) -= g.kds + g.kvs;
      if (with_master) {
        const int src = delay > 0 ? id0 + delay - 1 : ixm;
        es(src) += g.kds * alpha;
      }
    }
    return std::pair{em, es};
  };
  const int plant_states = n;
  const auto [em0, es0] = velocity_signals(plant_states);
  const bool has_fm = with_master && !em0.isZero(0.0);
  const bool has_fs = with_slave && !es0.isZero(0.0);
  // With no low-pass, a master velocity signal proportional to the slave's (symmetric gains)
  // makes the two backward-difference memories proportional too: one state serves both, and
  // the paper's realisation shows the redundant one as its third identically-zero eigenvalue.
  double shared_ratio = 0.0;  // e_m = shared_ratio * e_s when the memory is shared
  bool shared = false;
  if (has_fm && has_fs && filter_r_ == 0.0) {
    shared_ratio = em0.dot(es0) / es0.squaredNorm();
    shared = (em0 - shared_ratio * es0).cwiseAbs().maxCoeff() <= 1e-14 * em0.cwiseAbs().maxCoeff();
  }
  n += (has_fm && !shared ? 1 : 0) + (has_fs ? 1 : 0);
  Row em = Row::Zero(n);
  Row es = Row::Zero(n);
  em.head(plant_states) = em0;
  es.head(plant_states) = es0;
  const int ifs = has_fs ? id0 + delay : -1;
  const int ifm = has_fm ? (shared ? ifs : id0 + delay + (has_fs ? 1 : 0)) : -1;
  const double fm_scale = shared ? shared_ratio : 1.0;

  // H(z) = a (z - 1) / (T (z - r)): out(k) = (a/T) e(k) + f(k), f(k+1) = r f(k) - (a^2/T) e(k).
  const double a = filter_a_;
  const double r = filter_r_;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);

  // Each plant row is phi * own state + gamma * (actuator force), the force a row vector over
  // the state. Written coefficient by coefficient: this runs for every human of a band.
  auto plant_rows = [&](int ix, const ZohPlant& pl, const Row& force, double sign) {
    A(ix, ix) = pl.phi(0, 0);
    A(ix, ix + 1) = pl.phi(0, 1) / t;
    A(ix + 1, ix) = t * pl.phi(1, 0);
    A(ix + 1, ix + 1) = pl.phi(1, 1);
    A.row(ix) += (sign * pl.gamma(0)) * force;
    A.row(ix + 1) += (sign * t * pl.gamma(1)) * force;
  };
  Row force = Row::Zero(n);
  if (with_master) {
    force(ixm) = beta * g.kpm + kmvf;
    if (with_slave) force(ixs) = -beta * g.kpm / alpha;
    if (has_fm) {
      force += (a / t) * em;
      force(ifm) += fm_scale;
    }
    // The master is pushed by -F_am (F_h - F_am = Z_m X_m); F_h* is constant here.
    plant_rows(ixm, master_plant, force, -1.0);
    if (has_fm && !shared) {
      A.row(ifm) = -(a * a / t) * em;
      A(ifm, ifm) += r;
    }
  }
  if (with_slave) {
    force.setZero();
    force(ixs) = -(g.kps + ksvf);
    if (with_master) force(delay > 0 ? id0 + delay - 1 : ixm) += alpha * g.kps;
    if (has_fs) {
      force += (a / t) * es;
      force(ifs) += 1.0;
    }
    plant_rows(ixs, slave_plant_, force, 1.0);
    if (has_fs) {
      A.row(ifs) = -(a * a / t) * es;
      A(ifs, ifs) += r;
    }
  }
  for (int j = 0; j < delay; ++j) {
    A(id0 + j, j == 0 ? ixm : id0 + j - 1) = 1.0;
  }

  ModelBlock block;
  block.a = std::move(A);
  block.includes_master = with_master;
  block.delay_first = delay > 0 ? id0 : -1;
  block.delay = delay;
  block.delay_source = delay > 0 ? ixm : -1;
  block.master_position = ixm;
  block.slave_position = ixs;
  // Paper realisation per included side: X(k), X(k-1), X(k-2) and its held input.
  const int paper_states = (with_master ? 4 : 0) + (with_slave ? 4 : 0) + delay;
  block.structural_zeros = paper_states - n;
  return block;
}

}  // namespace teleop::stability
