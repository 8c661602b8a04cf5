#include "common/rt/fifo_check.hpp"

#include <sys/resource.h>

#include <charconv>
#include <fstream>
#include <sstream>
#include <vector>

namespace teleop::rt {
namespace {

ResourceLimit read_limit(int resource) {
  rlimit r{};
  if (getrlimit(resource, &r) != 0) return {};
  auto convert = [](rlim_t v) {
    return v == RLIM_INFINITY ? kUnlimited : static_cast<std::uint64_t>(v);
  };
  return {convert(r.rlim_cur), convert(r.rlim_max)};
}

std::optional<std::string> read_text(const std::string& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  std::stringstream ss;
  ss << in.rdbuf();
  if (in.bad()) return std::nullopt;
  return ss.str();
}

std::optional<std::int64_t> to_int(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.remove_suffix(1);
  std::int64_t v = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
  if (ec != std::errc{} || end != text.data() + text.size()) return std::nullopt;
  return v;
}

std::optional<std::int64_t> read_int(const std::string& path) {
  const std::optional<std::string> text = read_text(path);
  if (!text) return std::nullopt;
  return to_int(*text);
}

// The value after "key:" on its line of /proc/self/status.
std::optional<std::string_view> status_field(std::string_view status, std::string_view key) {
  std::size_t pos = 0;
  while (pos < status.size()) {
    const std::size_t eol = std::min(status.find('\n', pos), status.size());
    const std::string_view line = status.substr(pos, eol - pos);
    if (line.size() > key.size() && line.substr(0, key.size()) == key && line[key.size()] == ':') {
      std::string_view v = line.substr(key.size() + 1);
      while (!v.empty() && (v.front() == ' ' || v.front() == '\t')) v.remove_prefix(1);
      return v;
    }
    pos = eol + 1;
  }
  return std::nullopt;
}

std::vector<std::string_view> split(std::string_view text, char sep) {
  std::vector<std::string_view> out;
  std::size_t pos = 0;
  while (true) {
    const std::size_t next = text.find(sep, pos);
    out.push_back(text.substr(pos, next == std::string_view::npos ? next : next - pos));
    if (next == std::string_view::npos) return out;
    pos = next + 1;
  }
}

// Mount points escape space, tab, newline and backslash as \ooo.
std::string unescape_octal(std::string_view s) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '\\' && i + 3 < s.size()) {
      const std::string_view digits = s.substr(i + 1, 3);
      int v = 0;
      const auto [end, ec] = std::from_chars(digits.data(), digits.data() + 3, v, 8);
      if (ec == std::errc{} && end == digits.data() + 3) {
        out.push_back(static_cast<char>(v));
        i += 3;
        continue;
      }
    }
    out.push_back(s[i]);
  }
  return out;
}

std::string limit_text(std::uint64_t v) {
  return v == kUnlimited ? std::string("unlimited") : std::to_string(v);
}

std::string join(const std::vector<std::string>& causes) {
  std::string out;
  for (const std::string& c : causes) out += (out.empty() ? "" : "; also ") + c;
  return out;
}

}  // namespace

std::optional<std::uint64_t> parse_cap_effective(std::string_view proc_status) {
  const std::optional<std::string_view> v = status_field(proc_status, "CapEff");
  if (!v || v->empty()) return std::nullopt;
  std::uint64_t bits = 0;
  const auto [end, ec] = std::from_chars(v->data(), v->data() + v->size(), bits, 16);
  if (ec != std::errc{}) return std::nullopt;
  return bits;
}

std::optional<std::uint64_t> parse_status_bytes(std::string_view proc_status,
                                                std::string_view key) {
  const std::optional<std::string_view> v = status_field(proc_status, key);
  if (!v) return std::nullopt;
  std::uint64_t kib = 0;
  const auto [end, ec] = std::from_chars(v->data(), v->data() + v->size(), kib);
  if (ec != std::errc{} ||
      std::string_view(end, static_cast<std::size_t>(v->data() + v->size() - end)) != " kB") {
    return std::nullopt;
  }
  return kib * 1024u;
}

