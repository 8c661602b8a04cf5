#!/usr/bin/env bash
# scripts/run-ctest.sh BUILD_DIR [CTEST_ARGS...]: every test of BUILD_DIR with CTest, then the
# host-stall reruns (docs/testing.md "Host stalls"). A live test that failed while the nodes'
# own telemetry showed the host stalling them (tests/integration/node_harness.hpp, HostTiming)
# leaves a file named after it in BUILD_DIR/host-timing; such a test, and only such a test, is
# run again, at most twice. Any failure without that evidence fails at once. Exits 0 when
# every test passed, the first time or on a rerun.
set -euo pipefail
dir=$1
shift
timing="$dir/host-timing"
failed="$dir/Testing/Temporary/LastTestsFailed.log"
rm -rf "$timing"
TELEOP_HOST_TIMING_DIR="$(cd "$dir" && pwd)/host-timing"
export TELEOP_HOST_TIMING_DIR
if ctest --test-dir "$dir" --output-on-failure --parallel "$(nproc)" "$@"; then exit 0; fi
for round in 1 2; do
  numbers=()
  while IFS= read -r line; do
    number=${line%%:*}
    name=${line#*:}
    name=${name%%  #*}  # a parameterized test's "  # GetParam() = ..."
    file="$timing/${name//\//_}"
    if [ ! -f "$file" ]; then
      echo "run-ctest: $name failed without host-timing evidence: a real failure" >&2
      exit 1
    fi
    echo "run-ctest: $name failed with the host's stalls in the nodes' telemetry" \
         "($(head -c 600 "$file")); run again ($round of 2)" >&2
    numbers+=("$number")
  done < "$failed"
  [ ${#numbers[@]} -gt 0 ] || exit 1
  rm -rf "$timing"
  list=$(IFS=,; echo "${numbers[*]}")
  if ctest --test-dir "$dir" --output-on-failure -I "0,0,0,$list"; then
    echo "run-ctest: ${#numbers[@]} test(s) passed when run again after a host stall" >&2
    exit 0
  fi
done
echo "run-ctest: still failing after two reruns" >&2
exit 1
