#!/usr/bin/env bash
# The Debian package (issue 8): a Release build without tests or benchmarks in build-pkg/ (or
# $1), then cpack; prints the .deb's path last. Extra arguments go to cmake.
#   scripts/package.sh                 -> build-pkg/teleop_<version>_<arch>.deb
#   sudo apt install ./build-pkg/teleop_*.deb
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-build-pkg}
shift || true
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DTELEOP_BUILD_TESTS=OFF \
  -DTELEOP_BUILD_BENCH=OFF -DTELEOP_FUZZ=OFF -DTELEOP_SANITIZE=OFF "$@"
cmake --build "$dir" --parallel "$(nproc)"
rm -f "$dir"/teleop_*.deb
(cd "$dir" && cpack -G DEB)
shopt -s nullglob
debs=("$(cd "$dir" && pwd)"/teleop_*.deb)
if [ "${#debs[@]}" -ne 1 ]; then
  echo "package.sh: expected one teleop_*.deb in $dir, got ${#debs[@]}" >&2
  exit 1
fi
echo "${debs[0]}"
