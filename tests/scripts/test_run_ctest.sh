#!/usr/bin/env bash
# scripts/run-ctest.sh against small CTest projects whose tests play the live tests' parts
# (docs/testing.md "Host stalls"): a test that fails once leaving host-timing evidence passes
# on a rerun; a failure without evidence fails at once, even beside one with evidence; a test
# that fails with evidence every time fails after two reruns; a parameterized test's name
# ("S/P.N/0  # GetParam() = ...") finds its file S_P.N_0.
set -euo pipefail
runner="$(cd "$(dirname "$0")/../.." && pwd)/scripts/run-ctest.sh"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
fails=0

# project NAME TEST... where TEST is "ctest name|file name|behaviour": behaviour once (fails the
# first run with evidence), always (fails every run with evidence), real (fails, no evidence),
# pass.
project() {
  local p="$work/$1"
  shift
  mkdir -p "$p"
  {
    echo "cmake_minimum_required(VERSION 3.19)"
    echo "project(t NONE)"
    echo "enable_testing()"
  } > "$p/CMakeLists.txt"
  local i=0 spec
  for spec in "$@"; do
    IFS='|' read -r name file behaviour <<< "$spec"
    i=$((i + 1))
    cat > "$p/t$i.sh" <<SH
#!/bin/sh
case $behaviour in
  pass) exit 0 ;;
  real) exit 1 ;;
  once) [ -f "$p/t$i.ran" ] && exit 0; touch "$p/t$i.ran" ;;
esac
mkdir -p "\$TELEOP_HOST_TIMING_DIR"
echo "node woke 40 ms late" > "\$TELEOP_HOST_TIMING_DIR/$file"
exit 1
SH
    chmod +x "$p/t$i.sh"
    echo "add_test(NAME [[$name]] COMMAND \"$p/t$i.sh\")" >> "$p/CMakeLists.txt"
  done
  cmake -S "$p" -B "$p/b" > /dev/null
}

# expect NAME STATUS WORDS: run-ctest on project NAME exits STATUS and says WORDS.
expect() {
  local status=0 out
  out=$("$runner" "$work/$1/b" 2>&1) || status=$?
  if [ "$status" != "$2" ] || ! grep -q -- "$3" <<< "$out"; then
    echo "FAIL $1: exit $status (want $2), output lacks '$3':"
    echo "$out" | tail -20
    fails=$((fails + 1))
  else
    echo "ok   $1: exit $status, '$3'"
  fi
}

project stalled_once "S/P.Stalled/0  # GetParam() = 1|S_P.Stalled_0|once" "Suite.Passes|x|pass"
expect stalled_once 0 "1 test(s) passed when run again"
project real_beside_stall "Suite.Stalled|Suite.Stalled|once" "Suite.Broken|Suite.Broken|real"
expect real_beside_stall 1 "Suite.Broken failed without host-timing evidence"
project stalled_always "Suite.Stalled|Suite.Stalled|always"
expect stalled_always 1 "still failing after two reruns"
project all_pass "Suite.Passes|x|pass"
expect all_pass 0 "100% tests passed"
[ "$fails" = 0 ]
