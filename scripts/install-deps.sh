#!/usr/bin/env bash
# Installs the build dependencies from Debian 12's packages (needs root or sudo).
set -euo pipefail
packages=(
  build-essential cmake ninja-build pkg-config clang libclang-rt-14-dev clang-format
  libeigen3-dev libprotobuf-dev protobuf-compiler libzmq3-dev cppzmq-dev libusb-1.0-0-dev
  libspdlog-dev libfmt-dev nlohmann-json3-dev libboost-dev zlib1g-dev
  libgtest-dev libgmock-dev libbenchmark-dev rt-tests
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "install-deps: installing ${missing[*]}"
$SUDO apt-get update -q
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
