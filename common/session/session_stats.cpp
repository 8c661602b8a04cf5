#include "common/session/session_stats.hpp"

#include <algorithm>
#include <cmath>
#include <iterator>

#include "common/telemetry/cycle_codec.hpp"

namespace teleop::record {

void NodeTelemetryStats::add(const v1::Telemetry& t) {
  ++messages;
  cycles_dropped = std::max(cycles_dropped, t.cycles_dropped());
  if (t.flight_record_size() > 0) ++flight_records;
  const double period_ns = t.loop().period_s() * 1e9;
  for (const v1::CycleRecord& c : t.cycles()) {
    ++cycles;
    ++modes[v1::NodeMode_Name(c.mode())];
    add_axes(c);
    wakeups_ns_.push_back(c.wakeup_latency_ns());
    auto& second = per_second_[c.sample_time_ns() / 1'000'000'000];
    ++second.first;
    if (any && t.session_id() == session_id && c.sequence() == last_sequence + 1 &&
        period_ns > 0.0 && c.sample_time_ns() > last_sample_ns_) {
      const double periods = static_cast<double>(c.sample_time_ns() - last_sample_ns_) / period_ns;
      const auto skipped = static_cast<std::int64_t>(std::llround(periods)) - 1;
      if (skipped > 0) second.second += static_cast<std::uint64_t>(skipped);
    }
    last_sample_ns_ = c.sample_time_ns();
    if (!any) {
      first_sequence = c.sequence();
      session_id = t.session_id();
    } else if (t.session_id() != session_id) {
      ++restarts;
      session_id = t.session_id();
    } else if (c.sequence() > last_sequence + 1) {
      missing += c.sequence() - last_sequence - 1;
    } else if (c.sequence() <= last_sequence) {
      ++out_of_order;
    }
    any = true;
    last_sequence = c.sequence();
  }
}

void NodeTelemetryStats::add_axes(const v1::CycleRecord& c) {
  const std::optional<node::CycleRecordAxes> r = telemetry::axes_from_proto(c);
  if (!r) {
    if (refused == 0) first_refused_sequence = c.sequence();
    ++refused;
    return;
  }
  if (last_axes_ != 0 && r->axes != last_axes_) ++axes_changes;
  last_axes_ = r->axes;
  axes = std::max(axes, r->axes);
  for (int i = 0; i < r->axes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    const bool first = per_axis.size() <= k;
    if (first) per_axis.push_back({r->position_m[k], r->position_m[k], 0.0, 0.0});
    AxisSummary& a = per_axis[k];
    a.min_position_m = std::min(a.min_position_m, r->position_m[k]);
    a.max_position_m = std::max(a.max_position_m, r->position_m[k]);
    a.max_abs_force_N = std::max(a.max_abs_force_N, std::abs(r->force_N[k]));
    a.max_abs_command_N = std::max(a.max_abs_command_N, std::abs(r->command_N[k]));
  }
}

std::optional<WakeupLatencySummary> NodeTelemetryStats::wakeup_latency() const {
  if (wakeups_ns_.empty()) return std::nullopt;
  std::vector<std::int64_t> v = wakeups_ns_;
  std::sort(v.begin(), v.end());
  const auto quantile_us = [&v](double q) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(v.size())));
    return static_cast<double>(v[std::clamp<std::size_t>(rank, 1, v.size()) - 1]) * 1e-3;
  };
  WakeupLatencySummary w;
  const std::int64_t edges_us[] = {0, 50, 100, 200, 500, 1000, 2000, 5000};
  const std::size_t n = std::size(edges_us);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t lo = edges_us[i] * 1000;
    const bool last = i + 1 == n;
    const std::int64_t hi = last ? 0 : edges_us[i + 1] * 1000;
    const auto from = std::lower_bound(v.begin(), v.end(), lo);
    const auto to = last ? v.end() : std::lower_bound(v.begin(), v.end(), hi);
    w.histogram.push_back({edges_us[i],
                           last ? std::nullopt : std::optional<std::int64_t>(edges_us[i + 1]),
                           static_cast<std::uint64_t>(to - from)});
  }
  w.negative =
      static_cast<std::uint64_t>(std::lower_bound(v.begin(), v.end(), std::int64_t{0}) - v.begin());
  w.p50_us = quantile_us(0.5);
  w.p99_us = quantile_us(0.99);
  w.p999_us = quantile_us(0.999);
  w.max_us = static_cast<double>(v.back()) * 1e-3;
  return w;
}

OverrunSummary NodeTelemetryStats::overruns() const {
  OverrunSummary o;
  const std::uint64_t edges[] = {0, 1, 2, 10, 100};
  std::vector<std::uint64_t> seconds(std::size(edges), 0);
  for (const auto& [second, counts] : per_second_) {
    o.total += counts.second;
    o.worst_second = std::max(o.worst_second, counts.second);
    std::size_t bin = 0;
    while (bin + 1 < std::size(edges) && counts.second >= edges[bin + 1]) ++bin;
    ++seconds[bin];
  }
  for (std::size_t i = 0; i < std::size(edges); ++i) {
    const bool last = i + 1 == std::size(edges);
    o.seconds_histogram.push_back(
        {edges[i], last ? std::nullopt : std::optional<std::uint64_t>(edges[i + 1] - 1),
         seconds[i]});
  }
  o.seconds = per_second_.size();
  return o;
}

}  // namespace teleop::record