std::optional<CpuCgroup> parse_cpu_cgroup(std::string_view proc_cgroup) {
  std::optional<CpuCgroup> unified;
  for (const std::string_view line : split(proc_cgroup, '\n')) {
    // ID:CONTROLLERS:PATH; the path may itself hold colons.
    const std::size_t a = line.find(':');
    if (a == std::string_view::npos) continue;
    const std::size_t b = line.find(':', a + 1);
    if (b == std::string_view::npos) continue;
    const std::string_view controllers = line.substr(a + 1, b - a - 1);
    const std::string path(line.substr(b + 1));
    if (line.substr(0, a) == "0" && controllers.empty()) {
      unified = CpuCgroup{path, false};
      continue;
    }
    for (const std::string_view c : split(controllers, ',')) {
      if (c == "cpu") return CpuCgroup{path, true};
    }
  }
  return unified;
}

std::optional<std::string> cgroup_directory(std::string_view mountinfo, const CpuCgroup& cgroup) {
  for (const std::string_view line : split(mountinfo, '\n')) {
    const std::size_t dash = line.find(" - ");
    if (dash == std::string_view::npos) continue;
    const std::vector<std::string_view> before = split(line.substr(0, dash), ' ');
    const std::vector<std::string_view> after = split(line.substr(dash + 3), ' ');
    if (before.size() < 6 || after.size() < 3) continue;
    bool match = false;
    if (cgroup.v1_cpu) {
      if (after[0] != "cgroup") continue;
      for (const std::string_view o : split(after[2], ',')) match = match || o == "cpu";
    } else {
      match = after[0] == "cgroup2";
    }
    if (!match) continue;
    // The mount shows the hierarchy from `root` on: the cgroup must lie below it.
    const std::string root = unescape_octal(before[3]);
    std::string mount_point = unescape_octal(before[4]);
    std::string relative;
    if (root == "/") {
      relative = cgroup.path;
    } else if (cgroup.path == root) {
      relative = "";
    } else if (cgroup.path.rfind(root + "/", 0) == 0) {
      relative = cgroup.path.substr(root.size());
    } else {
      continue;
    }
    if (relative == "/") relative.clear();
    return mount_point + relative;
  }
  return std::nullopt;
}

RtFacts gather_rt_facts() {
  RtFacts f;
  f.rtprio = read_limit(RLIMIT_RTPRIO);
  f.memlock_bytes = read_limit(RLIMIT_MEMLOCK);
  if (const std::optional<std::string> status = read_text("/proc/self/status")) {
    f.cap_effective = parse_cap_effective(*status);
    f.mapped_bytes = parse_status_bytes(*status, "VmSize").value_or(0);
    f.locked_bytes = parse_status_bytes(*status, "VmLck").value_or(0);
  }
  f.sched_rt_runtime_us = read_int("/proc/sys/kernel/sched_rt_runtime_us");
  f.sched_rt_period_us = read_int("/proc/sys/kernel/sched_rt_period_us");
  if (const std::optional<std::string> text = read_text("/proc/self/cgroup")) {
    if (const std::optional<CpuCgroup> cg = parse_cpu_cgroup(*text)) {
      f.cgroup = cg->path;
      f.cgroup_v1_cpu = cg->v1_cpu;
      if (const std::optional<std::string> mounts = read_text("/proc/self/mountinfo")) {
        if (const std::optional<std::string> dir = cgroup_directory(*mounts, *cg)) {
          f.cgroup_rt_runtime_us = read_int(*dir + "/cpu.rt_runtime_us");
        }
      }
    }
  }
  return f;
}

