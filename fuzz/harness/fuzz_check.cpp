#include "fuzz/harness/fuzz_check.hpp"

#include <cstdio>

#if defined(__has_feature)
#if __has_feature(address_sanitizer)
#define TELEOP_FUZZ_HAVE_SANITIZER 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__)
#define TELEOP_FUZZ_HAVE_SANITIZER 1
#endif
#ifdef TELEOP_FUZZ_HAVE_SANITIZER
#include <sanitizer/common_interface_defs.h>
#endif

namespace teleop::fuzz {
namespace {
bool g_print_stack = false;
}  // namespace

void print_stack_on_failure(bool on) { g_print_stack = on; }

void fail(const char* file, int line, const std::string& what) {
  const std::string message =
      std::string(file) + ":" + std::to_string(line) + ": invariant broken: " + what;
#ifdef TELEOP_FUZZ_HAVE_SANITIZER
  if (g_print_stack) {
    std::fprintf(stderr, "==teleop-fuzz== %s, at:\n", message.c_str());
    __sanitizer_print_stack_trace();
  }
#endif
  throw InvariantViolation(message);
}

}  // namespace teleop::fuzz
