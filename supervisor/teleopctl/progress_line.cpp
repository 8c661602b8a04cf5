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

std::function<void(double)> ProgressLine::part(double begin, double end) {
  if (!enabled_) return {};
  return [this, begin, end](double f) { update(begin + (end - begin) * std::clamp(f, 0.0, 1.0)); };
}

std::function<void(std::uint64_t, std::uint64_t)> ProgressLine::part_bytes(double begin,
                                                                           double end) {
  if (!enabled_) return {};
  return [this, begin, end](std::uint64_t done, std::uint64_t total) {
    if (total == 0) return;
    update(begin +
           (end - begin) * std::min(1.0, static_cast<double>(done) / static_cast<double>(total)));
  };
}

std::pair<double, double> ProgressParts::next(double time) {
  const double begin = total_ > 0.0 ? at_ / total_ : 0.0;
  at_ += time;
  return {begin, total_ > 0.0 ? std::min(1.0, at_ / total_) : 1.0};
}

std::function<void(std::uint64_t, std::uint64_t)> ProgressParts::bytes(double time) {
  const auto [begin, end] = next(time);
  return line_.part_bytes(begin, end);
}

std::function<void(double)> ProgressParts::fraction(double time) {
  const auto [begin, end] = next(time);
  return line_.part(begin, end);
}

}  // namespace teleop::ctl
