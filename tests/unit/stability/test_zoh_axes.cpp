// The n-axis ZOH plant (issue 18): one axis equals zoh.hpp's discretize_plant; a coupled plant
// with proportional damping equals its modes discretised one by one (generalized eigenvectors
// of (K, M)) and mapped back; a coupled plant without is checked against Eigen's own matrix
// exponential (unsupported/MatrixFunctions, Pade with scaling and squaring) of the augmented
// system; bad plants are refused by name.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <stdexcept>
#include <unsupported/Eigen/MatrixFunctions>

#include "common/stability/zoh.hpp"
#include "common/stability/zoh_axes.hpp"

namespace teleop::stability {
namespace {

// A 3-axis arm's task-space mass matrix (kg): symmetric positive definite, coupled.
Eigen::MatrixXd coupled_mass() {
  Eigen::MatrixXd m(3, 3);
  m << 0.30, 0.05, -0.02,  //
      0.05, 0.22, 0.04,    //
      -0.02, 0.04, 0.18;
  return m;
}

Eigen::MatrixXd coupled_stiffness() {
  Eigen::MatrixXd k(3, 3);
  k << 900, -200, 0,   //
      -200, 700, 150,  //
      0, 150, 500;
  return k;
}

TEST(ZohAxes, OneAxisIsTheScalarDiscretisation) {
  for (const double k : {0.0, 70.0, 3000.0}) {
    const ZohPlant one = discretize_plant(0.040, 0.41, k, 1e-3);
    const ZohPlantAxes n = discretize_plant_axes(Eigen::MatrixXd::Constant(1, 1, 0.040),
                                                 Eigen::MatrixXd::Constant(1, 1, 0.41),
                                                 Eigen::MatrixXd::Constant(1, 1, k), 1e-3);
    ASSERT_EQ(n.phi.rows(), 2);
    ASSERT_EQ(n.gamma.cols(), 1);
    EXPECT_LT((n.phi - one.phi).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_LT((n.gamma - one.gamma).cwiseAbs().maxCoeff(), 1e-18);
  }
}

TEST(ZohAxes, ProportionalDampingDecouplesIntoModes) {
  // B = alpha M + beta K: with K Phi = M Phi Lambda and Phi^T M Phi = I the modes
  // eta'' + (alpha + beta lambda_i) eta' + lambda_i eta = (Phi^T u)_i are independent unit
  // masses; x = Phi eta and x' = Phi eta'.
  const Eigen::MatrixXd m = coupled_mass();
  const Eigen::MatrixXd k = coupled_stiffness();
  const double alpha = 3.0;
  const double beta = 2e-3;
  const Eigen::MatrixXd b = alpha * m + beta * k;
  const double t = 1e-3;
  const ZohPlantAxes plant = discretize_plant_axes(m, b, k, t);

  const Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> modes(k, m);
  const Eigen::MatrixXd v = modes.eigenvectors();  // Phi, M-orthonormal
  Eigen::MatrixXd phi_modal = Eigen::MatrixXd::Zero(6, 6);
  Eigen::MatrixXd gamma_modal = Eigen::MatrixXd::Zero(6, 3);
  for (int i = 0; i < 3; ++i) {
    const double lambda = modes.eigenvalues()(i);
    const ZohPlant one = discretize_plant(1.0, alpha + beta * lambda, lambda, t);
    phi_modal(i, i) = one.phi(0, 0);
    phi_modal(i, 3 + i) = one.phi(0, 1);
    phi_modal(3 + i, i) = one.phi(1, 0);
    phi_modal(3 + i, 3 + i) = one.phi(1, 1);
    gamma_modal(i, i) = one.gamma(0);
    gamma_modal(3 + i, i) = one.gamma(1);
  }
  Eigen::MatrixXd to_x = Eigen::MatrixXd::Zero(6, 6);
  to_x.topLeftCorner(3, 3) = v;
  to_x.bottomRightCorner(3, 3) = v;
  const Eigen::MatrixXd phi = to_x * phi_modal * to_x.inverse();
  const Eigen::MatrixXd gamma = to_x * gamma_modal * v.transpose();
  EXPECT_LT((plant.phi - phi).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LT((plant.gamma - gamma).cwiseAbs().maxCoeff(), 1e-14);
}

TEST(ZohAxes, CoupledPlantMatchesTheAugmentedMatrixExponential) {
  // Non-proportional damping (the modes do not decouple) and a long period (many squarings):
  // exp([[A, Bu], [0, 0]] T) = [[Phi, Gamma], [0, I]].
  const Eigen::MatrixXd m = coupled_mass();
  const Eigen::MatrixXd k = coupled_stiffness();
  Eigen::MatrixXd b(3, 3);
  b << 2.0, 0.5, 0.0,  //
      -0.3, 1.2, 0.4,  //
      0.0, 0.1, 0.8;
  for (const double t : {1e-4, 1e-3, 2e-2}) {
    const ZohPlantAxes plant = discretize_plant_axes(m, b, k, t);
    const Eigen::MatrixXd m_inv = m.inverse();
    Eigen::MatrixXd aug = Eigen::MatrixXd::Zero(9, 9);
    aug.block(0, 3, 3, 3) = Eigen::MatrixXd::Identity(3, 3);
    aug.block(3, 0, 3, 3) = -m_inv * k;
    aug.block(3, 3, 3, 3) = -m_inv * b;
    aug.block(3, 6, 3, 3) = m_inv;
    const Eigen::MatrixXd e = (aug * t).exp();
    // Eigen's exponential is in double: scaling and squaring leaves an error of about the unit
    // roundoff times ||A T|| (Higham): the bound grows with the period.
    const double tol = 1e-13 * (1.0 + (aug * t).cwiseAbs().rowwise().sum().maxCoeff());
    EXPECT_LT((plant.phi - e.topLeftCorner(6, 6)).cwiseAbs().maxCoeff(), tol) << t;
    EXPECT_LT((plant.gamma - e.block(0, 6, 6, 3)).cwiseAbs().maxCoeff(), tol * t) << t;
  }
}

TEST(ZohAxes, BadPlantsAreRefusedByName) {
  const Eigen::MatrixXd z = Eigen::MatrixXd::Zero(3, 3);
  Eigen::MatrixXd asym = coupled_mass();
  asym(0, 1) += 0.01;
  EXPECT_EQ(check_plant_axes(asym, z, z), "the mass matrix must be symmetric");
  Eigen::MatrixXd indefinite = coupled_mass();
  indefinite(2, 2) = -0.1;
  EXPECT_EQ(check_plant_axes(indefinite, z, z), "the mass matrix must be positive definite");
  EXPECT_EQ(check_plant_axes(coupled_mass(), Eigen::MatrixXd::Zero(2, 2), z),
            "mass, damping and stiffness must all be 3x3");
  Eigen::MatrixXd nan = z;
  nan(1, 1) = std::nan("");
  EXPECT_EQ(check_plant_axes(coupled_mass(), nan, z), "mass, damping and stiffness must be finite");
  EXPECT_EQ(check_plant_axes(Eigen::MatrixXd::Identity(7, 7), Eigen::MatrixXd::Zero(7, 7),
                             Eigen::MatrixXd::Zero(7, 7)),
            "the plant must have 1 to 6 axes, got 7");
  EXPECT_THROW((void)discretize_plant_axes(indefinite, z, z, 1e-3), std::invalid_argument);
  EXPECT_THROW((void)discretize_plant_axes(coupled_mass(), z, z, 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace teleop::stability
