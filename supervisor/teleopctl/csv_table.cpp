#include "supervisor/teleopctl/csv_table.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "supervisor/teleopctl/cli_args.hpp"

namespace teleop::ctl {

namespace {

[[nodiscard]] std::string trim_cr(std::string line) {
  if (!line.empty() && line.back() == '\r') line.pop_back();
  return line;
}

}  // namespace

Csv read_csv(const std::string& path, const BytesRead& read) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(fmt::format("cannot read '{}'", path));
  std::error_code ec_size;
  const std::uint64_t size = std::filesystem::file_size(path, ec_size);
  std::uint64_t done = 0;
  Csv csv;
  std::string line;
  if (!std::getline(in, line)) throw std::runtime_error(fmt::format("{}: empty file", path));
  csv.names = split(trim_cr(line), ',');
  csv.columns.resize(csv.names.size());
  std::size_t line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    done += line.size() + 1;
    if (read && !ec_size && line_no % 1000 == 0) read(done, size);
    line = trim_cr(line);
    if (line.empty()) continue;
    const std::vector<std::string> cells = split(line, ',');
    if (cells.size() != csv.names.size()) {
      throw std::runtime_error(fmt::format("{}:{}: {} cells, the header has {}", path, line_no,
                                           cells.size(), csv.names.size()));
    }
    for (std::size_t c = 0; c < cells.size(); ++c) {
      const std::string& cell = cells[c];
      double v = 0.0;
      const char* last = cell.data() + cell.size();
      const auto [ptr, ec] = std::from_chars(cell.data(), last, v);
      if (ec != std::errc{} || ptr != last || !std::isfinite(v)) {
        throw std::runtime_error(fmt::format("{}:{}: column '{}': '{}' is not a finite number",
                                             path, line_no, csv.names[c], cell));
      }
      csv.columns[c].push_back(v);
    }
  }
  if (csv.columns.empty() || csv.columns.front().empty()) {
    throw std::runtime_error(fmt::format("{}: no data rows", path));
  }
  if (read) read(1, 1);
  return csv;
}

const std::vector<double>& column(const Csv& csv, const std::string& path, const std::string& name,
                                  const char* what) {
  for (std::size_t c = 0; c < csv.names.size(); ++c) {
    if (csv.names[c] == name) return csv.columns[c];
  }
  std::string known;
  for (const std::string& n : csv.names) known += (known.empty() ? "" : ", ") + n;
  throw std::runtime_error(
      fmt::format("{}: no column '{}' for the {} (columns: {})", path, name, what, known));
}

std::vector<double> evaluate(const Csv& csv, const std::string& path, const std::string& expression,
                             const char* what) {
  const std::size_t rows = csv.columns.front().size();
  for (const std::string& n : csv.names) {
    if (n == expression) return column(csv, path, expression, what);
  }
  std::vector<double> sum(rows, 0.0);
  std::size_t i = 0;
  while (i < expression.size()) {
    double sign = 1.0;
    if (expression[i] == '+' || expression[i] == '-') {
      sign = expression[i] == '-' ? -1.0 : 1.0;
      ++i;
    }
    const std::size_t end = expression.find_first_of("+-", i);
    const std::string name = expression.substr(i, end == std::string::npos ? end : end - i);
    if (name.empty()) {
      throw std::runtime_error(fmt::format("the {} '{}' has an empty term", what, expression));
    }
    const std::vector<double>& c = column(csv, path, name, what);
    for (std::size_t r = 0; r < rows; ++r) sum[r] += sign * c[r];
    i = end == std::string::npos ? expression.size() : end;
  }
  return sum;
}

}  // namespace teleop::ctl