std::string explain_fifo_refusal(const RtFacts& f, int priority) {
  const std::string p = std::to_string(priority);
  std::vector<std::string> causes;
  if (priority < 1 || priority > 99) {
    causes.push_back("priority " + p +
                     " is outside SCHED_FIFO's range 1..99: set rt.fifo_priority in 1..99");
  }
  const std::optional<bool> nice = f.has_capability(kCapSysNice);
  if (nice != true) {
    const std::string lacks = nice ? "the process lacks CAP_SYS_NICE"
                                   : "the process may lack CAP_SYS_NICE (/proc/self/status "
                                     "was unreadable)";
    const std::string hard = "hard limit " + limit_text(f.rtprio.hard);
    const std::string raise =
        f.rtprio.hard != kUnlimited && f.rtprio.hard < static_cast<std::uint64_t>(priority)
            ? "run with LimitRTPRIO=" + p + " (systemd) or an rtprio " + p +
                  " line in /etc/security/limits.conf (`ulimit -r` cannot pass the " + hard + ")"
            : "run with LimitRTPRIO=" + p + " (systemd) or `ulimit -r " + p + "`";
    if (f.rtprio.soft == 0) {
      causes.push_back("RLIMIT_RTPRIO is 0 (" + hard + ") and " + lacks + ": " + raise +
                       ", or grant CAP_SYS_NICE (AmbientCapabilities=CAP_SYS_NICE)");
    } else if (priority > 0 && f.rtprio.soft != kUnlimited &&
               f.rtprio.soft < static_cast<std::uint64_t>(priority)) {
      causes.push_back("priority " + p + " is above RLIMIT_RTPRIO " + limit_text(f.rtprio.soft) +
                       " (" + hard + ") and " + lacks + ": lower rt.fifo_priority to " +
                       limit_text(f.rtprio.soft) + ", or " + raise +
                       ", or grant CAP_SYS_NICE (AmbientCapabilities=CAP_SYS_NICE)");
    }
  }
  if (f.sched_rt_runtime_us && *f.sched_rt_runtime_us == 0) {
    causes.push_back(
        "sched_rt_runtime_us is 0 (/proc/sys/kernel/sched_rt_runtime_us): the kernel gives "
        "real-time tasks no CPU time; set it with `sysctl kernel.sched_rt_runtime_us=950000` "
        "(or -1)");
  }
  // RT group scheduling refuses a real-time task in a group without a budget, even to root;
  // with throttling off (-1) the kernel skips that check. The root group's budget is
  // sched_rt_runtime_us itself, said above.
  const bool throttling = !f.sched_rt_runtime_us || *f.sched_rt_runtime_us != -1;
  if (throttling && f.cgroup_rt_runtime_us && *f.cgroup_rt_runtime_us == 0 && !f.cgroup.empty() &&
      f.cgroup != "/") {
    causes.push_back("cgroup " + f.cgroup +
                     " has cpu.rt_runtime_us 0 (RT group scheduling gives its tasks no real-time "
                     "budget): write a budget such as 950000 into its cpu.rt_runtime_us (and its "
                     "parents' first), or start the process in the root cpu cgroup");
  }
  if (!causes.empty()) return join(causes);
  const std::string cap = nice ? (*nice ? "present" : "absent") : "unknown";
  return "no cause found in the limits (RLIMIT_RTPRIO " + limit_text(f.rtprio.soft) +
         ", CAP_SYS_NICE " + cap + ", sched_rt_runtime_us " +
         (f.sched_rt_runtime_us ? std::to_string(*f.sched_rt_runtime_us) : "unknown") +
         ", cgroup " + (f.cgroup.empty() ? "unknown" : f.cgroup) + " cpu.rt_runtime_us " +
         (f.cgroup_rt_runtime_us ? std::to_string(*f.cgroup_rt_runtime_us) : "unknown") +
         "): a container runtime, a seccomp filter or a security module may deny "
         "sched_setscheduler, or RT group scheduling under cgroup v2";
}

std::string explain_mlock_refusal(const RtFacts& f) {
  const std::optional<bool> ipc = f.has_capability(kCapIpcLock);
  const std::string fix =
      "run with LimitMEMLOCK=infinity (systemd) or `ulimit -l unlimited`, or grant CAP_IPC_LOCK "
      "(AmbientCapabilities=CAP_IPC_LOCK)";
  const std::string mapped = std::to_string(f.mapped_bytes) + " bytes (VmSize)";
  if (ipc == true) {
    return "the process has CAP_IPC_LOCK, so RLIMIT_MEMLOCK does not apply: the kernel could not "
           "lock its " +
           mapped + "; free memory or lower the process's mappings";
  }
  const std::string lacks =
      ipc ? "the process lacks CAP_IPC_LOCK" : "the process may lack CAP_IPC_LOCK";
  if (f.memlock_bytes.soft == 0) return "RLIMIT_MEMLOCK is 0 and " + lacks + ": " + fix;
  if (f.memlock_bytes.soft != kUnlimited && f.memlock_bytes.soft < f.mapped_bytes) {
    return "RLIMIT_MEMLOCK is " + std::to_string(f.memlock_bytes.soft) + " bytes (" +
           std::to_string(f.memlock_bytes.soft / 1024u) +
           " KiB) but mlockall(MCL_CURRENT) must lock the process's " + mapped + " and " + lacks +
           ": " + fix;
  }
  return "RLIMIT_MEMLOCK is " + limit_text(f.memlock_bytes.soft) + " bytes and the process maps " +
         mapped + ": the kernel still refused; it may lack free memory to lock, or " + fix;
}

}  // namespace teleop::rt
