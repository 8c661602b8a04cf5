#include "supervisor/teleopctl/progress_line.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <utility>

namespace teleop::ctl {

bool stderr_is_terminal() { return ::isatty(STDERR_FILENO) == 1; }

ProgressLine::ProgressLine(std::ostream& err, std::string label, bool enabled)
    : err_(err), label_(std::move(label)), enabled_(enabled) {}

ProgressLine::~ProgressLine() {
  // Erase the line: what the command prints next starts at column 0 of a clean line.
  if (drawn_) err_ << "\r\033[K" << std::flush;
}

void ProgressLine::update(double fraction) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  if (drawn_ && now < next_draw_) return;
  next_draw_ = now + std::chrono::milliseconds(100);
  const double f = std::clamp(fraction, 0.0, 1.0);
  err_ << fmt::format("\r\033[K{}: {:3.0f}%", label_, 100.0 * f) << std::flush;
  drawn_ = true;
}

void ProgressLine::update(std::size_t done, std::size_t total) {
  if (!enabled_ || total == 0) return;
  update(static_cast<double>(done) / static_cast<double>(total));
}

}  // namespace teleop::ctl
