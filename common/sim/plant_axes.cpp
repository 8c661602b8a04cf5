#include "common/sim/plant_axes.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "common/sim/switch_search.hpp"

namespace teleop::sim {

namespace {

constexpr int kMaxState = 2 * kMaxAxes;
using MatL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxState, kMaxState>;
using InL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxState, kMaxAxes>;

constexpr std::uint64_t kTicksPerPeriod = std::uint64_t{1} << PlantAxes::kTickBits;
constexpr int kLevels = PlantAxes::kTickBits + 1;

void require(bool ok, const std::string& field, const char* what) {
  if (!ok) throw std::invalid_argument("plant_axes: " + field + " " + what);
}

// An event function g > 0 at both ends, with first derivatives d and second derivatives s at
// the ends: where g'' keeps its sign g' is monotone and may_dip is complete; otherwise the
// travel bound.
bool may_cross(double g0, double d0, double s0, double g1, double d1, double s1,
               double dt) noexcept {
  if (s0 * s1 >= 0.0) return d0 * d1 < 0.0 && may_dip(g0, d0, g1, d1, dt);
  const double rate =
      0.5 * (std::abs(d0) + std::abs(d1) + std::max(std::abs(s0), std::abs(s1)) * dt);
  return may_reach(g0, g1, rate, dt);
}

// y = m x for the leading n x n block, summed left to right from 0 (for n = 1 exactly m x).
inline double row_dot(const AxesMatrix& m, int row, const AxesVector& x, int n) noexcept {
  double sum = 0.0;
  for (int k = 0; k < n; ++k) sum += m(row, k) * x(k);
  return sum;
}

bool symmetric(const Eigen::MatrixXd& m) {
  return m.isApprox(m.transpose(), 1e-12) || m.cwiseAbs().maxCoeff() == 0.0;
}

bool positive_semidefinite(const Eigen::MatrixXd& m) {
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(m, Eigen::EigenvaluesOnly);
  const double scale = std::max(1.0, m.cwiseAbs().maxCoeff());
  return eig.info() == Eigen::Success && eig.eigenvalues().minCoeff() >= -1e-12 * scale;
}

void check_human_matrix(const Eigen::MatrixXd& m, Eigen::Index n, const char* field) {
  if (m.size() == 0) return;
  require(m.rows() == n && m.cols() == n, field, "must be empty or n x n");
  require(m.allFinite(), field, "must be finite");
  require(symmetric(m), field, "must be symmetric");
  require(positive_semidefinite(m), field, "must be positive semidefinite");
}

AxesMatrix or_zero(const Eigen::MatrixXd& m, int n) {
  if (m.size() == 0) return AxesMatrix::Zero(n, n);
  return m;
}

}  // namespace

PlantAxesParams to_axes(const PlantParams& one_axis) {
  require(one_axis.environment.kind != EnvironmentKind::kRigidWall, "environment.kind",
          "rigid_wall is not modelled by PlantAxes (use a stiff plane)");
  require(one_axis.method == SteppingMethod::kEventLocation, "method",
          "must be event_location (PlantAxes has no sub-stepping)");
  PlantAxesParams p;
  p.device.mass_kg = Eigen::MatrixXd::Constant(1, 1, one_axis.device.mass_kg);
  p.device.damping_Ns_per_m = Eigen::VectorXd::Constant(1, one_axis.device.damping_Ns_per_m);
  p.device.coulomb_N = Eigen::VectorXd::Constant(1, one_axis.coulomb_friction_N);
  const HumanImpedance& h = one_axis.human;
  p.human.mass_kg = Eigen::MatrixXd::Constant(1, 1, h.mass_kg);
  p.human.damping_Ns_per_m = Eigen::MatrixXd::Constant(1, 1, h.damping_Ns_per_m);
  p.human.stiffness_N_per_m = Eigen::MatrixXd::Constant(1, 1, h.stiffness_N_per_m);
  const Environment& env = one_axis.environment;
  if (env.kind == EnvironmentKind::kTissue) {
    p.planes.push_back(
        {Eigen::VectorXd::Ones(1), env.position_m, env.stiffness_N_per_m, env.damping_Ns_per_m});
  }
  return p;
}

PlantAxes::PlantAxes(const PlantAxesParams& params, std::chrono::nanoseconds period)
    : params_(params), period_s_(std::chrono::duration<double>(period).count()) {
  validate();
  n_ = params_.axes();
  planes_ = static_cast<int>(params_.planes.size());
  build_models();
  state_.position_m = AxesVector::Zero(n_);
  state_.velocity_m_per_s = AxesVector::Zero(n_);
  output_.acceleration_m_per_s2 = AxesVector::Zero(n_);
  output_.environment_force_N = AxesVector::Zero(n_);
  output_.human_force_N = AxesVector::Zero(n_);
}

void PlantAxes::validate() const {
  require(std::isfinite(period_s_) && period_s_ > 0.0, "period", "must be positive");
  const Eigen::MatrixXd& m = params_.device.mass_kg;
  const Eigen::Index n = m.rows();
  require(n >= 1 && n <= kMaxAxes && m.cols() == n, "device.mass_kg",
          "must be n x n with 1 <= n <= 6");
  require(m.allFinite(), "device.mass_kg", "must be finite");
  require(symmetric(m), "device.mass_kg", "must be symmetric");
  require(Eigen::LLT<Eigen::MatrixXd>(m).info() == Eigen::Success, "device.mass_kg",
          "must be positive definite");
  const Eigen::VectorXd& b = params_.device.damping_Ns_per_m;
  require(b.size() == n, "device.damping_Ns_per_m", "must have n entries");
  require(b.allFinite() && b.minCoeff() >= 0.0, "device.damping_Ns_per_m",
          "must be >= 0 and finite");
  const Eigen::VectorXd& c = params_.device.coulomb_N;
  require(c.size() == 0 || c.size() == n, "device.coulomb_N", "must be empty or have n entries");
  if (c.size() > 0) {
    require(c.allFinite() && c.minCoeff() >= 0.0, "device.coulomb_N", "must be >= 0 and finite");
  }
  check_human_matrix(params_.human.mass_kg, n, "human.mass_kg");
  check_human_matrix(params_.human.damping_Ns_per_m, n, "human.damping_Ns_per_m");
  check_human_matrix(params_.human.stiffness_N_per_m, n, "human.stiffness_N_per_m");
  if (c.size() > 0 && c.maxCoeff() > 0.0) {
    Eigen::MatrixXd total = m;
    if (params_.human.mass_kg.size() > 0) total += params_.human.mass_kg;
    const bool diagonal = (total - Eigen::MatrixXd(total.diagonal().asDiagonal())).isZero(0.0);
    require(diagonal, "device.coulomb_N",
            "needs a diagonal total mass (device.mass_kg + human.mass_kg): with a coupled mass "
            "the stuck axes' friction forces are coupled and per-axis sticking is not exact");
  }
  require(params_.planes.size() <= static_cast<std::size_t>(kMaxContactPlanes), "planes",
          "at most 4");
  for (std::size_t j = 0; j < params_.planes.size(); ++j) {
    const ContactPlane& p = params_.planes[j];
    const std::string at = "planes[" + std::to_string(j) + "].";
    require(p.normal.size() == n, at + "normal", "must have n entries");
    require(p.normal.allFinite() && std::abs(p.normal.norm() - 1.0) <= 1e-9, at + "normal",
            "must be a finite unit vector");
    require(std::isfinite(p.offset_m), at + "offset_m", "must be finite");
    require(std::isfinite(p.stiffness_N_per_m) && p.stiffness_N_per_m >= 0.0,
            at + "stiffness_N_per_m", "must be >= 0 and finite");
    require(std::isfinite(p.damping_Ns_per_m) && p.damping_Ns_per_m >= 0.0, at + "damping_Ns_per_m",
            "must be >= 0 and finite");
  }
}

// The per-contact-set matrices, the mass, and the propagator pool with its first modes.
void PlantAxes::build_models() {
  const int n = n_;
  human_mass_ = or_zero(params_.human.mass_kg, n);
  human_damping_ = or_zero(params_.human.damping_Ns_per_m, n);
  human_stiffness_ = or_zero(params_.human.stiffness_N_per_m, n);
  mass_kg_ = params_.device.mass_kg;
  mass_kg_ += human_mass_;
  mass_diagonal_ = (mass_kg_ - AxesMatrix(mass_kg_.diagonal().asDiagonal())).isZero(0.0);
  const Eigen::MatrixXd inverse = Eigen::MatrixXd(mass_kg_).inverse();
  mass_inverse_ = inverse;
  coulomb_N_ = AxesVector::Zero(n);
  if (params_.device.coulomb_N.size() == n) coulomb_N_ = params_.device.coulomb_N;
  friction_axes_ = 0;
  for (int i = 0; i < n; ++i) {
    if (coulomb_N_(i) > 0.0) friction_axes_ |= 1U << i;
  }
  for (int j = 0; j < planes_; ++j) {
    const ContactPlane& p = params_.planes[static_cast<std::size_t>(j)];
    const auto u = static_cast<std::size_t>(j);
    normal_[u] = p.normal;
    offset_m_[u] = p.offset_m;
    stiffness_[u] = p.stiffness_N_per_m;
    damping_[u] = p.damping_Ns_per_m;
  }
  for (unsigned c = 0; c < (1U << planes_); ++c) {
    ContactModel& model = model_[c];
    model.damping = AxesMatrix(params_.device.damping_Ns_per_m.asDiagonal());
    model.damping += human_damping_;
    model.stiffness = human_stiffness_;
    for (int j = 0; j < planes_; ++j) {
      if ((c & (1U << j)) == 0) continue;
      const auto u = static_cast<std::size_t>(j);
      model.damping += damping_[u] * normal_[u] * normal_[u].transpose();
      model.stiffness += stiffness_[u] * normal_[u] * normal_[u].transpose();
    }
    // |lambda| <= ||M^-1 B|| + sqrt(||M^-1 K||): chunks short against the mode's dynamics.
    double b_rate = 0.0;
    double k_rate = 0.0;
    for (int i = 0; i < n; ++i) {
      double b_row = 0.0;
      double k_row = 0.0;
      for (int k = 0; k < n; ++k) {
        if (mass_diagonal_) {
          b_row += std::abs(model.damping(i, k) / mass_kg_(i, i));
          k_row += std::abs(model.stiffness(i, k) / mass_kg_(i, i));
        } else {
          b_row += std::abs(row_dot(mass_inverse_, i, model.damping.col(k), n));
          k_row += std::abs(row_dot(mass_inverse_, i, model.stiffness.col(k), n));
        }
      }
      b_rate = std::max(b_rate, b_row);
      k_rate = std::max(k_rate, k_row);
    }
    const double fastest = b_rate + std::sqrt(k_rate);
    int level = 0;
    while (level < kTickBits && fastest * std::ldexp(period_s_, -level) > 0.25) ++level;
    model.guard_level = level;
  }
  // Modes: every contact set with every set of stuck axes (never all axes: at rest nothing
  // moves), stuck = 0 first.
  std::vector<int> keys;
  const unsigned all = (1U << n) - 1U;
  for (unsigned stuck = 0; stuck <= all; ++stuck) {
    if ((stuck & ~friction_axes_) != 0 || (stuck == all && stuck != 0)) continue;
    for (unsigned c = 0; c < (1U << planes_); ++c) {
      keys.push_back(static_cast<int>(c | (stuck << kMaxContactPlanes)));
    }
  }
  slot_count_ = std::min(static_cast<int>(keys.size()), kModeSlots);
  const auto level_size = static_cast<std::size_t>(6 * n * n);
  table_.assign(static_cast<std::size_t>(slot_count_) * kLevels * level_size, 0.0);
  slot_of_key_.assign(std::size_t{1} << (kMaxContactPlanes + n), -1);
  for (int s = 0; s < slot_count_; ++s) {
    Slot& slot = slots_[static_cast<std::size_t>(s)];
    slot.offset = static_cast<std::size_t>(s) * kLevels * level_size;
    fill(s, keys[static_cast<std::size_t>(s)]);
  }
}

// The exact solution of M x'' = D (g0 + g1 t - K x - B x') over tau (D zeroes the stuck axes'
// rows) as increments: x += X_v v + X_n n + X_r g1, v = V_v v + V_n n + V_r g1 with the net
// force n = g0 - K x. A Taylor series at tau = T / 2^36, then 36 doublings:
// W = exp(A tau) - I, G1 = int_0^tau exp(A s) ds Bin, G2 = int_0^tau exp(A (tau - s)) s ds Bin,
// W(2 tau) = 2 W + W^2, G1(2 tau) = (2 I + W) G1, G2(2 tau) = (2 I + W) G2 + tau G1.
void PlantAxes::fill(int slot_index, int key) noexcept {
  Slot& slot = slots_[static_cast<std::size_t>(slot_index)];
  if (slot.key >= 0) slot_of_key_[static_cast<std::size_t>(slot.key)] = -1;
  slot.key = key;
  slot.used = ++clock_;
  slot_of_key_[static_cast<std::size_t>(key)] = slot_index;
  const int n = n_;
  const int s2 = 2 * n;
  const auto contact = static_cast<unsigned>(key) & ((1U << kMaxContactPlanes) - 1U);
  const auto stuck = static_cast<unsigned>(key) >> kMaxContactPlanes;
  const ContactModel& model = model_[contact];
  MatL minv = MatL::Zero(n, n);
  for (int i = 0; i < n; ++i) {
    if ((stuck & (1U << i)) != 0) continue;
    for (int k = 0; k < n; ++k) {
      minv(i, k) = mass_diagonal_
                       ? (i == k ? 1.0L / static_cast<long double>(mass_kg_(i, i)) : 0.0L)
                       : static_cast<long double>(mass_inverse_(i, k));
    }
  }
  MatL a = MatL::Zero(s2, s2);
  a.topRightCorner(n, n).setIdentity();
  a.bottomLeftCorner(n, n) = -minv.lazyProduct(model.stiffness.cast<long double>());
  a.bottomRightCorner(n, n) = -minv.lazyProduct(model.damping.cast<long double>());
  InL in = InL::Zero(s2, n);
  in.bottomRows(n) = minv;
  long double tau = std::ldexp(static_cast<long double>(period_s_), -kTickBits);
  const MatL x = a * tau;
  const MatL identity = MatL::Identity(s2, s2);
  MatL term = identity;
  MatL w = MatL::Zero(s2, s2);
  MatL sum1 = identity;
  MatL sum2 = identity * 0.5L;
  for (int k = 1; k < 40; ++k) {
    const MatL product = term.lazyProduct(x);  // lazyProduct does not guard aliasing
    term = product / static_cast<long double>(k);
    w += term;
    sum1 += term / static_cast<long double>(k + 1);
    sum2 += term / static_cast<long double>((k + 1) * (k + 2));
    if (term.cwiseAbs().maxCoeff() <= 1e-30L) break;
  }
  InL g1 = (sum1 * tau).lazyProduct(in);
  InL g2 = (sum2 * (tau * tau)).lazyProduct(in);
  const auto level_size = static_cast<std::size_t>(6 * n * n);
  for (int level = kTickBits; level >= 0; --level) {
    double* out = table_.data() + slot.offset + static_cast<std::size_t>(level) * level_size;
    // Column-major 2n x 3n: [E(:, v) | G1 | G2].
    for (int col = 0; col < n; ++col) {
      for (int row = 0; row < s2; ++row) {
        const long double e = w(row, n + col) + (row == n + col ? 1.0L : 0.0L);
        out[static_cast<std::size_t>(col * s2 + row)] = static_cast<double>(e);
        out[static_cast<std::size_t>((n + col) * s2 + row)] = static_cast<double>(g1(row, col));
        out[static_cast<std::size_t>((2 * n + col) * s2 + row)] = static_cast<double>(g2(row, col));
      }
    }
    if (level == 0) break;
    const MatL two_plus_w = identity * 2.0L + w;
    const InL g2_next = two_plus_w.lazyProduct(g2) + g1 * tau;  // no aliasing: temporaries
    const InL g1_next = two_plus_w.lazyProduct(g1);
    const MatL w_next = w * 2.0L + w.lazyProduct(w);
    g2 = g2_next;
    g1 = g1_next;
    w = w_next;
    tau *= 2.0L;
  }
}

const double* PlantAxes::propagators(unsigned contact, unsigned stuck) noexcept {
  const auto key = static_cast<int>(contact | (stuck << kMaxContactPlanes));
  int s = slot_of_key_[static_cast<std::size_t>(key)];
  if (s < 0) {
    // Least recently used slot.
    s = 0;
    for (int i = 1; i < slot_count_; ++i) {
      if (slots_[static_cast<std::size_t>(i)].used < slots_[static_cast<std::size_t>(s)].used) {
        s = i;
      }
    }
    fill(s, key);
    ++late_modes_;
  }
  Slot& slot = slots_[static_cast<std::size_t>(s)];
  slot.used = ++clock_;
  return table_.data() + slot.offset;
}

void PlantAxes::reset(const PlantAxesState& state) noexcept {
  state_ = state;
  output_ = {};
  output_.acceleration_m_per_s2 = AxesVector::Zero(n_);
  output_.environment_force_N = AxesVector::Zero(n_);
  output_.human_force_N = AxesVector::Zero(n_);
}

double PlantAxes::normal_dot(int plane, const AxesVector& v) const noexcept {
  const AxesVector& normal = normal_[static_cast<std::size_t>(plane)];
  double sum = 0.0;
  for (int i = 0; i < n_; ++i) sum += normal(i) * v(i);
  return sum;
}

double PlantAxes::depth(int plane, const AxesVector& x) const noexcept {
  return normal_dot(plane, x) - offset_m_[static_cast<std::size_t>(plane)];
}

bool PlantAxes::plane_contact(int plane, const AxesVector& x, const AxesVector& v) const noexcept {
  const auto j = static_cast<std::size_t>(plane);
  const double d = depth(plane, x);
  return d > 0.0 && stiffness_[j] * d + damping_[j] * normal_dot(plane, v) > 0.0;
}

unsigned PlantAxes::contacts(const AxesVector& x, const AxesVector& v) const noexcept {
  unsigned mask = 0;
  for (int j = 0; j < planes_; ++j) {
    if (plane_contact(j, x, v)) mask |= 1U << j;
  }
  return mask;
}

void PlantAxes::net_force(const AxesVector& x, double tau, unsigned contact, const Input& in,
                          AxesVector& out) const noexcept {
  const AxesVector& u = *in.actuator;
  const AxesVector& f = *in.exogenous;
  const AxesVector& r = *in.slope;
  for (int i = 0; i < n_; ++i) {
    out(i) = u(i) + f(i) + r(i) * tau - row_dot(human_stiffness_, i, x, n_);
  }
  for (int j = 0; j < planes_; ++j) {
    if ((contact & (1U << j)) == 0) continue;
    const double push = stiffness_[static_cast<std::size_t>(j)] * depth(j, x);
    const AxesVector& normal = normal_[static_cast<std::size_t>(j)];
    for (int i = 0; i < n_; ++i) out(i) -= push * normal(i);
  }
}

void PlantAxes::net_drive(const Mode& mode, const AxesVector& x, double tau, const Input& in,
                          AxesVector& out) const noexcept {
  net_force(x, tau, mode.contact, in, out);
  for (int i = 0; i < n_; ++i) {
    out(i) -= static_cast<double>(mode.sign[static_cast<std::size_t>(i)]) * coulomb_N_(i);
  }
}

void PlantAxes::applied_force(unsigned contact, const AxesVector& x, const AxesVector& v,
                              double tau, const Input& in, AxesVector& out) const noexcept {
  net_force(x, tau, contact, in, out);
  const AxesMatrix& b = model_[contact].damping;
  for (int i = 0; i < n_; ++i) out(i) -= row_dot(b, i, v, n_);
}

void PlantAxes::acceleration(const Mode& mode, const AxesVector& x, const AxesVector& v, double tau,
                             const Input& in, AxesVector& out) const noexcept {
  AxesVector f(n_);
  net_drive(mode, x, tau, in, f);
  const AxesMatrix& b = model_[mode.contact].damping;
  for (int i = 0; i < n_; ++i) f(i) -= row_dot(b, i, v, n_);
  for (int i = 0; i < n_; ++i) {
    if ((mode.stuck & (1U << i)) != 0) {
      out(i) = 0.0;
    } else if (mass_diagonal_) {
      out(i) = f(i) / mass_kg_(i, i);
    } else {
      out(i) = row_dot(mass_inverse_, i, f, n_);
    }
  }
}

PlantAxes::Mode PlantAxes::classify(double tau, const Input& in) noexcept {
  Mode mode;
  const AxesVector& x = state_.position_m;
  const AxesVector& v = state_.velocity_m_per_s;
  mode.contact = contacts(x, v);
  if (friction_axes_ == 0) return mode;
  AxesVector p(n_);
  bool at_rest = false;
  for (int i = 0; i < n_; ++i) at_rest = at_rest || (coulomb_N_(i) > 0.0 && v(i) == 0.0);
  if (at_rest) applied_force(mode.contact, x, v, tau, in, p);
  for (int i = 0; i < n_; ++i) {
    const double fc = coulomb_N_(i);
    int& sign = mode.sign[static_cast<std::size_t>(i)];
    if (!(fc > 0.0)) continue;
    if (v(i) == 0.0) {
      if (p(i) >= -fc && p(i) <= fc) {
        mode.stuck |= 1U << i;
      } else {
        sign = p(i) > 0.0 ? 1 : -1;
      }
    } else {
      sign = v(i) > 0.0 ? 1 : -1;
    }
  }
  return mode;
}

bool PlantAxes::valid(const Mode& mode, const AxesVector& x, const AxesVector& v, double tau,
                      const Input& in) const noexcept {
  for (int i = 0; i < n_; ++i) {
    const int sign = mode.sign[static_cast<std::size_t>(i)];
    if (sign != 0 && static_cast<double>(sign) * v(i) <= 0.0) return false;
  }
  if (contacts(x, v) != mode.contact) return false;
  if (mode.stuck != 0) {
    AxesVector p(n_);
    applied_force(mode.contact, x, v, tau, in, p);
    for (int i = 0; i < n_; ++i) {
      if ((mode.stuck & (1U << i)) == 0) continue;
      if (!(p(i) >= -coulomb_N_(i) && p(i) <= coulomb_N_(i))) return false;
    }
  }
  return true;
}

bool PlantAxes::may_hide_event(const Mode& mode, double tau0, const PlantAxesState& s0, double tau1,
                               const PlantAxesState& s1, const Input& in) const noexcept {
  const double dt = tau1 - tau0;
  const AxesVector& x0 = s0.position_m;
  const AxesVector& v0 = s0.velocity_m_per_s;
  const AxesVector& x1 = s1.position_m;
  const AxesVector& v1 = s1.velocity_m_per_s;
  AxesVector a0(n_);
  AxesVector a1(n_);
  acceleration(mode, x0, v0, tau0, in, a0);
  acceleration(mode, x1, v1, tau1, in, a1);
  for (int i = 0; i < n_; ++i) {
    const int sign = mode.sign[static_cast<std::size_t>(i)];
    if (sign == 0) continue;
    const auto s = static_cast<double>(sign);
    if (may_dip(s * v0(i), s * a0(i), s * v1(i), s * a1(i), dt)) return true;
  }
  // Per plane, as Plant along its normal: the gap p - n^T x outside, k d + b n^T v inside.
  for (int j = 0; j < planes_; ++j) {
    const auto u = static_cast<std::size_t>(j);
    const double vn0 = normal_dot(j, v0);
    const double vn1 = normal_dot(j, v1);
    const double an0 = normal_dot(j, a0);
    const double an1 = normal_dot(j, a1);
    const double d0 = depth(j, x0);
    const double d1 = depth(j, x1);
    if ((mode.contact & (1U << j)) != 0) {
      const double k = stiffness_[u];
      const double b = damping_[u];
      const double c0 = k * d0 + b * vn0;
      const double c1 = k * d1 + b * vn1;
      const double r0 = k * vn0 + b * an0;
      const double r1 = k * vn1 + b * an1;
      if (an0 * an1 >= 0.0) {
        if (r0 * r1 < 0.0 && may_dip(c0, r0, c1, r1, dt)) return true;
      } else {
        const double a_max = std::max(std::abs(an0), std::abs(an1));
        const double v_max = 0.5 * (std::abs(vn0) + std::abs(vn1) + a_max * dt);
        if (may_reach(c0, c1, k * v_max + b * a_max, dt)) return true;
      }
    } else if (d0 <= 0.0 && d1 <= 0.0) {
      if (may_cross(-d0, -vn0, -an0, -d1, -vn1, -an1, dt)) return true;
    }
  }
  if (mode.stuck == 0) return false;
  // A stuck axis breaks free when |P_i| passes C_i: P_i' = g1_i - (K v)_i - (B a)_i, and
  // P_i'' is taken as -(K a)_i (the damping's jerk term is left out of the bound).
  AxesVector p0(n_);
  AxesVector p1(n_);
  applied_force(mode.contact, x0, v0, tau0, in, p0);
  applied_force(mode.contact, x1, v1, tau1, in, p1);
  const ContactModel& model = model_[mode.contact];
  for (int i = 0; i < n_; ++i) {
    if ((mode.stuck & (1U << i)) == 0) continue;
    const double r = (*in.slope)(i);
    const double dp0 = r - row_dot(model.stiffness, i, v0, n_) - row_dot(model.damping, i, a0, n_);
    const double dp1 = r - row_dot(model.stiffness, i, v1, n_) - row_dot(model.damping, i, a1, n_);
    const double sp0 = -row_dot(model.stiffness, i, a0, n_);
    const double sp1 = -row_dot(model.stiffness, i, a1, n_);
    const double fc = coulomb_N_(i);
    if (may_cross(fc - p0(i), -dp0, -sp0, fc - p1(i), -dp1, -sp1, dt)) return true;
    if (may_cross(fc + p0(i), dp0, sp0, fc + p1(i), dp1, sp1, dt)) return true;
  }
  return false;
}

void PlantAxes::propagate(const double* table, std::size_t level, const Mode& mode, double tau,
                          const Input& in, PlantAxesState& out) const noexcept {
  const int n = n_;
  const int rows = 2 * n;
  const double* p = table + level * static_cast<std::size_t>(6 * n * n);
  std::array<double, 3 * kMaxAxes> z{};
  AxesVector net(n);
  net_drive(mode, state_.position_m, tau, in, net);
  for (int i = 0; i < n; ++i) {
    const auto u = static_cast<std::size_t>(i);
    z[u] = state_.velocity_m_per_s(i);
    z[u + static_cast<std::size_t>(n)] = net(i);
    z[u + static_cast<std::size_t>(2 * n)] = (*in.slope)(i);
  }
  for (int row = 0; row < rows; ++row) {
    double sum = 0.0;
    for (int k = 0; k < 3 * n; ++k) {
      sum += p[static_cast<std::size_t>(k * rows + row)] * z[static_cast<std::size_t>(k)];
    }
    if (row < n) {
      out.position_m(row) = state_.position_m(row) + sum;
    } else {
      out.velocity_m_per_s(row - n) = sum;
    }
  }
}

// Every axis stuck: the state is constant and P linear in time; the first axis to pass a
// friction bound leaves rest.
double PlantAxes::rest_wait_s(const Mode& mode, double tau, const Input& in) const noexcept {
  AxesVector p(n_);
  applied_force(mode.contact, state_.position_m, state_.velocity_m_per_s, tau, in, p);
  double wait_s = std::numeric_limits<double>::infinity();
  for (int i = 0; i < n_; ++i) {
    const double ramp = (*in.slope)(i);
    const double fc = coulomb_N_(i);
    if (ramp > 0.0) {
      wait_s = std::min(wait_s, (fc - p(i)) / ramp);
    } else if (ramp < 0.0) {
      wait_s = std::min(wait_s, (-fc - p(i)) / ramp);
    }
  }
  return wait_s;
}

const PlantAxesOutput& PlantAxes::step(const AxesVector& actuator_N) noexcept {
  const AxesVector zero = AxesVector::Zero(n_);
  return step(actuator_N, zero, zero);
}

const PlantAxesOutput& PlantAxes::step(const AxesVector& actuator_N, const AxesVector& exogenous_N,
                                       const AxesVector& slope_N_per_s) noexcept {
  const Input in{&actuator_N, &exogenous_N, &slope_N_per_s};
  output_.events = 0;
  output_.first_event_s = -1.0;
  output_.event_limit_hit = false;
  step_events(in);
  finish(in);
  return output_;
}

void PlantAxes::step_events(const Input& in) noexcept {
  const double tick_s = std::ldexp(period_s_, -kTickBits);
  const unsigned all = (1U << n_) - 1U;
  AxesVector& x = state_.position_m;
  AxesVector& v = state_.velocity_m_per_s;
  EventClock clock{.end = kTicksPerPeriod};
  std::uint64_t& t = clock.t;
  const std::uint64_t end = clock.end;
  int events = 0;
  const auto seconds = [tick_s](std::uint64_t ticks) {
    return static_cast<double>(ticks) * tick_s;
  };
  const auto count_event = [&]() {
    if (events == 0) output_.first_event_s = seconds(t);
    ++events;
    if (events >= kMaxEventsPerStep) clock.frozen = true;
  };
  const auto stop_sliding = [&](const Mode& mode) {
    for (int i = 0; i < n_; ++i) {
      const int sign = mode.sign[static_cast<std::size_t>(i)];
      if (sign != 0 && static_cast<double>(sign) * v(i) <= 0.0) v(i) = 0.0;
    }
  };
  PlantAxesState next;
  next.position_m.setZero(n_);  // fixed capacity: no allocation
  next.velocity_m_per_s.setZero(n_);
  PlantAxesState past = next;
  while (t < end) {
    const Mode mode = classify(seconds(t), in);
    if (mode.stuck == all) {
      const double wait_s = rest_wait_s(mode, seconds(t), in);
      if (clock.frozen || !(wait_s < seconds(end - t))) break;
      const auto ticks = static_cast<std::uint64_t>(std::max(0.0, wait_s) / tick_s) + 1;
      t = std::min(end, t + ticks);
      count_event();
      continue;
    }
    const double* table = propagators(mode.contact, mode.stuck);
    const std::uint64_t guard = std::uint64_t{1} << (kTickBits - model_[mode.contact].guard_level);
    const SwitchSearchOps ops{
        [&](std::uint64_t t0, std::uint64_t chunk, PlantAxesState& out) {  // advance
          const auto level = static_cast<std::size_t>(kTickBits - std::countr_zero(chunk));
          propagate(table, level, mode, seconds(t0), in, out);
        },
        [&](std::uint64_t t1, const PlantAxesState& s) {  // valid
          return valid(mode, s.position_m, s.velocity_m_per_s, seconds(t1), in);
        },
        [&](std::uint64_t t0, std::uint64_t t1, const PlantAxesState& s1) {  // may_hide
          return may_hide_event(mode, seconds(t0), state_, seconds(t1), s1, in);
        },
        [&](const PlantAxesState& s) {  // accept
          x = s.position_m;
          v = s.velocity_m_per_s;
        },
        [&]() { stop_sliding(mode); },   // on_frozen
        [&]() { stop_sliding(mode); }};  // on_switch
    if (advance_to_switch<kMaxWorkPerStep>(clock, guard, next, past, ops)) count_event();
  }
  output_.events = events;
  output_.event_limit_hit = clock.frozen;
  total_events_ += static_cast<std::uint64_t>(events);
}

void PlantAxes::finish(const Input& in) noexcept {
  const Mode mode = classify(period_s_, in);
  const AxesVector& x = state_.position_m;
  const AxesVector& v = state_.velocity_m_per_s;
  output_.contact_mask = mode.contact;
  output_.stuck_mask = mode.stuck;
  AxesVector& a = output_.acceleration_m_per_s2;
  acceleration(mode, x, v, period_s_, in, a);
  AxesVector& env = output_.environment_force_N;
  env.setZero(n_);
  for (int j = 0; j < planes_; ++j) {
    const auto u = static_cast<std::size_t>(j);
    double f = 0.0;
    if ((mode.contact & (1U << j)) != 0) {
      f = std::max(0.0, stiffness_[u] * depth(j, x) + damping_[u] * normal_dot(j, v));
    }
    output_.plane_force_N[u] = f;
    for (int i = 0; i < n_; ++i) env(i) -= f * normal_[u](i);
  }
  AxesVector& h = output_.human_force_N;
  h.setZero(n_);
  for (int i = 0; i < n_; ++i) {
    h(i) = (*in.exogenous)(i) + (*in.slope)(i)*period_s_ - row_dot(human_mass_, i, a, n_) -
           row_dot(human_damping_, i, v, n_) - row_dot(human_stiffness_, i, x, n_);
  }
}

}  // namespace teleop::sim
