// Whether this test binary (and the project's binaries beside it, built with the same flags)
// runs under AddressSanitizer, whose runtime changes what some system calls do: it intercepts
// mlockall() and returns success without locking anything.
#pragma once

namespace teleop::test {

#if defined(__SANITIZE_ADDRESS__)
inline constexpr bool kAddressSanitizer = true;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif
#else
inline constexpr bool kAddressSanitizer = false;
#endif

}  // namespace teleop::test
