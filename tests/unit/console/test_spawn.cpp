// teleopctl launch's children (spawn_process, node_command.hpp). Found while splitting
// run_launch (issue 16): the child of a fork ran launch's own SIGINT handler until its exec, so
// a Ctrl-C (or launch's own stop) that reached it in that window was swallowed and the node
// started anyway, with nobody left to stop it. Here the test process installs a handler that
// only sets a flag, as launch does, and interrupts each child the moment spawn_process returns:
// every child must die of that SIGINT, none may live on as the program it was to exec.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <new>
#include <thread>

#include "supervisor/teleopctl/node_command.hpp"

// The child of a fork, until its exec, in this test binary: set by a pthread_atfork child
// handler. An operator new there ends the child at once with status 99, so a child that
// allocates before its exec is seen as such, deterministically, where in launch it would only
// now and then wait forever on an allocator lock another thread held at the fork.
volatile sig_atomic_t g_forked_child = 0;
constexpr int kAllocatedInChild = 99;

void* counted_new(std::size_t size) {
  if (g_forked_child != 0) ::_exit(kAllocatedInChild);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}

void* operator new(std::size_t size) { return counted_new(size); }
void* operator new[](std::size_t size) { return counted_new(size); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace teleop::ctl {
namespace {

volatile sig_atomic_t g_flag = 0;
void flag_handler(int) { g_flag = 1; }

// The child's end within `limit`: its wait status, or -1 while it still runs (then killed).
int wait_for(pid_t pid, std::chrono::milliseconds limit) {
  const auto until = std::chrono::steady_clock::now() + limit;
  int status = 0;
  while (std::chrono::steady_clock::now() < until) {
    if (::waitpid(pid, &status, WNOHANG) == pid) return status;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ::kill(pid, SIGKILL);
  (void)::waitpid(pid, &status, 0);
  return -1;
}

TEST(SpawnProcess, AnInterruptSentTheMomentAChildExistsEndsItEvenBeforeItsExec) {
  struct sigaction sa {};
  struct sigaction old {};
  sa.sa_handler = flag_handler;
  sigemptyset(&sa.sa_mask);
  ASSERT_EQ(::sigaction(SIGINT, &sa, &old), 0);
  int survived = 0;
  int other = 0;
  constexpr int kChildren = 100;
  for (int i = 0; i < kChildren; ++i) {
    const pid_t pid = spawn_process("/bin/sleep", {"10"});
    ASSERT_GT(pid, 0);
    ::kill(pid, SIGINT);
    const int status = wait_for(pid, std::chrono::milliseconds(2000));
    if (status == -1) {
      ++survived;
    } else if (!(WIFSIGNALED(status) && WTERMSIG(status) == SIGINT)) {
      ++other;
    }
  }
  (void)::sigaction(SIGINT, &old, nullptr);
  EXPECT_EQ(survived, 0) << "children that swallowed the SIGINT and ran on";
  EXPECT_EQ(other, 0) << "children that ended otherwise than by the SIGINT";
  // The parent's own handler still works, and its mask is as it was.
  sigset_t mask;
  ASSERT_EQ(::pthread_sigmask(SIG_SETMASK, nullptr, &mask), 0);
  EXPECT_EQ(sigismember(&mask, SIGINT), 0);
  EXPECT_EQ(sigismember(&mask, SIGTERM), 0);
}

// launch forks from a process with threads (the ZeroMQ context's, the telemetry readers'), so
// its child may call only async-signal-safe functions until the exec. Found when a supervisor
// forked by the live tests' harness, which built its argv in the child as launch did, never
// started under ASan in CI (its log empty after 22 s). Every child here must run /bin/true
// (status 0), never stop at an allocation (status 99).
TEST(SpawnProcess, TheChildAllocatesNothingBeforeItsExec) {
  static const int registered = ::pthread_atfork(nullptr, nullptr, [] { g_forked_child = 1; });
  ASSERT_EQ(registered, 0);
  int allocated = 0;
  int other = 0;
  for (int i = 0; i < 20; ++i) {
    const pid_t pid = spawn_process("/bin/true", {"--a", "several", "arguments"});
    ASSERT_GT(pid, 0);
    const int status = wait_for(pid, std::chrono::milliseconds(5000));
    if (status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == kAllocatedInChild) {
      ++allocated;
    } else if (!(status != -1 && WIFEXITED(status) && WEXITSTATUS(status) == 0)) {
      ++other;
    }
  }
  EXPECT_EQ(allocated, 0) << "children that allocated between the fork and the exec";
  EXPECT_EQ(other, 0) << "children that did not run /bin/true to its end";
}

}  // namespace
}  // namespace teleop::ctl
