#!/usr/bin/env bash
# The stiff-curve table of docs/robust-law-limits.md (docs/known-limits.md links it): B5's two curved-surface files (`scenarios/b05a-curve-slow.toml`,
# `b05b-curve-fast.toml`) with the surface's stiffness changed, run as a user runs them — `forcecell sim
# --scenario FILE --plant P --tuning robust --check` over the default wires — on P1 and P2. Each cell: the
# RMS error after 3 s (or how the run ended), contact losses (and the longest), final k̂_c. Not spec'd cases: a measurement of
# where the robust law stops holding a moving surface.
# Usage: scripts/stiff-curves.sh [path/to/forcecell] [stiffness N/m ...]   (default: target/release/forcecell;
# 100000 140000 200000 500000)
set -euo pipefail
bin=${1:-target/release/forcecell}
shift || true
stiffnesses=("$@")
[ ${#stiffnesses[@]} -gt 0 ] || stiffnesses=(100000 140000 200000 500000)
here=$(cd "$(dirname "$0")/.." && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cell() { # FILE PLANT -> one table cell
  local text
  text=$("$bin" sim --scenario "$1" --plant "$2" --tuning robust --check --out "$tmp/out" 2>&1 || true)
  awk '
    /the loop ended early: fault/ {
      at = ""
      if (match($0, /force [0-9.]+ N/)) at = " at " substr($0, RSTART + 6, RLENGTH - 6)
      sub(/.*the loop ended early: /, ""); sub(/ \(.*/, ""); end = "**" $0 "**" at " ❌"
    }
    /^  contact losses/ { losses = $3; if ($3 > 0 && match($0, /longest [0-9.]+ s/)) longest = ", longest " substr($0, RSTART + 8, RLENGTH - 8) }
    /^  final k̂_c/ { k = sprintf("%.0f kN/m", $3 / 1000) }
    /^  rms_error/ { rms = sprintf("%.3f N", $(NF - 1)); if ($NF != "pass") rms = "**" rms "** ❌" }
    END { printf "%s, %s losses%s, %s", (end != "" ? end : rms), losses, longest, k }' <<<"$text"
}
echo '| `k_c` | B5a 0.5 mm @ 0.5 Hz, P1 | B5a, P2 | B5b 1 mm @ 1 Hz, P1 | B5b, P2 |'
echo '|---|---|---|---|---|'
for k in "${stiffnesses[@]}"; do
  row="| $((k / 1000)) kN/m"
  for base in b05a-curve-slow b05b-curve-fast; do
    sed "s/^k_c = .*/k_c = $k.0/" "$here/scenarios/$base.toml" > "$tmp/$base-$k.toml"
    # A file whose stiffness line reads otherwise would run unchanged under this row's label.
    grep -qx "k_c = $k.0" "$tmp/$base-$k.toml" || { echo "stiff-curves: no 'k_c = ' line in $base.toml" >&2; exit 1; }
    for plant in p1 p2; do
      row+=" | $(cell "$tmp/$base-$k.toml" "$plant")"
    done
  done
  echo "$row |"
done
