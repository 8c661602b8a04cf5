// Why the kernel refuses SCHED_FIFO and mlockall (issue 8): each explanation from facts written
// by hand (the sentence names the numbers it was given and the fix), the parsers on text written
// by hand, and the facts gathered from this process against independent reads (capget, a
// child's own setrlimit, the files themselves) — then the kernel's real refusal, explained, in
// a child stripped of CAP_SYS_NICE / CAP_IPC_LOCK with its limits lowered, and in a cgroup
// without a real-time budget.
#include <gtest/gtest.h>
#include <linux/capability.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <thread>

#include "common/rt/fifo_check.hpp"
#include "common/rt/periodic_loop.hpp"
#include "tests/support/sanitizer.hpp"

namespace teleop::rt {
namespace {

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

#define EXPECT_CONTAINS(text, part) EXPECT_TRUE(contains(text, part)) << (text)

// Facts of a process that may do everything; each test takes one thing away.
RtFacts permissive() {
  RtFacts f;
  f.rtprio = {kUnlimited, kUnlimited};
  f.memlock_bytes = {kUnlimited, kUnlimited};
  f.cap_effective = (1ull << kCapSysNice) | (1ull << kCapIpcLock);
  f.sched_rt_runtime_us = 950000;
  f.sched_rt_period_us = 1000000;
  f.cgroup = "/system.slice/teleop-master.service";
  f.cgroup_v1_cpu = true;
  f.cgroup_rt_runtime_us = 500000;
  f.mapped_bytes = 367001600;
  return f;
}

RtFacts unprivileged() {
  RtFacts f = permissive();
  f.cap_effective = 0;
  return f;
}

TEST(FifoExplain, RtprioZeroWithoutCapSysNice) {
  RtFacts f = unprivileged();
  f.rtprio = {0, 99};
  const std::string s = explain_fifo_refusal(f, 95);
  EXPECT_EQ(s,
            "RLIMIT_RTPRIO is 0 (hard limit 99) and the process lacks CAP_SYS_NICE: run with "
            "LimitRTPRIO=95 (systemd) or `ulimit -r 95`, or grant CAP_SYS_NICE "
            "(AmbientCapabilities=CAP_SYS_NICE)");
  // A hard limit of 0 cannot be raised by `ulimit -r`: the sentence says where to set it.
  f.rtprio = {0, 0};
  const std::string t = explain_fifo_refusal(f, 80);
  EXPECT_CONTAINS(t, "RLIMIT_RTPRIO is 0 (hard limit 0)");
  EXPECT_CONTAINS(t, "LimitRTPRIO=80");
  EXPECT_CONTAINS(t, "/etc/security/limits.conf");
  EXPECT_FALSE(contains(t, "`ulimit -r 80`")) << t;
}

TEST(FifoExplain, PriorityAboveRtprio) {
  RtFacts f = unprivileged();
  f.rtprio = {50, 50};
  const std::string s = explain_fifo_refusal(f, 80);
  EXPECT_CONTAINS(s, "priority 80 is above RLIMIT_RTPRIO 50 (hard limit 50)");
  EXPECT_CONTAINS(s, "lacks CAP_SYS_NICE");
  EXPECT_CONTAINS(s, "lower rt.fifo_priority to 50");
  EXPECT_CONTAINS(s, "LimitRTPRIO=80");
  // At or below the limit the limit is not the cause (nor anything else in these facts).
  EXPECT_EQ(explain_fifo_refusal(f, 50).rfind("no cause found", 0), 0u);
  EXPECT_EQ(explain_fifo_refusal(f, 12).rfind("no cause found", 0), 0u);
}

TEST(FifoExplain, CapSysNiceMakesTheLimitIrrelevant) {
  RtFacts f = permissive();
  f.rtprio = {0, 0};
  const std::string s = explain_fifo_refusal(f, 80);
  EXPECT_FALSE(contains(s, "is 0 (hard limit")) << s;
  // Nothing in the facts explains it: the sentence lists what was checked.
  EXPECT_CONTAINS(s, "no cause found");
  EXPECT_CONTAINS(s, "RLIMIT_RTPRIO 0");
  EXPECT_CONTAINS(s, "CAP_SYS_NICE present");
  EXPECT_CONTAINS(s, "sched_rt_runtime_us 950000");
  EXPECT_CONTAINS(s, "cgroup /system.slice/teleop-master.service cpu.rt_runtime_us 500000");
}

TEST(FifoExplain, UnreadableCapabilitiesAreSaidAsSuch) {
  RtFacts f = permissive();
  f.cap_effective.reset();
  f.rtprio = {0, 0};
  EXPECT_CONTAINS(explain_fifo_refusal(f, 80), "may lack CAP_SYS_NICE");
}

TEST(FifoExplain, SchedRtRuntimeZero) {
  RtFacts f = permissive();
  f.sched_rt_runtime_us = 0;
  const std::string s = explain_fifo_refusal(f, 80);
  EXPECT_EQ(s.rfind("sched_rt_runtime_us is 0", 0), 0u) << s;
  EXPECT_CONTAINS(s, "sysctl kernel.sched_rt_runtime_us=950000");
}

TEST(FifoExplain, CgroupWithoutRtBudget) {
  RtFacts f = permissive();
  f.cgroup = "/system.slice/x";
  f.cgroup_rt_runtime_us = 0;
  const std::string s = explain_fifo_refusal(f, 80);
  EXPECT_EQ(s.rfind("cgroup /system.slice/x has cpu.rt_runtime_us 0 (RT group scheduling", 0), 0u)
      << s;
  EXPECT_CONTAINS(s, "cpu.rt_runtime_us");
  // With RT throttling off (-1) the kernel does not check the group's budget.
  f.sched_rt_runtime_us = -1;
  EXPECT_FALSE(contains(explain_fifo_refusal(f, 80), "/system.slice/x has")) << s;
  // The root group's budget is sched_rt_runtime_us itself: not said twice.
  f.sched_rt_runtime_us = 0;
  f.cgroup = "/";
  const std::string r = explain_fifo_refusal(f, 80);
  EXPECT_FALSE(contains(r, "cgroup / has")) << r;
  EXPECT_CONTAINS(r, "sched_rt_runtime_us is 0");
}

TEST(FifoExplain, EveryCauseIsNamed) {
  RtFacts f = unprivileged();
  f.rtprio = {0, 0};
  f.cgroup_rt_runtime_us = 0;
  const std::string s = explain_fifo_refusal(f, 80);
  EXPECT_EQ(s.rfind("RLIMIT_RTPRIO is 0", 0), 0u) << s;
  EXPECT_CONTAINS(s, "; also cgroup /system.slice/teleop-master.service has cpu.rt_runtime_us 0");
}

TEST(FifoExplain, PriorityOutOfRange) {
  EXPECT_CONTAINS(explain_fifo_refusal(permissive(), 120), "priority 120 is outside");
}

TEST(MlockExplain, EachCause) {
  RtFacts f = unprivileged();
  f.memlock_bytes = {0, 0};
  EXPECT_EQ(explain_mlock_refusal(f),
            "RLIMIT_MEMLOCK is 0 and the process lacks CAP_IPC_LOCK: run with "
            "LimitMEMLOCK=infinity (systemd) or `ulimit -l unlimited`, or grant CAP_IPC_LOCK "
            "(AmbientCapabilities=CAP_IPC_LOCK)");
  f.memlock_bytes = {8388608, 8388608};
  const std::string small = explain_mlock_refusal(f);
  EXPECT_CONTAINS(small, "RLIMIT_MEMLOCK is 8388608 bytes (8192 KiB)");
  EXPECT_CONTAINS(small, "367001600 bytes (VmSize)");
  EXPECT_CONTAINS(small, "lacks CAP_IPC_LOCK");
  EXPECT_CONTAINS(small, "LimitMEMLOCK=infinity");
  // With the capability the limit does not apply: memory is what is missing.
  f.cap_effective = 1ull << kCapIpcLock;
  EXPECT_CONTAINS(explain_mlock_refusal(f), "has CAP_IPC_LOCK, so RLIMIT_MEMLOCK does not apply");
}

TEST(FifoFactsParse, CapEffAndVm) {
  const std::string status =
      "Name:\tteleop-master\nVmPeak:\t  500000 kB\nVmSize:\t  358400 kB\nVmLck:\t       4 kB\n"
      "CapInh:\t0000000000000000\nCapPrm:\t000001fffeffffff\nCapEff:\t0000000000800000\n"
      "CapBnd:\t000001ffffffffff\n";
  ASSERT_TRUE(parse_cap_effective(status).has_value());
  EXPECT_EQ(*parse_cap_effective(status), 0x800000u);  // bit 23 only: CAP_SYS_NICE
  RtFacts f;
  f.cap_effective = parse_cap_effective(status);
  EXPECT_EQ(f.has_capability(kCapSysNice), true);
  EXPECT_EQ(f.has_capability(kCapIpcLock), false);
  EXPECT_EQ(parse_status_bytes(status, "VmSize"), 358400u * 1024u);
  EXPECT_EQ(parse_status_bytes(status, "VmLck"), 4096u);
  EXPECT_FALSE(parse_status_bytes(status, "VmSwap").has_value());
  EXPECT_FALSE(parse_cap_effective("Name:\tx\n").has_value());
}

TEST(FifoFactsParse, CgroupV1AndV2) {
  const std::string v1 =
      "12:pids:/user.slice\n4:cpu,cpuacct:/system.slice/teleop-slave.service\n"
      "1:name=systemd:/system.slice/teleop-slave.service\n0::/system.slice/teleop-slave.service\n";
  const auto a = parse_cpu_cgroup(v1);
  ASSERT_TRUE(a.has_value());
  EXPECT_EQ(a->path, "/system.slice/teleop-slave.service");
  EXPECT_TRUE(a->v1_cpu);
  const auto b = parse_cpu_cgroup("0::/user.slice/user-1000.slice/session-2.scope\n");
  ASSERT_TRUE(b.has_value());
  EXPECT_EQ(b->path, "/user.slice/user-1000.slice/session-2.scope");
  EXPECT_FALSE(b->v1_cpu);
  // cpuacct alone is not the cpu controller.
  const auto c = parse_cpu_cgroup("2:cpuacct:/a\n0::/b\n");
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(c->path, "/b");
  EXPECT_FALSE(c->v1_cpu);

  const std::string mountinfo =
      "31 23 0:28 / /sys/fs/cgroup rw,relatime - tmpfs tmpfs rw,mode=755\n"
      "33 31 0:30 / /sys/fs/cgroup/cpuacct rw,relatime - cgroup cgroup rw,cpuacct\n"
      "32 31 0:29 / /sys/fs/cgroup/cpu rw,relatime shared:9 - cgroup cgroup rw,cpu\n"
      "41 31 0:38 / /sys/fs/cgroup/unified rw,relatime - cgroup2 cgroup2 rw\n";
  EXPECT_EQ(cgroup_directory(mountinfo, {"/system.slice/x.service", true}),
            "/sys/fs/cgroup/cpu/system.slice/x.service");
  EXPECT_EQ(cgroup_directory(mountinfo, {"/", true}), "/sys/fs/cgroup/cpu");
  EXPECT_EQ(cgroup_directory(mountinfo, {"/a", false}), "/sys/fs/cgroup/unified/a");
  // A container sees its hierarchy from its own root on; a cgroup outside it is not there.
  const std::string container =
      "500 400 0:29 /docker/abc /sys/fs/cgroup/cpu\\040x ro - cgroup cgroup rw,cpu,cpuacct\n";
  EXPECT_EQ(cgroup_directory(container, {"/docker/abc/inner", true}), "/sys/fs/cgroup/cpu x/inner");
  EXPECT_EQ(cgroup_directory(container, {"/docker/abc", true}), "/sys/fs/cgroup/cpu x");
  EXPECT_FALSE(cgroup_directory(container, {"/docker/abcd", true}).has_value());
  EXPECT_FALSE(cgroup_directory(container, {"/x", false}).has_value());
}

// Runs `body` in a forked child (to change its limits and capabilities) and returns what it
// reported: "" when every check in it held, else what failed.
std::string in_child(const std::function<std::string()>& body) {
  int fds[2];
  if (::pipe(fds) != 0) return "pipe failed";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::close(fds[0]);
    std::string out;
    try {
      out = body();
    } catch (const std::exception& e) {
      out = std::string("threw: ") + e.what();
    }
    const ssize_t n = ::write(fds[1], out.data(), out.size());
    ::_exit(n == static_cast<ssize_t>(out.size()) ? 0 : 1);
  }
  ::close(fds[1]);
  std::string out;
  char buf[4096];
  ssize_t n = 0;
  while ((n = ::read(fds[0], buf, sizeof(buf))) > 0) out.append(buf, static_cast<std::size_t>(n));
  ::close(fds[0]);
  int status = 0;
  ::waitpid(pid, &status, 0);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) out += " (child failed)";
  return out;
}

