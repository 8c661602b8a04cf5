// libFuzzer's entry point for one harness, chosen at compile time by TELEOP_FUZZ_TARGET (one of
// the functions of fuzz_check.hpp). An exception escaping the harness is reported, then abort():
// libFuzzer records the input as a crash.
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <typeinfo>

#include "fuzz/harness/fuzz_check.hpp"

#ifndef TELEOP_FUZZ_TARGET
#error "define TELEOP_FUZZ_TARGET to the harness to run"
#endif

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  teleop::fuzz::print_stack_on_failure(true);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    return teleop::fuzz::TELEOP_FUZZ_TARGET(data, size);
  } catch (const teleop::fuzz::InvariantViolation& e) {
    std::fprintf(stderr, "==teleop-fuzz== %s\n", e.what());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "==teleop-fuzz== undocumented exception %s: %s\n", typeid(e).name(),
                 e.what());
  } catch (...) {
    std::fprintf(stderr, "==teleop-fuzz== unknown exception\n");
  }
  std::abort();
}
