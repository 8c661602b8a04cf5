// A CSV file with a header row as named columns of finite numbers (`teleopctl identify` reads
// `teleopctl simulate --out` tables and any recorder's): the whole file in memory, column by
// column; a force as a sum of signed columns.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace teleop::ctl {

struct Csv {
  std::vector<std::string> names{};
  std::vector<std::vector<double>> columns{};
};

// How far a file is read: bytes done of its size (empty: not called).
using BytesRead = std::function<void(std::uint64_t done, std::uint64_t total)>;

// Throws std::runtime_error naming the file, line and column: unreadable, empty, no data rows, a
// row with another number of cells than the header, a cell that is not a finite number.
[[nodiscard]] Csv read_csv(const std::string& path, const BytesRead& read = {});

// The column `name`; throws naming the file, the column, what it was for and the columns there
// are.
[[nodiscard]] const std::vector<double>& column(const Csv& csv, const std::string& path,
                                                const std::string& name, const char* what);

// Sum of signed columns: an exact column name, or terms joined by '+' and '-'.
[[nodiscard]] std::vector<double> evaluate(const Csv& csv, const std::string& path,
                                           const std::string& expression, const char* what);

}  // namespace teleop::ctl
