#!/usr/bin/env bash
# Touch-downs under sensor noise σ 1 N (twice B6's) over the default wires — `forcecell sim --scenario FILE
# --plant P --tuning robust`, the RSI driver against the simulated KRC and the ATI driver against the
# simulated node — one run per sensor seed, the cross-check of the range tests' `noise_corners` (which run
# in process, and on the 12 ms cell too, which is no `--plant` of `forcecell sim`). A 3 s approach from
# 1 mm off the surface at 2 mm/s. Each row: runs; how many ended on a fault; the peak force, median and
# largest, against the impact bound 2·f_r + k_c·v·(delay + one cycle) and how many exceed it; how many
# declared more than one contact (a contact declared on noise and taken back, or a bounce); the RMS error over the last
# 0.5 s, median and largest, of the runs without a fault; the final k̂_c's error, median.
# Usage: scripts/noisy-touchdowns.sh [path/to/forcecell] [seeds]   (default: target/release/forcecell; 60)
set -euo pipefail
bin=${1:-target/release/forcecell}
seeds=${2:-60}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo '| f_r, `k_c`, plant | runs | faults | peak force: median, largest (bound, over it) | runs with more than one contact | RMS error after 2.5 s: median, largest | `k̂_c` error, median |'
echo '|---|---|---|---|---|---|---|'
for corner in "20 500000 p2" "20 500000 p1" "5 50000 p2" "2 10000 p1"; do
  read -r f_r k_c plant <<<"$corner"
  for seed in $(seq 1 "$seeds"); do
    file="$tmp/noisy-$seed.toml"
    cat > "$file" <<EOF
name = "noisy-$seed"
description = "touch-down under σ 1 N on $k_c N/m at f_r $f_r N"
duration = 3.0
x0 = 0.009

[environment]
k_c = $k_c.0
x_c = 0.010

[sensor]
noise = 1.0
seed = $seed

[controller]
f_r = $f_r.0

[[targets]]
metric = "rms_error"
max = 1000.0
after = 2.5
EOF
    "$bin" sim --scenario "$file" --plant "$plant" --tuning robust --out "$tmp/out" 2>&1 || true
  done | awk -v f_r="$f_r" -v k_c="$k_c" -v plant="$plant" '
    function sort(a, n,   i, j, t) { for (i = 2; i <= n; i++) { t = a[i]; for (j = i - 1; j >= 1 && a[j] > t; j--) a[j + 1] = a[j]; a[j + 1] = t } }
    /^plant / { match($0, /period [0-9.]+ ms/); cycle = substr($0, RSTART + 7, RLENGTH - 10) / 1000
                match($0, /delay [0-9.]+ ms/); delay = substr($0, RSTART + 6, RLENGTH - 9) / 1000; runs++ }
    /the loop ended early: fault/ { faults++ }
    /^  peak force/ { peak[++np] = $3 }
    /^  law events/ { if ($3 > 1) back++ }
    /^  final k̂_c/ { e = ($3 - k_c) / k_c; kerr[++nk] = (e < 0 ? -e : e) }
    /^  rms_error/ { if ($(NF - 1) ~ /^[0-9.]+$/) rms[++nr] = $(NF - 1) }
    END {
      bound = 2 * f_r + k_c * 0.002 * (delay + cycle)
      sort(peak, np); sort(rms, nr); sort(kerr, nk)
      for (i = 1; i <= np; i++) if (peak[i] > bound) over++
      printf "| %s N, %d kN/m, %s | %d | %d | %.1f N, %.1f N (%.1f N, %d) | %d | %.3f N, %.3f N | %.1f %% |\n",
        f_r, k_c / 1000, toupper(plant), runs, faults, peak[int((np + 1) / 2)], peak[np], bound, over,
        back, rms[int((nr + 1) / 2)], rms[nr], 100 * kerr[int((nk + 1) / 2)]
    }'
done
