// The fuzz harnesses (issue 7 "Bad input"): one function per parser that takes outside input,
// called by libFuzzer (fuzz_entry.cpp) and by the regression tests
// (tests/unit/fuzz_regressions/), which replay the corpora and every minimised crash.
//
// A harness feeds the bytes to the parser, lets its documented rejections (ConfigError,
// McapError, a PacketError, a Rejection) pass, and checks cheap invariants on what it accepts.
// A broken invariant throws InvariantViolation; any other exception escaping a harness is a bug
// too (the parser threw something it does not document). libFuzzer turns both into a crash.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

namespace teleop::fuzz {

struct InvariantViolation : std::logic_error {
  using std::logic_error::logic_error;
};

[[noreturn]] void fail(const char* file, int line, const std::string& what);
// fail() also prints the stack where the invariant broke (sanitizer builds; the libFuzzer entry
// turns this on, since the exception unwinds to it before the crash is reported).
void print_stack_on_failure(bool on);

// The harnesses; each returns 0 (libFuzzer's convention) or throws.
int node_state(const std::uint8_t* data, std::size_t size);  // PeerStateFilter, encode
int commands(const std::uint8_t* data, std::size_t size);    // NodeCommand, SupervisorRequest, ...
int config(const std::uint8_t* data, std::size_t size);      // load_config_text, overrides, ...
int mcap(const std::uint8_t* data, std::size_t size);        // McapReader open/recover/iterate
int usb(const std::uint8_t* data, std::size_t size);         // USB packet codec, emulator

}  // namespace teleop::fuzz

#define TELEOP_FUZZ_CHECK(cond, what)                                                          \
  do {                                                                                         \
    if (!(cond)) ::teleop::fuzz::fail(__FILE__, __LINE__, std::string(#cond " -- ") + (what)); \
  } while (false)
