#!/usr/bin/env bash
# The re-acquire table of docs/controller.md ("Choosing the re-acquire search"): the shipped fast search (tuning `robust`) against
# the gentle one (`robust-gentle`, which stops within 2·f_r), run as a user runs them — `forcecell sim
# --scenario S --plant P --tuning T` over the default wires — on P1 and P2. Rows: B3a (the surface 1 mm
# away at 3 s, 70 kN/m, f_r 5 N), B8 (160 kN/m: 0.05 mm towards the tool at 1.2 s, back at 1.8 s) and,
# not spec'd, a 1 mm retreat of a 500 kN/m surface at f_r 5 N at 3 s. Each cell: the longest contact loss and the
# largest true force after the retreat (a surface that came nearer presses at once, before any loop:
# B8's 13 N at 1.2 s is that, not a search), or how the run ended.
# Usage: scripts/reacquire-table.sh [path/to/forcecell]   (default: target/release/forcecell)
set -euo pipefail
bin=${1:-target/release/forcecell}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat > "$tmp/retreat-500k.toml" <<EOF
name = "retreat-500k"
description = "the surface 1 mm away at t = 3 s on 500 kN/m"
duration = 5.0
x0 = 0.009

[environment]
k_c = 500000.0
x_c = 0.010
x_c_events = [{ kind = "step", at = 3.0, delta = 0.001 }]
EOF
cell() { # SCENARIO PLANT TUNING RETREAT_AT -> one table cell
  local text csv
  text=$("$bin" sim --scenario "$1" --plant "$2" --tuning "$3" --out "$tmp/out" 2>&1 || true)
  csv=$(ls -t "$tmp"/out/*.csv | head -n 1)
  local peak
  peak=$(awk -F, -v at="$4" 'NR > 1 && $1 >= at && $3 > m { m = $3 } END { printf "%.1f N", m }' "$csv")
  awk -v peak="$peak" '
    /the loop ended early: fault/ { sub(/.*the loop ended early: /, ""); sub(/: .*/, ""); end = "**" $0 "**, backed off" }
    /^  contact losses/ { lost = sprintf("%.0f ms", $5 * 1000) }
    END { if (end != "") printf "%s", end; else printf "%s lost, %s", lost, peak }' <<<"$text"
  rm -f "$tmp"/out/*
}
echo '| case | search | P1: contact lost, largest force after | P2 |'
echo '|---|---|---|---|'
for row in "b03a-surface-retreat:B3a, 1 mm retreat, 70 kN/m:3.0" "b08-identification:B8, 0.05 mm back, 160 kN/m:1.8" "$tmp/retreat-500k.toml:1 mm retreat, 500 kN/m (not spec'd):3.0"; do
  IFS=: read -r scenario label at <<<"$row"
  for tuning in robust robust-gentle; do
    line="| $label | \`$tuning\`"
    for plant in p1 p2; do
      line+=" | $(cell "$scenario" "$plant" "$tuning" "$at")"
    done
    echo "$line |"
  done
done
