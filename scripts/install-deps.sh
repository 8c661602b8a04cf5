#!/usr/bin/env bash
# Installs the build dependencies from Debian 12's packages (needs root or sudo).
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config clang libclang-rt-14-dev clang-format
  libeigen3-dev libprotobuf-dev protobuf-compiler libzmq3-dev cppzmq-dev libusb-1.0-0-dev
  libspdlog-dev libfmt-dev nlohmann-json3-dev libboost-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev rt-tests libncurses-dev tmux jq
  libsystemd-dev systemd dpkg-dev iproute2 python3 help2man
  libwebsocketpp-dev libasio-dev libxml2-dev
  python3-dev pybind11-dev python3-pybind11 python3-numpy
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
else
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  echo "install-deps: installing ${missing[*]}"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

# The independent client checks, each pinned by its package-lock.json and installed with the
# machine's own node and npm: tests/mcap_js (ctest record.mcap_js: the official TypeScript MCAP
# reader and protobufjs) and tests/ws_js (the live bridge: the official Foxglove WebSocket
# client @foxglove/ws-protocol, ws and protobufjs).
root="$(cd "$(dirname "$0")/.." && pwd)"
for js_dir in "$root/tests/mcap_js" "$root/tests/ws_js"; do
  if ! command -v npm >/dev/null; then
    echo "install-deps: npm not found: the checks in ${js_dir#"$root"/} will fail" >&2
  elif [ "$js_dir/node_modules/.package-lock.json" -nt "$js_dir/package-lock.json" ]; then
    echo "install-deps: ${js_dir#"$root"/}/node_modules up to date"
  else
    npm ci --prefix "$js_dir" --no-audit --no-fund
  fi
done
