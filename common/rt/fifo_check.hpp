// Why the kernel refuses SCHED_FIFO or mlockall, said so that a lab user can fix it (issue 8
// "a startup check that explains why the kernel refuses SCHED_FIFO"). The facts come from
// getrlimit and files under /proc and /sys, gathered once at start when a setting was refused,
// never in the loop; the explanations are pure functions of them, so each cause is tested
// with facts written by hand.
#pragma once

#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

namespace teleop::rt {

// RLIM_INFINITY, whatever the platform's rlim_t.
inline constexpr std::uint64_t kUnlimited = std::numeric_limits<std::uint64_t>::max();

// Capability bits (linux/capability.h) as they appear in /proc/self/status CapEff.
inline constexpr int kCapIpcLock = 14;
inline constexpr int kCapSysNice = 23;

struct ResourceLimit {
  std::uint64_t soft{0};  // kUnlimited: no limit
  std::uint64_t hard{0};
};

struct RtFacts {
  ResourceLimit rtprio{};         // RLIMIT_RTPRIO: highest SCHED_FIFO priority without the cap
  ResourceLimit memlock_bytes{};  // RLIMIT_MEMLOCK
  // The effective capability set (CapEff); nullopt when /proc/self/status was unreadable.
  std::optional<std::uint64_t> cap_effective{};
  // /proc/sys/kernel/sched_rt_runtime_us (-1: RT throttling off) and its period.
  std::optional<std::int64_t> sched_rt_runtime_us{};
  std::optional<std::int64_t> sched_rt_period_us{};
  // The process's cgroup: the cgroup v1 `cpu` controller's when there is one, else the
  // unified (v2) one; with its cpu.rt_runtime_us (RT group scheduling) when readable.
  std::string cgroup{};
  bool cgroup_v1_cpu{false};
  std::optional<std::int64_t> cgroup_rt_runtime_us{};
  // What mlockall(MCL_CURRENT) has to lock (VmSize) and what is locked already (VmLck).
  std::uint64_t mapped_bytes{0};
  std::uint64_t locked_bytes{0};

  [[nodiscard]] std::optional<bool> has_capability(int bit) const {
    if (!cap_effective) return std::nullopt;
    return ((*cap_effective >> bit) & 1u) != 0;
  }
};

// Reads the calling process's facts. Never throws; what it cannot read stays unset.
[[nodiscard]] RtFacts gather_rt_facts();

// A sentence naming why SCHED_FIFO at `priority` was refused and how to fix it (every cause
// the facts show, most likely first).
[[nodiscard]] std::string explain_fifo_refusal(const RtFacts& facts, int priority);
// The same for mlockall(MCL_CURRENT | MCL_FUTURE).
[[nodiscard]] std::string explain_mlock_refusal(const RtFacts& facts);

// The parsers behind gather_rt_facts, on the files' text (tested on text written by hand).
// CapEff of /proc/self/status.
[[nodiscard]] std::optional<std::uint64_t> parse_cap_effective(std::string_view proc_status);
// A "kB" line of /proc/self/status (VmSize, VmLck), in bytes.
[[nodiscard]] std::optional<std::uint64_t> parse_status_bytes(std::string_view proc_status,
                                                              std::string_view key);
struct CpuCgroup {
  std::string path{};  // as /proc/self/cgroup gives it, relative to its hierarchy's root
  bool v1_cpu{false};  // the cgroup v1 `cpu` controller's (else the unified hierarchy's)
};
// The process's cgroup for the `cpu` controller from /proc/self/cgroup.
[[nodiscard]] std::optional<CpuCgroup> parse_cpu_cgroup(std::string_view proc_cgroup);
// The directory holding `cgroup`'s files, from /proc/self/mountinfo; nullopt when its
// hierarchy is not mounted here.
[[nodiscard]] std::optional<std::string> cgroup_directory(std::string_view mountinfo,
                                                          const CpuCgroup& cgroup);

}  // namespace teleop::rt
