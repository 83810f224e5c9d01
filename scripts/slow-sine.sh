#!/usr/bin/env bash
# The slow-sine table of docs/robust-law-limits.md (docs/known-limits.md links it): a surface 1 mm from the start that moves as 0.2 mm·sin(2π·0.5 Hz·t)
# from t = 2 s (0.63 mm/s at most, under the estimator's `max_surface_speed`), held at f_r 20 N for 6 s,
# run as a user runs it — `forcecell sim --scenario FILE --plant P --tuning robust` over the default
# wires — on P1 and P2. Each cell: the peak force, the RMS error from first contact, the final k̂_c and
# the RMS error after 3 s (or how the run ended). Not a spec'd case: a slow curvature on a stiff material.
# Usage: scripts/slow-sine.sh [path/to/forcecell] [stiffness N/m ...]   (default: target/release/forcecell;
# 70000 200000 300000 500000)
set -euo pipefail
bin=${1:-target/release/forcecell}
shift || true
stiffnesses=("$@")
[ ${#stiffnesses[@]} -gt 0 ] || stiffnesses=(70000 200000 300000 500000)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cell() { # FILE PLANT -> one table cell
  local text
  text=$("$bin" sim --scenario "$1" --plant "$2" --tuning robust --out "$tmp/out" 2>&1 || true)
  awk '
    /the loop ended early: fault/ { sub(/.*the loop ended early: /, ""); sub(/ \(.*/, ""); end = "**" $0 "** ❌" }
    /^  peak force/ { peak = sprintf("%.1f N", $3) }
    /^  RMS error/ { rms = sprintf("%.2f N", $3) }
    /^  final k̂_c/ { k = sprintf("%.1f kN/m", $3 / 1000) }
    /^  rms_error/ { after = sprintf("%.3f N", $(NF - 1)) }
    END { printf "%s, %s, %s, %s", peak, rms, k, (end != "" ? end : after) }' <<<"$text"
}
echo '| `k_c` | P1 | P2 |'
echo '|---|---|---|'
for k in "${stiffnesses[@]}"; do
  file="$tmp/slow-sine-$k.toml"
  cat > "$file" <<EOF
name = "slow-sine-$k"
description = "0.2 mm at 0.5 Hz from 2 s on $k N/m at f_r 20 N"
duration = 6.0
x0 = 0.009

[environment]
k_c = $k.0
x_c = 0.010
x_c_events = [{ kind = "sine", start = 2.0, amplitude = 0.0002, frequency = 0.5 }]

[controller]
f_r = 20.0

[[targets]]
metric = "rms_error"
max = 0.25
after = 3.0
EOF
  row="| $((k / 1000)) kN/m"
  for plant in p1 p2; do
    row+=" | $(cell "$file" "$plant")"
  done
  echo "$row |"
done
