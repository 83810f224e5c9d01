#!/usr/bin/env bash
# The real-time benchmark (docs/realtime.md): `run`'s loop (examples/cell_latency.rs --cell run: the RSI link
# bound from a cell file, the control loop, the recorder) answers a robot stand-in paced at 4 ms by the clock,
# side by side with a bare UDP echo in the same run, with and without `run`'s real-time settings (SCHED_FIFO 80,
# memory locked, the stack touched: `--realtime`, applied to the loop and to the echo alike), without load and
# under CPU and memory load on every CPU (stress-ng). The stand-in runs at SCHED_FIFO 90 in every condition (it
# plays the robot controller). Prints one markdown row per run; late = replies after more than the 4 ms cycle.
# Needs root (or an rtprio and memlock limit) for the settings; installs stress-ng with apt-get when missing.
# Usage: scripts/rt-bench.sh [ROUNDS] [CYCLES]   (default 2 rounds of 5000 cycles = 20 s per condition)
set -euo pipefail
rounds=${1:-2}
cycles=${2:-5000}
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
if ! command -v stress-ng >/dev/null; then
  echo "installing stress-ng (apt-get)" >&2
  apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq stress-ng >/dev/null
fi
cargo build --release --example cell_latency 2>&1 | tail -1 >&2
bin=target/release/examples/cell_latency
cpus=$(nproc)
other=$((cpus > 1 ? 1 : 0))
load_pid=
stop_load() { if [ -n "$load_pid" ]; then kill "$load_pid" 2>/dev/null || true; wait "$load_pid" 2>/dev/null || true; load_pid=; fi; }
trap stop_load EXIT

# row LOAD SETTINGS: one run, one markdown row.
row() {
  local load=$1 rt=$2 out
  if [ "$load" = on ]; then
    # Every CPU busy, and memory churned: a worker per CPU spinning, one writing and freeing 25 % of RAM.
    stress-ng --cpu "$cpus" --vm 1 --vm-bytes 25% --quiet --timeout 600s &
    load_pid=$!
    sleep 2
  fi
  out=$("$bin" --cell run --sensor inproc --cycles "$cycles" --warmup 250 --period-us 4000 \
    --loop-cpu 0 --other-cpu "$other" --standin-priority 90 $([ "$rt" = on ] && echo --realtime) 2>&1)
  stop_load
  awk -v load="$load" -v rt="$rt" '
    /^bare UDP echo/ { e50=$4; e999=$6; emax=$7 }
    /^forcecell  / { f50=$2; f999=$4; fmax=$5 }
    /^late/ { el=$8; en=$10; fl=$12; fn=$14; sub(",", "", en) }
    /^ratio/ { r50=$3; r999=$5 }
    END {
      printf "| %s | %s | %s / %s / %s | %s of %s | %s / %s / %s | %s of %s | %s / %s |\n",
        load, rt, e50, e999, emax, el, en, f50, f999, fmax, fl, fn, r50, r999
    }' <<<"$out"
}

echo "| load | real-time settings | echo p50 / p99.9 / max (µs) | echo late | forcecell p50 / p99.9 / max (µs) | forcecell late | forcecell/echo p50 / p99.9 |"
echo "|---|---|---|---|---|---|---|"
for _ in $(seq "$rounds"); do
  for load in off on; do
    for rt in off on; do
      row "$load" "$rt"
    done
  done
done
