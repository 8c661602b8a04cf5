#!/usr/bin/env bash
# Issue 4 "Benchmarks", real-time part: on this machine, in one run, one measurement after the
# other, with real-time scheduling and with the default scheduling:
#  1. PeriodicLoop's wake-up latency against cyclictest (rt-tests) at the same 1000 us interval,
#     priority, memory locking and /dev/cpu_dma_latency request; both binned alike (whole us);
#  2. the node link's one-way latency (round trip / 2) against a raw UDP ping at 1 kHz, and the
#     real teleop-master/teleop-slave pair's from its telemetry.
# Prints markdown tables with the ratios. Needs root (or CAP_SYS_NICE and a memlock limit).
#
#   bench/run_rt_bench.sh [--duration S] [--priority P]
#   env: BENCH_DURATION_S (20), BENCH_PRIORITY (80), BENCH_DMA_LATENCY_US (10, the nodes'
#        default rt.cpu_dma_latency_us), BENCH_STEP (node | empty: PeriodicLoop's step),
#        BUILD_DIR (build)
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
build=${BUILD_DIR:-$root/build}
duration=${BENCH_DURATION_S:-20}
prio=${BENCH_PRIORITY:-80}
dma=${BENCH_DMA_LATENCY_US:-10}
step=${BENCH_STEP:-node}
while [ $# -gt 0 ]; do
  case "$1" in
    --duration) duration=$2; shift 2 ;;
    --priority) prio=$2; shift 2 ;;
    *) echo "usage: $0 [--duration S] [--priority P]" >&2; exit 2 ;;
  esac
done
loops=$(awk -v d="$duration" 'BEGIN { printf "%d", d * 1000 }')

if ! command -v cyclictest >/dev/null; then
  echo "run_rt_bench: cyclictest not found: apt-get install -y rt-tests (scripts/install-deps.sh)" >&2
  exit 1
fi
cmake --build "$build" --target bench_loop_latency bench_link_latency teleop-master teleop-slave \
  >/dev/null
loop_bench=$build/bench/bench_loop_latency
link_bench=$build/bench/bench_link_latency
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# Value of KEY in the `key=value` result line of FILE.
kv() { sed -n 's/.*[ ]'"$2"'=\([^ ]*\).*/\1/p' "$1" | head -n 1; }
# A / B with two decimals ("n/a" when B is 0 or not a number).
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (b + 0 > 0 && a ~ /^[0-9.]+$/) printf "%.2f", a / b; else printf "n/a" }'; }
# Steal time is the hypervisor running someone else on our vCPU: a VM's extra latency.
cpu_ticks() { awk '/^cpu / { t = 0; for (i = 2; i <= 9; ++i) t += $i; print t, $9 }' /proc/stat; }

# run NAME COMMAND...: its output in $tmp/NAME.out, the conditions in $tmp/NAME.cond.
run() {
  local name=$1
  shift
  echo "run_rt_bench: $name: $*" >&2
  echo "$*" >"$tmp/$name.cmd"
  read -r t0 s0 < <(cpu_ticks)
  "$@" >"$tmp/$name.out"
  read -r t1 s1 < <(cpu_ticks)
  awk -v l="$(cut -d' ' -f1 /proc/loadavg)" -v s=$((s1 - s0)) -v t=$((t1 - t0)) \
    'BEGIN { printf "%s / %.1f %%", l, (t > 0 ? 100 * s / t : 0) }' >"$tmp/$name.cond"
}

rt_label="SCHED_FIFO $prio, mlockall, cpu_dma_latency $dma us"
other_label="SCHED_OTHER, no mlock, cpu_dma_latency untouched"

# 1. Wake-up latency. cyclictest bins whole microseconds (truncated); so does bench_loop_latency,
# and both histograms go through its one quantile function.
run ct_rt cyclictest -t1 -p"$prio" -i1000 -l "$loops" -m -q -h 20000 \
  --histfile="$tmp/ct_rt.hist" --latency="$dma"
"$loop_bench" --quantiles "$tmp/ct_rt.hist" >"$tmp/ct_rt.out"
run loop_rt "$loop_bench" --duration "$duration" --priority "$prio" --mlock \
  --dma-latency-us "$dma" --step "$step"
run ct_other cyclictest -t1 --policy=other -i1000 -l "$loops" -q -h 20000 \
  --histfile="$tmp/ct_other.hist" --laptop
"$loop_bench" --quantiles "$tmp/ct_other.hist" >"$tmp/ct_other.out"
run loop_other "$loop_bench" --duration "$duration" --priority 0 --no-mlock --step "$step"

