#!/usr/bin/env bash
# The pass table of docs/controller.md, from the shipped command over the default wires (RSI to the simulated KRC over
# loopback UDP, ATI over the in-memory CAN bus): `forcecell sim --scenario NAME --plant P --check` for every
# pass on P1 and P2. Usage: scripts/pass-table.sh [path/to/forcecell]   (default: target/release/forcecell)
set -euo pipefail
bin=${1:-target/release/forcecell}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo '| pass | plant | cycles/s | in band (≥ 98 %) | overshoot (≤ 10 %) | release excess (≤ 5 % F) | final \|x_cmd\| (≤ 10 µm) | contact losses (0) | pressing (s) |'
echo '|---|---|---|---|---|---|---|---|---|'
for pass in pass-flat-20n pass-wavy-50 pass-wavy-100 pass-tilt-step pass-force-steps; do
  for plant in p1 p2; do
    text=$("$bin" sim --scenario "$pass" --plant "$plant" --check --out "$out" || true)
    awk -v pass="$pass" -v plant="${plant^^}" '
      / steps\/s\)/ { gsub(/[()]/, ""); for (i = 1; i <= NF; i++) if ($i == "steps/s") rate = $(i - 1) }
      $1 ~ /^(pressing_in_band_pct|press_overshoot_pct|release_excess|final_correction|press_contact_losses|pressing_time)$/ {
        v[$1] = $(NF - 1); ok[$1] = ($NF == "pass")
      }
      function cell(m, fmt, scale,   s) {
        s = sprintf(fmt, v[m] * scale)
        return ok[m] ? s : "**" s " ✗**"
      }
      END {
        printf "| `%s` | %s | %s | %s | %s | %s | %s | %s | %s |\n", pass, plant, rate,
          cell("pressing_in_band_pct", "%.1f", 1), cell("press_overshoot_pct", "%.1f", 1),
          cell("release_excess", "%.2f N", 1), cell("final_correction", "%.1f µm", 1e6),
          cell("press_contact_losses", "%d", 1), cell("pressing_time", "%.2f", 1)
      }' <<<"$text"
  done
done
