#!/usr/bin/env bash
# The stress, soak and fault campaign (issue 7) in one command, with a report at the end:
#   ./scripts/campaign.sh            the full campaign (about 20 minutes: 10-minute soak)
#   ./scripts/campaign.sh --short    the CI version (a few minutes)
# Environment: SOAK_S (soak seconds), FUZZ_S (seconds per fuzz target), CASES (analyser cases).
# Parts: the analyser against the 50-digit reference; the live fault table (relay faults, CPU
# load, kills and restarts, disk full, e-stop); fuzzing of every outside-input parser; a soak
# of the simulated system with recording. Exit status non-zero when any part fails.
set -uo pipefail
cd "$(dirname "$0")/.."
short=false
[[ "${1:-}" == "--short" ]] && short=true
if $short; then
  : "${SOAK_S:=30}" "${FUZZ_S:=15}" "${CASES:=300}"
else
  : "${SOAK_S:=600}" "${FUZZ_S:=120}" "${CASES:=5000}"
fi
report=()
failed=0
note() { report+=("$1"); }
part() { echo; echo "== $1"; }

./scripts/build.sh >/dev/null || { echo "campaign: build failed"; exit 1; }
ctl=./build/supervisor/teleopctl/teleopctl

part "analyser against the 50-digit reference ($CASES seeded cases)"
if [[ -x build/bench/bench_campaign_analyser ]]; then
  if build/bench/bench_campaign_analyser --cases "$CASES" | tee /tmp/teleop-campaign-analyser.txt; then
    note "analyser: $(tail -n 1 /tmp/teleop-campaign-analyser.txt)"
  else
    note "analyser: FAILED (see above)"
    failed=1
  fi
else
  note "analyser: bench_campaign_analyser not built"
  failed=1
fi

part "faults on the live system (loopback)"
faults='^(Relay\.|Nodes\.(SlaveKilled|RestartedSlave|EStop|NaNPosition|HundredThousand)|SupervisorLive\.(KillNine|Restarted|DiskFull|BuzzingWall)|NodesCurve\.Unlisted|Console\.EstopGoesStraight)'
if (cd build && ctest -R "$faults" --output-on-failure 2>&1 | tee /tmp/teleop-campaign-faults.txt |
    grep -E "Test +#|tests passed|round trip p50|overruns during"); then
  note "faults: $(grep -E 'tests passed' /tmp/teleop-campaign-faults.txt)"
  grep -q "100% tests passed" /tmp/teleop-campaign-faults.txt || failed=1
else
  note "faults: FAILED"
  failed=1
fi

part "fuzzing every outside-input parser (${FUZZ_S} s per target)"
if [[ -x scripts/fuzz.sh ]]; then
  if bash scripts/fuzz.sh "$FUZZ_S" | tee /tmp/teleop-campaign-fuzz.txt; then
    note "fuzz: no crash in ${FUZZ_S} s per target"
  else
    note "fuzz: CRASH (see above)"
    failed=1
  fi
else
  note "fuzz: scripts/fuzz.sh missing"
  failed=1
fi

part "soak: the simulated system with recording for ${SOAK_S} s"
dir=$(mktemp -d /tmp/teleop-soak-XXXXXX)
"$ctl" launch examples/live.textproto --duration "$SOAK_S" --record-dir "$dir/sessions" \
  >"$dir/launch.log" 2>&1 &
launch=$!
rss() { ps -o rss= -p "$(pgrep -f "$1 .*examples/live.textproto" | head -n 1)" 2>/dev/null | tr -d ' '; }
sleep 5
declare -A rss0
for p in teleop-master teleop-slave teleop-supervisor; do rss0[$p]=$(rss "$p"); done
sleep $((SOAK_S > 8 ? SOAK_S - 8 : 1))
"$ctl" status --json >"$dir/status.json" 2>/dev/null
declare -A rss1
for p in teleop-master teleop-slave teleop-supervisor; do rss1[$p]=$(rss "$p"); done
wait "$launch"
launch_rc=$?
file=$(ls "$dir"/sessions/*.mcap 2>/dev/null | head -n 1)
if [[ $launch_rc -ne 0 || -z "$file" || ! -s "$dir/status.json" ]]; then
  note "soak: FAILED (launch exit $launch_rc; see $dir)"
  failed=1
else
  "$ctl" replay "$file" >"$dir/summary.txt" 2>&1
  drops=$(jq -r '.recordingDrops // "0"' "$dir/status.json")
  for side in master slave; do
    jq -r --arg s "$side" '.[$s] | "\($s): overruns \(.loop.overruns // 0) (last minute \(.overrunsLastMinute // 0)), wake-up p50/p99/p99.9/max \((.loop.wakeupP50Ns // "0" | tonumber) / 1000) / \((.loop.wakeupP99Ns // "0" | tonumber) / 1000) / \((.loop.wakeupP999Ns // "0" | tonumber) / 1000) / \((.loop.wakeupMaxNs // "0" | tonumber) / 1000) us, loss \(.link.lossFraction // 0), round trip p99 \((.link.roundTripP99Ns // "0" | tonumber) / 1e6) ms, mode \(.mode)"' \
      "$dir/status.json" | tee -a "$dir/report.txt"
  done
  missing=$(grep -Eo '[0-9]+ missing' "$dir/summary.txt" | awk '{s += $1} END {print s + 0}')
  for p in teleop-master teleop-slave teleop-supervisor; do
    echo "$p RSS ${rss0[$p]:-?} kB -> ${rss1[$p]:-?} kB" | tee -a "$dir/report.txt"
  done
  note "soak ${SOAK_S} s: recorder drops $drops, missing cycles in the file $missing; $(paste -sd ';' "$dir/report.txt")"
  [[ "$drops" == "0" && "$missing" == "0" ]] || failed=1
fi

echo
echo "== campaign report"
for line in "${report[@]}"; do echo "- $line"; done
exit $failed