struct Caps {
  __user_cap_header_struct header{_LINUX_CAPABILITY_VERSION_3, 0};
  __user_cap_data_struct data[2]{};
};

std::optional<Caps> capget() {
  Caps c;
  if (::syscall(SYS_capget, &c.header, c.data) != 0) return std::nullopt;
  return c;
}

std::uint64_t effective(const Caps& c) {
  return static_cast<std::uint64_t>(c.data[0].effective) |
         (static_cast<std::uint64_t>(c.data[1].effective) << 32);
}

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(FifoFacts, LimitsFollowSetrlimit) {
  rlimit rtprio{};
  rlimit memlock{};
  ASSERT_EQ(::getrlimit(RLIMIT_RTPRIO, &rtprio), 0);
  ASSERT_EQ(::getrlimit(RLIMIT_MEMLOCK, &memlock), 0);
  const RtFacts here = gather_rt_facts();
  auto same = [](std::uint64_t fact, rlim_t v) {
    return fact == (v == RLIM_INFINITY ? kUnlimited : static_cast<std::uint64_t>(v));
  };
  EXPECT_TRUE(same(here.rtprio.soft, rtprio.rlim_cur) && same(here.rtprio.hard, rtprio.rlim_max));
  EXPECT_TRUE(same(here.memlock_bytes.soft, memlock.rlim_cur) &&
              same(here.memlock_bytes.hard, memlock.rlim_max));
  // A child lowers its own limits (anyone may): the facts follow.
  const rlim_t rt_hard = rtprio.rlim_max == RLIM_INFINITY || rtprio.rlim_max > 3 ? 3 : 0;
  const rlim_t rt_soft = rt_hard == 3 ? 2 : 0;
  const std::string report = in_child([&]() -> std::string {
    const rlimit r{rt_soft, rt_hard};
    const rlimit m{65536, 131072};
    if (::setrlimit(RLIMIT_RTPRIO, &r) != 0 || ::setrlimit(RLIMIT_MEMLOCK, &m) != 0) {
      return "setrlimit failed";
    }
    const RtFacts f = gather_rt_facts();
    std::string out;
    if (f.rtprio.soft != rt_soft || f.rtprio.hard != rt_hard) {
      out += "rtprio " + std::to_string(f.rtprio.soft) + "/" + std::to_string(f.rtprio.hard) + "; ";
    }
    if (f.memlock_bytes.soft != 65536 || f.memlock_bytes.hard != 131072) {
      out += "memlock " + std::to_string(f.memlock_bytes.soft) + "/" +
             std::to_string(f.memlock_bytes.hard) + "; ";
    }
    return out;
  });
  EXPECT_EQ(report, "");
}

