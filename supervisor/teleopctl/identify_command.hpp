// `teleopctl identify FILE.csv...`: a device's mass and damping by least squares from recorded
// runs (Abbott-Okamura §4.1, eqs. 32-35; common/stability/identify.hpp), printed with the
// `--set` overrides that put them into a configuration, or refused when the data do not
// determine them; `--plot FILE.svg` shows the measured force against the fitted one. Reads the CSV
// time series `teleopctl simulate --out` writes, or any CSV with a header row through
// --time/--position/--force.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <string>
#include <vector>

#include "common/stability/identify.hpp"

namespace teleop::ctl {

[[nodiscard]] std::string identify_usage();

// Handles the whole command, usage errors included. Exit codes: 0 identified, 1 unreadable or
// unusable data (the message names the file, line, column or problem) or a fit with a
// non-positive mass or negative damping, 2 usage (`--help` prints the usage on `out`, exit 0),
// 4 not identified: too little excitation (r^2 below 0.9, or the position moving over fewer
// than 10 steps of its resolution), no parameters printed.
int run_identify(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);

// One CSV file as a run: the position column, the sampled force and held force as sums of
// signed columns ("human_force_N", "-environment_force_N", "a_N-b_N"; an empty held expression
// means none). position_lag_rows: the position column was sensed that many rows before the
// instant the forces of its row refer to, so the position of row k + lag goes with the forces
// of row k (the last rows are dropped). rate_hz > 0 uses that rate instead of the time column.
// Throws std::runtime_error naming the file, line and column. `read`: the bytes read of the
// file's size, every 1000 rows and at the end (empty: not called).
struct CsvColumns {
  std::string time{"time_s"};
  std::string position{};
  std::string force{};
  std::string held_force{};
  std::size_t position_lag_rows{0};
  double rate_hz{0.0};
};
[[nodiscard]] stability::Series read_series_csv(
    const std::string& path, const CsvColumns& columns,
    const std::function<void(std::uint64_t done, std::uint64_t total)>& read = {});

}  // namespace teleop::ctl
