#!/usr/bin/env bash
# Fuzzes every parser that takes outside input (issue 7 "Bad input") with libFuzzer under
# ASan+UBSan, each target for a bounded time on its corpus, and prints a table.
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [--merge] [--seeds] [--only TARGET]...
#     SECONDS_PER_TARGET  default 30
#     --merge             add the inputs that found new coverage to fuzz/corpus/<target>/
#                         (otherwise the run works on a copy and the repository is untouched)
#     --seeds             first regenerate the seed corpora and dictionaries (fuzz_make_seeds,
#                         the shipped examples, a short `teleopctl simulate` session file)
#     --only TARGET       run only this target (repeatable): node_state commands config mcap usb
# Builds into build-fuzz/ (clang, -DTELEOP_FUZZ=ON -DTELEOP_SANITIZE=ON, as test.sh --sanitize
# does build-asan/); installs nothing. Logs go to build-fuzz/fuzz-logs/, crashing inputs to
# build-fuzz/fuzz-artifacts/<target>/. Exits 1 if any target crashed, leaked, timed out or ran
# out of memory; the table and the lines after it name the input.
# Minimise a crash:   build-fuzz/fuzz/fuzz_<target> -minimize_crash=1 -runs=100000 CRASH
# Replay one input:   build-fuzz/fuzz/fuzz_<target> INPUT
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=30
merge=0
seeds=0
only=()
while [ $# -gt 0 ]; do
  case "$1" in
    --merge) merge=1 ;;
    --seeds) seeds=1 ;;
    --only) only+=("${2:?--only needs a target}"); shift ;;
    -h|--help) sed -n '2,16p' "$0"; exit 0 ;;
    *[!0-9]*|'') echo "fuzz.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    *) seconds=$1 ;;
  esac
  shift
done

all_targets=(node_state commands config mcap usb)
targets=("${only[@]:-${all_targets[@]}}")
for t in "${targets[@]}"; do
  case " ${all_targets[*]} " in *" $t "*) ;; *) echo "fuzz.sh: no target '$t'" >&2; exit 2 ;; esac
done

# Longest input per target: a NodeState stream, a protobuf message, a configuration, a session
# file (the seeds stay under 64 KiB), a stream of USB packets.
max_len() {
  case "$1" in
    node_state) echo 8192 ;;
    commands) echo 4096 ;;
    config) echo 16384 ;;
    mcap) echo 65536 ;;
    usb) echo 4096 ;;
  esac
}

for tool in clang clang++ cmake ninja; do
  command -v "$tool" >/dev/null || { echo "fuzz.sh: $tool not found (scripts/install-deps.sh)" >&2; exit 1; }
done

dir=build-fuzz
CC=clang CXX=clang++ cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DTELEOP_WERROR=ON -DTELEOP_SANITIZE=ON -DTELEOP_FUZZ=ON -DTELEOP_BUILD_TESTS=OFF -DTELEOP_BUILD_BENCH=OFF >/dev/null
build_targets=()
for t in "${targets[@]}"; do build_targets+=("fuzz_$t"); done
[ "$seeds" = 1 ] && build_targets+=(fuzz_make_seeds)
cmake --build "$dir" --parallel "$(nproc)" --target "${build_targets[@]}"

if [ "$seeds" = 1 ]; then
  "$dir/fuzz/fuzz_make_seeds" fuzz
  for f in examples/*.textproto; do cp "$f" "fuzz/corpus/config/$(basename "$f")"; done
  for f in examples/scenes/*.textproto; do cp "$f" "fuzz/corpus/config/scene_$(basename "$f")"; done
  teleopctl=${TELEOPCTL:-build/supervisor/teleopctl/teleopctl}
  if [ -x "$teleopctl" ]; then
    "$teleopctl" simulate examples/scenes/paddles_unilateral.textproto --duration 0.01 \
      --out fuzz/corpus/mcap/simulated_10ms.mcap >/dev/null
  else
    echo "fuzz.sh: $teleopctl not built: kept fuzz/corpus/mcap/simulated_10ms.mcap as it is" >&2
  fi
fi

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
work=$(mktemp -d "${TMPDIR:-/tmp}/teleop-fuzz.XXXXXX")
trap 'rm -rf "$work"' EXIT
mkdir -p "$dir/fuzz-logs"

rows=()
notes=()
failed=0
for t in "${targets[@]}"; do
  corpus="$work/corpus/$t"
  artifacts="$dir/fuzz-artifacts/$t"
  log="$dir/fuzz-logs/$t.log"
  mkdir -p "$corpus" "$artifacts"
  cp fuzz/corpus/"$t"/* "$corpus"/ 2>/dev/null || true
  args=("$corpus" -max_total_time="$seconds" -max_len="$(max_len "$t")" -timeout=10
        -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$(realpath "$artifacts")/")
  [ -f "fuzz/dict/$t.dict" ] && args+=(-dict="fuzz/dict/$t.dict")
  echo "fuzz.sh: $t for ${seconds} s ..." >&2
  set +e
  timeout --kill-after=30 $((seconds * 2 + 120)) "$dir/fuzz/fuzz_$t" "${args[@]}" >"$log" 2>&1
  rc=$?
  set -e

  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  added=$(sed -n 's/^stat::new_units_added: *//p' "$log" | tail -1)
  cov0=$(sed -n 's/.*INITED cov: \([0-9]*\).*/\1/p' "$log" | head -1)
  cov1=$(grep -o ' cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || true)
  result=ok
  if [ "$rc" != 0 ]; then
    failed=1
    if grep -q 'ERROR: libFuzzer: timeout' "$log"; then result=TIMEOUT
    elif grep -q 'ERROR: libFuzzer: out-of-memory' "$log"; then result=OOM
    elif grep -q 'ERROR: LeakSanitizer' "$log"; then result=LEAK
    elif [ "$rc" = 124 ] || [ "$rc" = 137 ]; then result=HUNG
    else result=CRASH
    fi
    input=$(sed -n 's/.*Test unit written to \(.*\)$/\1/p' "$log" | tail -1)
    why=$(grep -m1 -E '==teleop-fuzz==|ERROR: AddressSanitizer|runtime error:|ERROR: LeakSanitizer|ERROR: libFuzzer' "$log" || true)
    notes+=("$t: $result: ${input:-no input written} (log: $log)")
    notes+=("    $why")
  fi
  rows+=("$(printf '%-11s %10s %8s %24s  %s' "$t" "${runs:-?}" "${speed:-?}" \
    "${cov0:-?} -> ${cov1:-?} (+${added:-?})" "$result")")

  if [ "$merge" = 1 ] && [ "$result" = ok ]; then
    "$dir/fuzz/fuzz_$t" -merge=1 -max_len="$(max_len "$t")" "fuzz/corpus/$t" "$corpus" \
      >>"$log" 2>&1
  fi
done

echo
printf '%-11s %10s %8s %24s  %s\n' target runs exec/s "coverage (+units)" result
for r in "${rows[@]}"; do echo "$r"; done
if [ "${#notes[@]}" -gt 0 ]; then
  echo
  for n in "${notes[@]}"; do echo "$n"; done
fi
exit "$failed"
