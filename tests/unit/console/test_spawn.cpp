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
#include <thread>

#include "supervisor/teleopctl/node_command.hpp"

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

}  // namespace
}  // namespace teleop::ctl
