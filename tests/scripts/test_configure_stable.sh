#!/usr/bin/env bash
# configure_twice_same_commands: a build directory configured a second time keeps every compile
# command line. CMake 3.25 once moved libzmq's "-isystem /usr/include/mit-krb5" from the include
# directories (first configure) to the compile options (later ones), and the campaign's
# reconfigure of CI's build recompiled every object that uses ZeroMQ
# (common/transport/CMakeLists.txt). Usage: test_configure_stable.sh SOURCE_DIR
set -euo pipefail
src=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cmake -S "$src" -B "$tmp/b" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTELEOP_WERROR=ON >"$tmp/first.log" 2>&1 ||
  { cat "$tmp/first.log"; echo "FAIL: first configure"; exit 1; }
grep -E '^  (FLAGS|INCLUDES|DEFINES) = ' "$tmp/b/build.ninja" >"$tmp/first.txt"
cmake -S "$src" -B "$tmp/b" -G Ninja -DTELEOP_WERROR=ON >"$tmp/second.log" 2>&1 ||
  { cat "$tmp/second.log"; echo "FAIL: second configure"; exit 1; }
grep -E '^  (FLAGS|INCLUDES|DEFINES) = ' "$tmp/b/build.ninja" >"$tmp/second.txt"
lines=$(wc -l <"$tmp/first.txt")
[ "$lines" -gt 100 ] || { echo "FAIL: only $lines command lines found in build.ninja"; exit 1; }
if ! diff "$tmp/first.txt" "$tmp/second.txt" >"$tmp/diff.txt"; then
  echo "FAIL: the second configure changed compile command lines (every such object recompiles):"
  head -n 20 "$tmp/diff.txt"
  exit 1
fi
echo "configure twice: $lines command lines, identical"