static_assert(kCapSysNice == CAP_SYS_NICE && kCapIpcLock == CAP_IPC_LOCK);

TEST(FifoFacts, CapabilitiesMatchCapget) {
  const std::optional<Caps> caps = capget();
  ASSERT_TRUE(caps.has_value());
  const RtFacts f = gather_rt_facts();
  ASSERT_TRUE(f.cap_effective.has_value());
  EXPECT_EQ(*f.cap_effective, effective(*caps));
  EXPECT_EQ(f.has_capability(kCapSysNice), ((effective(*caps) >> CAP_SYS_NICE) & 1u) != 0);
  EXPECT_EQ(f.has_capability(kCapIpcLock), ((effective(*caps) >> CAP_IPC_LOCK) & 1u) != 0);
}

TEST(FifoFacts, SystemFilesMatchTheirOwnReads) {
  const RtFacts f = gather_rt_facts();
  const std::string runtime = read_file("/proc/sys/kernel/sched_rt_runtime_us");
  if (runtime.empty()) {
    EXPECT_FALSE(f.sched_rt_runtime_us.has_value());
  } else {
    ASSERT_TRUE(f.sched_rt_runtime_us.has_value());
    EXPECT_EQ(*f.sched_rt_runtime_us, std::stoll(runtime));
  }
  // The cgroup is one /proc/self/cgroup names.
  const std::string cgroups = read_file("/proc/self/cgroup");
  if (!cgroups.empty()) {
    EXPECT_CONTAINS(cgroups, ":" + f.cgroup + "\n");
  }
  // VmSize as the kernel says it, in bytes (the test process maps far more than a page).
  EXPECT_GT(f.mapped_bytes, 4096u);
}

