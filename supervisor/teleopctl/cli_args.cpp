#include "supervisor/teleopctl/cli_args.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>

namespace teleop::ctl {

double parse_number(const std::string& text, const std::string& what) {
  double v = 0.0;
  const char* last = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), last, v);
  if (ec != std::errc{} || ptr != last || !std::isfinite(v)) {
    throw UsageError(fmt::format("{}: '{}' is not a finite number", what, text));
  }
  return v;
}

std::vector<std::string> split(const std::string& s, char separator) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t pos = s.find(separator, start);
    parts.push_back(s.substr(start, pos - start));
    if (pos == std::string::npos) break;
    start = pos + 1;
  }
  return parts;
}

std::string svg_plot_path(const std::string& path) {
  const std::string_view ext = ".svg";
  if (path.size() <= ext.size() || path.compare(path.size() - ext.size(), ext.size(), ext) != 0) {
    throw UsageError(
        fmt::format("--plot writes SVG: give FILE.svg, not '{}' (for a PNG: rsvg-convert -o "
                    "FILE.png FILE.svg)",
                    path));
  }
  return path;
}

void take_only_positional(const std::string& arg, std::string& only,
                          std::string_view option_prefix) {
  if (arg.rfind(option_prefix, 0) == 0) throw UsageError("unknown option '" + arg + "'");
  if (!only.empty()) throw UsageError("unexpected argument '" + arg + "'");
  only = arg;
}

bool take_set_option(ArgCursor& cur, std::vector<std::string>& overrides) {
  if (cur.arg() != "--set") return false;
  overrides.push_back(cur.value("--set"));
  return true;
}

int parse_timeout_ms(const std::string& text) {
  const double t = parse_number(text, "--timeout-ms");
  if (!(t >= 1.0 && t <= 60000.0)) throw UsageError("--timeout-ms must be in [1, 60000]");
  return static_cast<int>(t);
}

}  // namespace teleop::ctl