# 2. Link latency.
nodes=(--master-bin "$build/master_node/teleop-master" --slave-bin "$build/slave_node/teleop-slave"
  --config "$root/examples/paddles.textproto")
for mode in udp zmq nodes; do
  extra=()
  [ "$mode" = nodes ] && extra=("${nodes[@]}")
  run "${mode}_rt" "$link_bench" --mode "$mode" --duration "$duration" --priority "$prio" \
    --mlock --dma-latency-us "$dma" "${extra[@]}"
  run "${mode}_other" "$link_bench" --mode "$mode" --duration "$duration" --priority 0 \
    --no-mlock "${extra[@]}"
done

row() {  # LABEL TOOL NAME: p50 p99 p99.9 max (and lost for the link) from NAME's result
  local f=$tmp/$3.out lost=""
  [ -n "$(kv "$f" lost)" ] && lost=" $(kv "$f" lost) |"
  echo "| $1 | $2 | $(kv "$f" p50_us) | $(kv "$f" p99_us) | $(kv "$f" p999_us) | $(kv "$f" max_us) |$lost $(kv "$f" samples) | $(cat "$tmp/$3.cond") |"
}
ratio_row() {  # PATH-LABEL NUM DEN TARGET [EXTRA-CELL]
  local a=$tmp/$2.out b=$tmp/$3.out
  echo "| | **$1** | **$(ratio "$(kv "$a" p50_us)" "$(kv "$b" p50_us)")** | **$(ratio "$(kv "$a" p99_us)" "$(kv "$b" p99_us)")** | $(ratio "$(kv "$a" p999_us)" "$(kv "$b" p999_us)") | $(ratio "$(kv "$a" max_us)" "$(kv "$b" max_us)") |${5:-} $4 | |"
}

step_text=$([ "$step" = node ] && echo "NodeCore master step" || echo "empty step")
echo
echo "$(date -u '+%Y-%m-%d %H:%M UTC'), $(uname -r), $(nproc) CPUs ($(sed -n 's/^model name[^:]*: //p' /proc/cpuinfo | head -n 1)), cpuidle $(cat /sys/devices/system/cpu/cpuidle/current_driver 2>/dev/null || echo none); $duration s per measurement, 1000 us period. Load is the 1-minute load average after the measurement, steal the share of CPU time the hypervisor took during it."
echo
echo "**Wake-up latency** (µs, whole µs truncated as cyclictest bins them):"
echo
echo "| scheduling | loop | p50 | p99 | p99.9 | max | samples | load / steal |"
echo "|---|---|---|---|---|---|---|---|"
row "$rt_label" "cyclictest" ct_rt
row "" "PeriodicLoop ($step_text)" loop_rt
ratio_row "ratio PeriodicLoop / cyclictest" loop_rt ct_rt "target: p99 ≤ 1.2"
row "$other_label" "cyclictest" ct_other
row "" "PeriodicLoop ($step_text)" loop_other
ratio_row "ratio PeriodicLoop / cyclictest" loop_other ct_other ""
echo
echo "**Master→slave latency** (round trip / 2, µs):"
echo
echo "| scheduling (loop thread) | path | p50 | p99 | p99.9 | max | lost | samples | load / steal |"
echo "|---|---|---|---|---|---|---|---|---|"
for s in rt other; do
  label=$([ $s = rt ] && echo "$rt_label" || echo "$other_label")
  row "$label" "raw UDP ping, echoed at once" "udp_$s"
  row "" "our link: ZeroMQ + NodeState, node_app's threads" "zmq_$s"
  ratio_row "ratio our link / UDP" "zmq_$s" "udp_$s" "$([ $s = rt ] && echo "target: p50 ≤ 4, p99 ≤ 5")" " |"
  row "" "teleop-master ↔ teleop-slave (telemetry)" "nodes_$s"
  ratio_row "ratio nodes / UDP" "nodes_$s" "udp_$s" "" " |"
done
echo
echo "UDP and our link are timed from the pinging step (after its wake-up) to the echo's arrival;"
echo "the nodes' round trip runs from the sending cycle's deadline, so it also holds both loops'"
echo "wake-up latency and step (the peer's hold until its next cycle is subtracted)."
echo
echo "Commands:"
for n in ct_rt loop_rt ct_other loop_other udp_rt zmq_rt nodes_rt udp_other zmq_other nodes_other; do
  echo "- \`$(sed "s|$tmp|TMP|g; s|$root/||g" "$tmp/$n.cmd")\`"
done
echo
echo "Details:"
for n in loop_rt loop_other udp_rt zmq_rt nodes_rt udp_other zmq_other nodes_other; do
  sed -n 's/^# /- '"$n"': /p' "$tmp/$n.out"
done