// A child without CAP_SYS_NICE and CAP_IPC_LOCK and with RLIMIT_RTPRIO 0 and a 64 KiB
// RLIMIT_MEMLOCK asks for SCHED_FIFO and mlockall: the kernel refuses both, and each refusal
// says why with the child's own numbers.
TEST(FifoFacts, TheKernelsRefusalIsExplained) {
  const std::string report = in_child([]() -> std::string {
    const rlimit zero{0, 0};
    const rlimit small{65536, 65536};
    if (::setrlimit(RLIMIT_RTPRIO, &zero) != 0 || ::setrlimit(RLIMIT_MEMLOCK, &small) != 0) {
      return "setrlimit failed";
    }
    std::optional<Caps> c = capget();
    if (!c) return "capget failed";
    const std::uint64_t before = effective(*c);
    c->data[0].effective &= ~((1u << CAP_SYS_NICE) | (1u << CAP_IPC_LOCK));
    if (::syscall(SYS_capset, &c->header, c->data) != 0) return "capset failed";
    const RtFacts f = gather_rt_facts();
    std::string out;
    if (f.has_capability(kCapSysNice) != false) out += "CAP_SYS_NICE still seen; ";
    if (f.has_capability(kCapIpcLock) != false) out += "CAP_IPC_LOCK still seen; ";
    const std::uint64_t dropped = (1ull << CAP_SYS_NICE) | (1ull << CAP_IPC_LOCK);
    if (f.cap_effective && *f.cap_effective != (before & ~dropped)) out += "other caps changed; ";
    RtSettings s;
    s.fifo_priority = 10;
    s.lock_memory = true;
    const std::vector<std::string> refused = apply_rt_settings(s);
    if (test::kAddressSanitizer) {
      // ASan's runtime intercepts mlockall and returns success: only SCHED_FIFO is refused.
      if (refused.size() != 1) {
        out += "refused " + std::to_string(refused.size()) + " settings under ASan; ";
        return out;
      }
      const std::string& fifo = refused[0];
      if (fifo.rfind("SCHED_FIFO", 0) != 0 ||
          !contains(fifo, "RLIMIT_RTPRIO is 0 (hard limit 0)") ||
          !contains(fifo, "lacks CAP_SYS_NICE") || !contains(fifo, "LimitRTPRIO=10")) {
        out += "fifo: [" + fifo + "] ";
      }
      return out;
    }
    if (refused.size() != 2) {
      out += "refused " + std::to_string(refused.size()) + " settings; ";
      for (const std::string& r : refused) out += "[" + r + "] ";
      return out;
    }
    const std::string& mlock = refused[0];
    const std::string& fifo = refused[1];
    if (mlock.rfind("mlockall", 0) != 0 || !contains(mlock, "RLIMIT_MEMLOCK is 65536 bytes") ||
        !contains(mlock, "lacks CAP_IPC_LOCK")) {
      out += "mlock: [" + mlock + "] ";
    }
    if (fifo.rfind("SCHED_FIFO", 0) != 0 || !contains(fifo, "RLIMIT_RTPRIO is 0 (hard limit 0)") ||
        !contains(fifo, "lacks CAP_SYS_NICE") || !contains(fifo, "LimitRTPRIO=10")) {
      out += "fifo: [" + fifo + "] ";
    }
    return out;
  });
  EXPECT_EQ(report, "");
}

