#!/usr/bin/env bash
# The README's first command: install dependencies, build, and run the main job (the
# analysis, then both nodes live on simulated devices: teleopctl launch).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/install-deps.sh
./scripts/build.sh build
echo
echo "== teleopctl analyze examples/paddles.textproto"
./build/supervisor/teleopctl/teleopctl analyze examples/paddles.textproto
echo
echo "== maximum stable slave fixture stiffness against sample rate (the paper's Fig. 7)"
./build/supervisor/teleopctl/teleopctl analyze examples/paddles.textproto \
  --max-stiffness slave --rates 250,500,1000,2000
echo
echo "== the force-controlled device of Vlachos & Papadopoulos"
./build/supervisor/teleopctl/teleopctl analyze examples/force_loop.textproto --force-loop
echo
echo "== a slave fixture below and above its limit, simulated with the nodes' control law"
./build/supervisor/teleopctl/teleopctl simulate examples/scenes/paddles_slave_fixture_stable.textproto
./build/supervisor/teleopctl/teleopctl simulate examples/scenes/paddles_slave_fixture_unstable.textproto || true
echo
echo "== the main job: teleop-master and teleop-slave on loopback, engaged (Ctrl-C stops them)"
echo "   watch and command it from another terminal: ./build/supervisor/teleopctl/teleopctl console"
duration=()
if [[ -n "${DEMO_DURATION:-}" ]]; then duration=(--duration "$DEMO_DURATION"); fi
./build/supervisor/teleopctl/teleopctl launch examples/live.textproto "${duration[@]}"
