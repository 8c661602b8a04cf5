#!/usr/bin/env bash
# The README's second command: build (installing dependencies if needed) and run every test.
#   scripts/test.sh            normal build in build/
#   scripts/test.sh --sanitize Debug build with ASan+UBSan and clang in build-asan/
# TELEOP_BUILD_TYPE=Release|Debug|RelWithDebInfo (default) picks the normal build's type.
#
# scripts/run-ctest.sh runs the tests, and again, at most twice, only those that failed with the
# host's stalls in the nodes' own telemetry (docs/testing.md "Host stalls").
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh

if [ "${1:-}" = "--sanitize" ]; then
  CC=clang CXX=clang++ ./scripts/build.sh build-asan -DCMAKE_BUILD_TYPE=Debug -DTELEOP_SANITIZE=ON \
    -DTELEOP_BUILD_BENCH=OFF
  export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
  LSAN_OPTIONS=suppressions=$(pwd)/scripts/lsan.supp:print_suppressions=0
  export LSAN_OPTIONS
  ./scripts/run-ctest.sh build-asan
else
  ./scripts/build.sh build -DCMAKE_BUILD_TYPE="${TELEOP_BUILD_TYPE:-RelWithDebInfo}"
  ./scripts/run-ctest.sh build
fi