// RT group scheduling: a child in a fresh cgroup v1 `cpu` group (whose cpu.rt_runtime_us
// starts at 0) is refused SCHED_FIFO even with CAP_SYS_NICE, and the refusal names the group.
// Needs a writable cgroup v1 cpu hierarchy with RT group scheduling (root on such a kernel).
TEST(FifoFacts, CgroupWithoutRtBudgetIsNamed) {
  const RtFacts here = gather_rt_facts();
  if (!here.cgroup_v1_cpu || !here.cgroup_rt_runtime_us) {
    GTEST_SKIP() << "no cgroup v1 cpu controller with cpu.rt_runtime_us here";
  }
  const std::optional<std::string> mounts = [] {
    const std::string m = read_file("/proc/self/mountinfo");
    return m.empty() ? std::nullopt : std::optional<std::string>(m);
  }();
  ASSERT_TRUE(mounts.has_value());
  const std::optional<std::string> dir =
      cgroup_directory(*mounts, CpuCgroup{here.cgroup, here.cgroup_v1_cpu});
  ASSERT_TRUE(dir.has_value());
  const std::string name = "teleop-fifo-check-" + std::to_string(::getpid());
  const std::filesystem::path group = std::filesystem::path(*dir) / name;
  std::error_code ec;
  if (!std::filesystem::create_directory(group, ec)) {
    GTEST_SKIP() << "cannot create a cgroup at " << group << ": " << ec.message();
  }
  const std::string budget = read_file((group / "cpu.rt_runtime_us").string());
  const std::string expected_path = (here.cgroup == "/" ? "" : here.cgroup) + "/" + name;
  const std::string report = in_child([&]() -> std::string {
    {
      std::ofstream procs(group / "cgroup.procs");
      procs << ::getpid() << "\n";
    }
    const RtFacts f = gather_rt_facts();
    std::string out;
    if (f.cgroup != expected_path) out += "cgroup " + f.cgroup + "; ";
    if (!f.cgroup_rt_runtime_us || std::to_string(*f.cgroup_rt_runtime_us) + "\n" != budget) {
      out += "cpu.rt_runtime_us differs from the file's " + budget + "; ";
    }
    RtSettings s;
    s.fifo_priority = 10;
    const std::vector<std::string> refused = apply_rt_settings(s);
    if (budget == "0\n") {
      if (refused.size() != 1 ||
          !contains(refused[0], "cgroup " + expected_path + " has cpu.rt_runtime_us 0")) {
        out += "refusal: ";
        for (const std::string& r : refused) out += "[" + r + "] ";
      }
    }
    return out;
  });
  std::filesystem::remove(group, ec);
  EXPECT_EQ(report, "");
  EXPECT_EQ(budget, "0\n") << "a new cgroup's cpu.rt_runtime_us";
}

}  // namespace
}  // namespace teleop::rt
