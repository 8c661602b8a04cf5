#include "common/config/axes_config.hpp"

#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "common/config/config_internal.hpp"
#include "common/config/parameter_space.hpp"
#include "common/config/text_format.hpp"
#include "common/control/plane_fixtures.hpp"

namespace teleop::config {
namespace {

namespace v1 = teleop::v1;
using Values = google::protobuf::RepeatedField<double>;
using text_format::format_float;
using text_format::Problems;

// Device masses in every direction: the one-axis rule of mass_kg (parameter_space.cpp), applied
// to the eigenvalues of the mass matrix.
constexpr double kMinMass_kg = 1e-4;
constexpr double kMaxMass_kg = 1e3;

// A computed value (an eigenvalue) to 6 significant digits: "-0.05", not "-0.04999999999999999".
std::string approx(double value) {
  std::array<char, 32> buffer{};
  std::snprintf(buffer.data(), buffer.size(), "%.6g", value + 0.0);  // -0 prints as 0
  return buffer.data();
}

bool all_finite(const Values& values) {
  for (const double v : values) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

// Every |element| <= ceiling: else check_fields names the element, and the matrix's eigenvalues
// (which would overflow) are not computed.
bool all_within(const Values& values, double ceiling) {
  for (const double v : values) {
    if (!(std::abs(v) <= ceiling)) return false;
  }
  return true;
}

// The ceiling of a Gains field (parameter_space.cpp's rule), +inf without one.
double gain_ceiling(const std::string& field, std::string& unit) {
  const FieldRule* rule = rule_for(v1::Gains::descriptor()->FindFieldByName(field));
  if (rule == nullptr) return std::numeric_limits<double>::infinity();
  unit = rule->unit.empty() ? "" : " " + std::string(rule->unit);
  return rule->max;
}

std::string axes_text(int n) { return "axes: " + std::to_string(n); }

// The n x n matrix of n*n row-major values, or the diagonal of n values.
Eigen::MatrixXd matrix_of(const Values& values, int n) {
  if (values.size() == n && n * n != n) {
    Eigen::MatrixXd m = Eigen::MatrixXd::Zero(n, n);
    for (int i = 0; i < n; ++i) m(i, i) = values[i];
    return m;
  }
  Eigen::MatrixXd m(n, n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) m(i, j) = values[i * n + j];
  }
  return m;
}

Eigen::VectorXd vector_of(const Values& values) {
  Eigen::VectorXd v(values.size());
  for (int i = 0; i < values.size(); ++i) v(i) = values[i];
  return v;
}

// Checks that m is symmetric (within kSymmetryTolerance of its largest element) and makes it
// exactly so; false (and a problem naming the first mirrored pair that differs) otherwise.
bool symmetrise(Problems& problems, const std::string& path, Eigen::MatrixXd& m) {
  const double scale = m.cwiseAbs().maxCoeff();
  const auto n = m.rows();
  for (Eigen::Index i = 0; i < n; ++i) {
    for (Eigen::Index j = i + 1; j < n; ++j) {
      if (std::abs(m(i, j) - m(j, i)) > kSymmetryTolerance * scale) {
        problems.add(path, "not symmetric: element [" + std::to_string(i * n + j) + "] (row " +
                               std::to_string(i) + ", column " + std::to_string(j) + ") is " +
                               format_float(m(i, j)) + " but element [" +
                               std::to_string(j * n + i) + "] (row " + std::to_string(j) +
                               ", column " + std::to_string(i) + ") is " + format_float(m(j, i)));
        return false;
      }
    }
  }
  m = 0.5 * (m + m.transpose()).eval();
  return true;
}

// n elements, or a problem saying how many there must be.
bool has_length(Problems& problems, const std::string& path, const Values& values, int length,
                const std::string& why) {
  if (values.size() == length) return true;
  problems.add(path, "must have " + std::to_string(length) + " elements (" + why + "), got " +
                         std::to_string(values.size()));
  return false;
}

// A scalar given together with its per-axis (or matrix) form.
void refuse_both(Problems& problems, const std::string& path, const std::string& scalar_name,
                 const std::string& vector_name) {
  problems.add(path, "give " + scalar_name + " (every axis) or " + vector_name + ", not both");
}

// The mass matrix: n*n row-major or its diagonal; symmetric, every eigenvalue (the mass along
// a principal direction) in [1e-4, 1e3] kg.
Eigen::MatrixXd read_mass(Problems& problems, const std::string& prefix, const v1::Device& d,
                          int n) {
  const std::string path = prefix + "mass_matrix_kg";
  const Values& values = d.mass_matrix_kg();
  if (values.empty()) return d.mass_kg() * Eigen::MatrixXd::Identity(n, n);
  if (d.has_mass_kg()) refuse_both(problems, path, "mass_kg", "mass_matrix_kg");
  if (values.size() != n * n && values.size() != n) {
    problems.add(path, "must have " + std::to_string(n * n) + " elements (" + std::to_string(n) +
                           " x " + std::to_string(n) + ", row-major) or " + std::to_string(n) +
                           " (the diagonal) for " + axes_text(n) + ", got " +
                           std::to_string(values.size()));
    return Eigen::MatrixXd::Identity(n, n);
  }
  Eigen::MatrixXd m = matrix_of(values, n);
  // Non-finite or out-of-range elements: check_fields names them.
  if (!all_finite(values) || !all_within(values, kMaxMass_kg) || !symmetrise(problems, path, m)) {
    return m;
  }
  const Eigen::VectorXd eigen =
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m, Eigen::EigenvaluesOnly).eigenvalues();
  if (!(eigen.minCoeff() > 0.0)) {
    problems.add(path, "not positive definite: its smallest eigenvalue is " +
                           approx(eigen.minCoeff()) +
                           " kg (a mass matrix is symmetric positive definite)");
  } else if (eigen.minCoeff() < kMinMass_kg || eigen.maxCoeff() > kMaxMass_kg) {
    problems.add(path, "its eigenvalues (the masses along its principal directions) must be in [" +
                           approx(kMinMass_kg) + ", " + approx(kMaxMass_kg) +
                           "] kg (0.1 g to 1 t, as mass_kg), got " + approx(eigen.minCoeff()) +
                           " to " + approx(eigen.maxCoeff()));
  }
  return m;
}

// A diagonal given as one scalar for every axis or n values.
Eigen::VectorXd read_diagonal(Problems& problems, const std::string& prefix, double scalar,
                              const char* scalar_name, const Values& per_axis,
                              const char* per_axis_name, int n) {
  if (per_axis.empty()) return Eigen::VectorXd::Constant(n, scalar);
  const std::string path = prefix + per_axis_name;
  if (scalar != 0.0) refuse_both(problems, path, scalar_name, per_axis_name);
  if (!has_length(problems, path, per_axis, n, "one per axis, " + axes_text(n))) {
    return Eigen::VectorXd::Constant(n, scalar);
  }
  return vector_of(per_axis);
}

DeviceAxesParams read_device(Problems& problems, const std::string& side, const v1::Device& d,
                             int n) {
  const std::string prefix = side + ".device.";
  DeviceAxesParams out;
  out.mass_kg = read_mass(problems, prefix, d, n);
  out.damping_Ns_per_m =
      read_diagonal(problems, prefix, d.damping_ns_per_m(), "damping_Ns_per_m",
                    d.damping_ns_per_m_per_axis(), "damping_Ns_per_m_per_axis", n);
  out.coulomb_N = read_diagonal(problems, prefix, d.coulomb_friction_n(), "coulomb_friction_N",
                                d.coulomb_n_per_axis(), "coulomb_N_per_axis", n);
  return out;
}

// Two elements into a, b.
bool read_pair(Problems& problems, const std::string& path, const Values& values, double& a,
               double& b) {
  if (!has_length(problems, path, values, 2, "one per arm of the linkage")) return false;
  a = values[0];
  b = values[1];
  return std::isfinite(a) && std::isfinite(b);  // non-finite: check_fields names it
}

void read_five_bar(Problems& problems, const std::string& path, const v1::FiveBar& f, int n,
                   KinematicsConfig& out) {
  out.kind = KinematicsConfig::Kind::kFiveBar;
  if (n != 2) {
    problems.add(path, "a five-bar linkage moves its end point on 2 task axes: set axes: 2, got " +
                           axes_text(n));
  }
  kinematics::FiveBarGeometry& g = out.five_bar;
  g.base_separation_m = f.base_separation_m();
  if (f.has_min_singularity_distance()) {
    out.min_singularity_distance = f.min_singularity_distance();
  }
  bool ok =
      read_pair(problems, path + ".proximal_m", f.proximal_m(), g.proximal_m[0], g.proximal_m[1]);
  ok = read_pair(problems, path + ".distal_m", f.distal_m(), g.distal_m[0], g.distal_m[1]) && ok;
  ok = read_pair(problems, path + ".home_joint_rad", f.home_joint_rad(), out.home_joint_rad[0],
                 out.home_joint_rad[1]) &&
       ok;
  if (!ok) return;
  if (const std::string why = kinematics::check(g); !why.empty()) {
    problems.add(path, why);
    return;
  }
  const auto pose = kinematics::forward(g, out.home_joint_rad);
  if (!pose) {
    problems.add(path + ".home_joint_rad",
                 "the linkage does not assemble at home: the elbows are further apart than the "
                 "distal links reach, or too close for them to meet at an angle");
    return;
  }
  out.home_end_m = pose->end_m;
  out.home_singularity_distance = pose->singularity_distance;
  if (!(pose->singularity_distance >= out.min_singularity_distance)) {
    problems.add(path + ".home_joint_rad",
                 "the home pose is " + approx(pose->singularity_distance) +
                     " from a singularity (the smallest |sin| of its transmission angles), below "
                     "min_singularity_distance " +
                     format_float(out.min_singularity_distance));
  }
}

KinematicsConfig read_kinematics(Problems& problems, const std::string& side, const v1::Device& d,
                                 int n) {
  KinematicsConfig out;
  if (!d.has_kinematics()) return out;
  const std::string path = side + ".device.kinematics";
  switch (d.kinematics().kind_case()) {
    case v1::Kinematics::kCartesian:
      break;
    case v1::Kinematics::kFiveBar:
      read_five_bar(problems, path + ".five_bar", d.kinematics().five_bar(), n, out);
      break;
    case v1::Kinematics::KIND_NOT_SET:
      problems.add(path, "give cartesian {} or five_bar { ... }");
      break;
  }
  return out;
}

// A USB device's actuators (Device.torque_constant_N_m_per_A / force_constant_N_per_A and
// amplifier_A_per_count): K_T in the unit the kinematics takes, n of each or none (a five-bar
// on USB needs them). Elements' signs and ceilings are check_fields'.
std::vector<ActuatorGains> read_actuators(Problems& problems, const std::string& side,
                                          const v1::Device& d, const KinematicsConfig& k, int n) {
  const std::string prefix = side + ".device.";
  const bool five_bar = k.kind == KinematicsConfig::Kind::kFiveBar;
  const char* fits = five_bar ? "torque_constant_N_m_per_A" : "force_constant_N_per_A";
  const char* other = five_bar ? "force_constant_N_per_A" : "torque_constant_N_m_per_A";
  const Values& constants = five_bar ? d.torque_constant_n_m_per_a() : d.force_constant_n_per_a();
  const Values& wrong = five_bar ? d.force_constant_n_per_a() : d.torque_constant_n_m_per_a();
  const Values& amplifier = d.amplifier_a_per_count();
  if (!wrong.empty()) {
    problems.add(prefix + other,
                 std::string("not for this device's kinematics: give ") + fits +
                     (five_bar ? " (a five-bar's joints take torque, N m/A)"
                               : " (a Cartesian axis takes force at the handle, N/A)"));
  }
  if (constants.empty() && amplifier.empty()) {
    if (five_bar && d.kind() == v1::USB) {
      problems.add(prefix + fits, "a USB five-bar needs its actuators' gains: " +
                                      std::to_string(n) + " elements (one per joint), and " +
                                      std::to_string(n) + " of amplifier_A_per_count");
    }
    return {};
  }
  const std::string why = "one per channel, " + axes_text(n);
  bool ok = has_length(problems, prefix + fits, constants, n, why);
  ok = has_length(problems, prefix + "amplifier_A_per_count", amplifier, n, why) && ok;
  if (!ok) return {};
  std::vector<ActuatorGains> out;
  for (int i = 0; i < n; ++i) out.push_back({constants[i], amplifier[i]});
  return out;
}

// The planes of one side. n = 1 without planes: the one-axis wall as the plane normal (+1) at
// its position (kept at stiffness 0, as to_axes does). n > 1 refuses the one-axis wall.
std::vector<PlaneFixtureParams> read_planes(Problems& problems, const std::string& side,
                                            const v1::Side& s, int n) {
  const v1::Fixture& f = s.fixture();
  const std::string prefix = side + ".fixture.";
  const bool one_axis_wall = f.stiffness_n_per_m() != 0.0 || f.position_m() != 0.0;
  if (f.plane().empty()) {
    if (n == 1) {
      return {{Eigen::VectorXd::Constant(1, 1.0), f.position_m(), f.stiffness_n_per_m()}};
    }
    if (one_axis_wall) {
      problems.add(prefix + (f.stiffness_n_per_m() != 0.0 ? "stiffness_N_per_m" : "position_m"),
                   "the one-axis wall; with " + axes_text(n) +
                       " give the fixture as fixture.plane { normal offset_m stiffness_N_per_m }");
    }
    return {};
  }
  if (one_axis_wall) {
    problems.add(prefix + (f.stiffness_n_per_m() != 0.0 ? "stiffness_N_per_m" : "position_m"),
                 "the one-axis wall: leave it out when fixture.plane is given (a wall is the "
                 "plane normal: [1])");
  }
  if (f.plane_size() > control::kMaxPlanes) {
    problems.add(prefix + "plane", "at most " + std::to_string(control::kMaxPlanes) +
                                       " planes a side, got " + std::to_string(f.plane_size()) +
                                       " (the law renders " + std::to_string(control::kMaxPlanes) +
                                       ")");
    return {};
  }
  std::vector<PlaneFixtureParams> out;
  for (int i = 0; i < f.plane_size(); ++i) {
    const v1::Plane& p = f.plane(i);
    const std::string path = prefix + "plane[" + std::to_string(i) + "].normal";
    if (!has_length(problems, path, p.normal(), n, "one per axis, " + axes_text(n)) ||
        !all_finite(p.normal())) {
      continue;
    }
    const Eigen::VectorXd normal = unit_direction(vector_of(p.normal()));
    if (normal.size() == 0) {
      problems.add(path, "must not be zero (a plane needs a direction)");
      continue;
    }
    out.push_back({normal, p.offset_m(), p.stiffness_n_per_m()});
  }
  return out;
}

// One gain: a scalar on every axis, its diagonal, or its whole matrix (symmetric positive
// semidefinite).
Eigen::MatrixXd read_gain(Problems& problems, const char* name, double scalar,
                          const Values& per_axis, const Values& matrix, int n) {
  const std::string base = std::string("gains.") + name;
  const int given = (scalar != 0.0 ? 1 : 0) + (per_axis.empty() ? 0 : 1) + (matrix.empty() ? 0 : 1);
  if (given > 1) {
    problems.add(matrix.empty() ? base + "_per_axis" : base + "_matrix",
                 std::string("give one of ") + name + " (every axis), " + name + "_per_axis or " +
                     name + "_matrix");
  }
  if (!matrix.empty()) {
    const std::string path = base + "_matrix";
    if (!has_length(
            problems, path, matrix, n * n,
            std::to_string(n) + " x " + std::to_string(n) + " row-major, " + axes_text(n)) ||
        !all_finite(matrix)) {
      return Eigen::MatrixXd::Zero(n, n);
    }
    std::string unit;
    const double element_ceiling = gain_ceiling(std::string(name) + "_matrix", unit);
    Eigen::MatrixXd m = matrix_of(matrix, n);
    if (!all_within(matrix, element_ceiling) || !symmetrise(problems, path, m)) return m;
    const Eigen::VectorXd eigen =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(m, Eigen::EigenvaluesOnly).eigenvalues();
    if (eigen.minCoeff() < -kSymmetryTolerance * m.cwiseAbs().maxCoeff()) {
      problems.add(path, "not positive semidefinite: its smallest eigenvalue is " +
                             approx(eigen.minCoeff()) +
                             " (a negative gain along a direction is positive feedback)");
    }
    // The scalar gain's ceiling holds along every direction (as mass_kg's range does for the
    // mass matrix): nine elements of 1e7 are 3e7 along (1, 1, 1) / sqrt(3).
    const double ceiling = gain_ceiling(name, unit);
    if (eigen.maxCoeff() > ceiling * (1.0 + kSymmetryTolerance)) {
      problems.add(path, "its largest eigenvalue (the gain along its principal direction) is " +
                             approx(eigen.maxCoeff()) + ", above " + approx(ceiling) + unit +
                             " (the ceiling of " + name + ")");
    }
    return m;
  }
  if (!per_axis.empty()) {
    const std::string path = base + "_per_axis";
    if (!has_length(problems, path, per_axis, n, "one per axis, " + axes_text(n))) {
      return Eigen::MatrixXd::Zero(n, n);
    }
    return vector_of(per_axis).asDiagonal();
  }
  return scalar * Eigen::MatrixXd::Identity(n, n);
}

GainsAxes read_gains(Problems& problems, const v1::Gains& g, int n) {
  GainsAxes out;
  out.kpm = read_gain(problems, "kpm", g.kpm(), g.kpm_per_axis(), g.kpm_matrix(), n);
  out.kps = read_gain(problems, "kps", g.kps(), g.kps_per_axis(), g.kps_matrix(), n);
  out.kdm = read_gain(problems, "kdm", g.kdm(), g.kdm_per_axis(), g.kdm_matrix(), n);
  out.kds = read_gain(problems, "kds", g.kds(), g.kds_per_axis(), g.kds_matrix(), n);
  out.kvm = read_gain(problems, "kvm", g.kvm(), g.kvm_per_axis(), g.kvm_matrix(), n);
  out.kvs = read_gain(problems, "kvs", g.kvs(), g.kvs_per_axis(), g.kvs_matrix(), n);
  out.kfm = read_gain(problems, "kfm", g.kfm(), g.kfm_per_axis(), g.kfm_matrix(), n);
  return out;
}

// The human on n axes from the one-axis model (`fixed` and `band` on every axis) or a band per
// axis. The bands themselves are check_band's (config_loader.cpp).
HumanModelAxes read_human(Problems& problems, const v1::Human& h, const HumanModel& one_axis,
                          int n) {
  HumanModelAxes out;
  const Eigen::MatrixXd identity = Eigen::MatrixXd::Identity(n, n);
  if (h.band_per_axis().empty()) {
    out.kind = one_axis.kind;
    out.fixed = {one_axis.fixed.mass_kg * identity, one_axis.fixed.damping_Ns_per_m * identity,
                 one_axis.fixed.stiffness_N_per_m * identity};
    if (one_axis.kind == HumanKind::kBand) {
      out.band_per_axis.assign(static_cast<std::size_t>(n), one_axis.band);
    }
    return out;
  }
  const std::string path = "human.band_per_axis";
  if (h.kind_case() != v1::Human::KIND_NOT_SET) {
    problems.add(path, "give human.fixed, human.band, human.none or human.band_per_axis, not two");
  }
  if (h.band_per_axis_size() != n) {
    problems.add(path, "must have " + std::to_string(n) + " bands (one per axis, " + axes_text(n) +
                           "), got " + std::to_string(h.band_per_axis_size()));
  }
  out.kind = HumanKind::kBand;
  out.fixed = {0.0 * identity, 0.0 * identity, 0.0 * identity};
  for (const v1::HumanBand& band : h.band_per_axis()) out.band_per_axis.push_back(to_band(band));
  return out;
}

// Every n-axis field of the configuration, read and checked; `one_axis` supplies what the
// n-axis form shares with the one-axis one (rate, scaling, filter, delay, human, analysis).
AxesConfig read_axes(const v1::SystemConfig& c, const TeleopParams& one_axis, Problems& problems) {
  AxesConfig out;
  const int n = configured_axes(c);
  TeleopAxesParams& t = out.teleop;
  t.axes = n;
  t.sample_rate_hz = one_axis.sample_rate_hz;
  t.master_device = read_device(problems, "master", c.master().device(), n);
  t.slave_device = read_device(problems, "slave", c.slave().device(), n);
  out.master_kinematics = read_kinematics(problems, "master", c.master().device(), n);
  out.slave_kinematics = read_kinematics(problems, "slave", c.slave().device(), n);
  out.master_actuators =
      read_actuators(problems, "master", c.master().device(), out.master_kinematics, n);
  out.slave_actuators =
      read_actuators(problems, "slave", c.slave().device(), out.slave_kinematics, n);
  t.master_planes = read_planes(problems, "master", c.master(), n);
  t.slave_planes = read_planes(problems, "slave", c.slave(), n);
  t.gains = read_gains(problems, c.gains(), n);
  t.scaling = one_axis.scaling;
  t.velocity_cutoff_hz = one_axis.velocity_cutoff_hz;
  t.round_trip_delay_samples = one_axis.round_trip_delay_samples;
  t.human = read_human(problems, c.human(), one_axis.human, n);
  t.analysis = one_axis.analysis;
  return out;
}

}  // namespace

