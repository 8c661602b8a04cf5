// `teleopctl identify` with n task-space axes (issue 18 "identify"): several position columns
// (`--position x0,x1,x2`) and as many forces make an n-axis fit by common/stability/
// identify_axes.hpp, M x'' + B x' = F with M per axis or coupled and B diagonal or full, printed
// with the `--set` overrides of the n-axis configuration fields, or refused when the data do not
// determine it. From CSV files (identify_axes) or from runs a session file of n axes gave
// (identify_axes_runs; identify_command.cpp reads them).
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "common/stability/identify_axes.hpp"

namespace teleop::ctl {

struct IdentifyAxesArgs {
  std::vector<std::string> files{};
  std::optional<std::string> device{};  // master | slave: names the --set overrides
  // Per axis: the position column and the force expressions (sums of signed columns, as the
  // one-axis --force); held_force empty: none.
  std::vector<std::string> position{};
  std::vector<std::string> force{};
  std::vector<std::string> held_force{};
  std::string time{"time_s"};
  double rate_hz{0.0};  // > 0: instead of the time column
  stability::IdentifyAxesOptions options{};
  bool json{false};
};

// Exit codes as the one-axis command: 0 identified, 1 unreadable data or an unphysical fit (M
// not positive definite, negative damping), 4 not identified (r^2 below 0.9 overall or on an
// axis, or an axis moving over fewer than 10 steps of its resolution).
int identify_axes(const IdentifyAxesArgs& args, std::ostream& out, std::ostream& err);
// The same fit and report of runs already read: args.files names each run (its errors and the
// report name them); the column fields of args are not used.
int identify_axes_runs(const IdentifyAxesArgs& args, const std::vector<stability::SeriesAxes>& runs,
                       std::ostream& out, std::ostream& err);

}  // namespace teleop::ctl
