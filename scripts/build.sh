#!/usr/bin/env bash
# Configures and builds into build/ (or $1), warnings as errors (TELEOP_WERROR). Extra args go
# to cmake. A new build directory is RelWithDebInfo unless the args say otherwise; an existing
# one keeps its type (CI's Release build/ stays Release for the campaign).
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-build}
shift || true
type_arg=()
[ -f "$dir/CMakeCache.txt" ] || type_arg=(-DCMAKE_BUILD_TYPE=RelWithDebInfo)
cmake -S . -B "$dir" -G Ninja "${type_arg[@]}" -DTELEOP_WERROR=ON "$@"
cmake --build "$dir" --parallel "$(nproc)"