Eigen::VectorXd unit_direction(const Eigen::VectorXd& v) {
  const double largest = v.size() == 0 ? 0.0 : v.cwiseAbs().maxCoeff();
  if (!(largest > 0.0) || !std::isfinite(largest)) return {};
  // Scaled first: the largest element becomes exactly +-1, so subnormal elements keep all their
  // digits and the norm neither underflows nor overflows.
  const Eigen::VectorXd scaled = v / largest;
  return scaled / scaled.norm();
}

int configured_axes(const v1::SystemConfig& config) noexcept {
  return config.has_axes() ? config.axes() : 1;
}

void check_axes(const LoadedConfig& config, text_format::Problems& problems) {
  const int n = configured_axes(config.config);
  if (n < 1 || n > kMaxAxes) return;  // check_fields names it; nothing below has a size
  (void)read_axes(config.config, TeleopParams{}, problems);
  check_scene_axes(config, problems);  // axes_scene_loader.cpp
}

void require_one_axis(const LoadedConfig& config) {
  const v1::SystemConfig& c = config.config;
  Problems problems(config);
  const std::string why =
      "this is the one-axis path (the nodes, the supervisor, analyze, simulate, identify, "
      "replay and the console take several axes through their own, issue 18; resimulate and "
      "guarded parameter changes do not yet): refused rather than run on the first axis";
  if (configured_axes(c) != 1) {
    problems.add("axes", std::to_string(configured_axes(c)) + " axes; " + why);
    problems.throw_if_any();
  }
  const auto n_axis_field = [&](const std::string& path, bool given) {
    if (given) problems.add(path, "an n-axis field, given with axes: 1; " + why);
  };
  for (const auto& [side, s] : {std::pair<std::string, const v1::Side*>{"master", &c.master()},
                                std::pair<std::string, const v1::Side*>{"slave", &c.slave()}}) {
    const v1::Device& d = s->device();
    n_axis_field(side + ".device.mass_matrix_kg", !d.mass_matrix_kg().empty());
    n_axis_field(side + ".device.damping_Ns_per_m_per_axis",
                 !d.damping_ns_per_m_per_axis().empty());
    n_axis_field(side + ".device.coulomb_N_per_axis", !d.coulomb_n_per_axis().empty());
    n_axis_field(side + ".device.kinematics.five_bar", d.kinematics().has_five_bar());
    n_axis_field(side + ".device.torque_constant_N_m_per_A",
                 !d.torque_constant_n_m_per_a().empty());
    n_axis_field(side + ".device.force_constant_N_per_A", !d.force_constant_n_per_a().empty());
    n_axis_field(side + ".device.amplifier_A_per_count", !d.amplifier_a_per_count().empty());
    n_axis_field(side + ".fixture.plane", !s->fixture().plane().empty());
  }
  const v1::Gains& g = c.gains();
  const std::array<std::pair<const char*, int>, 14> gains{{
      {"kpm_per_axis", g.kpm_per_axis_size()},
      {"kps_per_axis", g.kps_per_axis_size()},
      {"kdm_per_axis", g.kdm_per_axis_size()},
      {"kds_per_axis", g.kds_per_axis_size()},
      {"kvm_per_axis", g.kvm_per_axis_size()},
      {"kvs_per_axis", g.kvs_per_axis_size()},
      {"kfm_per_axis", g.kfm_per_axis_size()},
      {"kpm_matrix", g.kpm_matrix_size()},
      {"kps_matrix", g.kps_matrix_size()},
      {"kdm_matrix", g.kdm_matrix_size()},
      {"kds_matrix", g.kds_matrix_size()},
      {"kvm_matrix", g.kvm_matrix_size()},
      {"kvs_matrix", g.kvs_matrix_size()},
      {"kfm_matrix", g.kfm_matrix_size()},
  }};
  for (const auto& [name, size] : gains) n_axis_field(std::string("gains.") + name, size > 0);
  n_axis_field("human.band_per_axis", !c.human().band_per_axis().empty());
  n_axis_field("scene.human_force_direction", !c.scene().human_force_direction().empty());
  n_axis_field("scene.environment_plane", !c.scene().environment_plane().empty());
  problems.throw_if_any();
}

AxesConfig to_axes_config(const LoadedConfig& config) {
  validate(config);
  const TeleopParams one_axis = one_axis_params_of_validated(config);  // requires the sections
  Problems problems(config);
  AxesConfig out = read_axes(config.config, one_axis, problems);
  problems.throw_if_any();  // validate() has seen every problem: none here
  return out;
}

TeleopAxesParams to_axes_params(const LoadedConfig& config) {
  return to_axes_config(config).teleop;
}

GainsAxes gains_axes_of(const v1::Gains& gains, int n, std::string& why) {
  why.clear();
  const LoadedConfig none{};  // no file: each line starts ": " (its origin, empty)
  Problems problems(none);
  GainsAxes out = read_gains(problems, gains, n);
  try {
    problems.throw_if_any();
  } catch (const ConfigError& e) {
    std::string text = e.what();
    for (std::size_t at = 0; (at = text.find(": ", at)) != std::string::npos;) {
      // Drop the empty origin at the start of each line.
      if (at == 0 || text[at - 1] == '\n') {
        text.erase(at, 2);
      } else {
        at += 2;
      }
    }
    why = text;
  }
  return out;
}

}  // namespace teleop::config
