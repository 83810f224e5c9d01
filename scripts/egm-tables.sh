#!/usr/bin/env bash
# The B table and the pass table over ABB EGM (docs/egm.md): the shipped command with the EGM driver against the
# simulated IRC5 over loopback UDP and the ATI driver over the in-memory CAN bus, lockstep, the shipped tuning:
#   forcecell sim --scenario NAME --robot egm --plant P --check
# on P1, P2 and the EGM plant (4 ms cycle, 10 ms lag, 20 ms pure delay: the top of the 10–20 ms control lag that
# EGM is said to have, taken as pure delay on top of the lag). The EGM plant is not a built-in `--plant`: the script
# writes a copy of each scenario with `plant = { period = 0.004, tau = 0.010, delay_cycles = 5 }` into a temp
# directory. A scenario with its own explicit plant (B7's delay sweep) runs on that plant only.
# Usage: scripts/egm-tables.sh [path/to/forcecell]   (default: target/release/forcecell)
set -euo pipefail
bin=${1:-target/release/forcecell}
here=$(cd "$(dirname "$0")/.." && pwd)
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
egm_plant='plant = { period = 0.004, tau = 0.010, delay_cycles = 5 }'

# run NAME PLANT → the command's output; PLANT is p1, p2, egm or own (the scenario's explicit plant)
run() {
  local name=$1 plant=$2 file="$here/scenarios/$1.toml"
  case $plant in
    own) "$bin" sim --scenario "$file" --robot egm --check --out "$out" || true ;;
    egm)
      mkdir -p "$out/egm"
      sed "s/^plant = .*/$egm_plant/" "$file" >"$out/egm/$name.toml"
      "$bin" sim --scenario "$out/egm/$name.toml" --robot egm --check --out "$out" || true ;;
    *) "$bin" sim --scenario "$file" --robot egm --plant "$plant" --check --out "$out" || true ;;
  esac
}
plants_of() { if grep -q '^plant = {' "$here/scenarios/$1.toml"; then echo own; else echo p1 p2 egm; fi; }
label() { case $1 in own) echo "own";; egm) echo "EGM";; *) echo "${1^^}";; esac; }

echo '### B scenarios over EGM'
echo
echo '| scenario | plant | targets (value, bound) | EGM link |'
echo '|---|---|---|---|'
for f in "$here"/scenarios/b*.toml; do
  name=$(basename "$f" .toml)
  for plant in $(plants_of "$name"); do
    run "$name" "$plant" | awk -v name="$name" -v plant="$(label "$plant")" '
      /^EGM link:/ { sub(/^EGM link: /, ""); split($0, a, ", "); link = a[1] ", " a[2] ", " a[7] }
      /^targets:/ { t = 1; next }
      t && NF >= 5 && ($NF == "pass" || $NF == "FAIL" || $NF == "fail") {
        bound = $(NF - 3) " " $(NF - 2); s = sprintf("%s %s (%s)", $1, $(NF - 1), bound)
        if ($NF != "pass") { s = "**" s " ✗**"; bad++ } else n++
        cells = cells (cells == "" ? "" : "; ") s
      }
      t && NF == 0 { t = 0 }
      END {
        if (cells == "") cells = "**no targets read ✗**"
        printf "| `%s` | %s | %s %s | %s |\n", name, plant, (bad ? "❌" : "✅"), cells, link
      }'
  done
done

echo
echo '### Passes over EGM'
echo
echo '| pass | plant | cycles/s | in band (≥ 98 %) | overshoot (≤ 10 %) | release excess (≤ 5 % F) | final \|x_cmd\| (≤ 10 µm) | contact losses (0) | pressing (s) |'
echo '|---|---|---|---|---|---|---|---|---|'
for pass in pass-flat-20n pass-wavy-50 pass-wavy-100 pass-tilt-step pass-force-steps; do
  for plant in p1 p2 egm; do
    run "$pass" "$plant" | awk -v pass="$pass" -v plant="$(label "$plant")" '
      / steps\/s\)/ { gsub(/[()]/, ""); for (i = 1; i <= NF; i++) if ($i == "steps/s") rate = $(i - 1) }
      $1 ~ /^(pressing_in_band_pct|press_overshoot_pct|release_excess|final_correction|press_contact_losses|pressing_time)$/ {
        v[$1] = $(NF - 1); ok[$1] = ($NF == "pass"); seen[$1] = 1
      }
      function cell(m, fmt, scale,   s) {
        if (!seen[m]) return "**— ✗**"
        s = sprintf(fmt, v[m] * scale)
        return ok[m] ? s : "**" s " ✗**"
      }
      END {
        printf "| `%s` | %s | %s | %s | %s | %s | %s | %s | %s |\n", pass, plant, rate,
          cell("pressing_in_band_pct", "%.1f", 1), cell("press_overshoot_pct", "%.1f", 1),
          cell("release_excess", "%.2f N", 1), cell("final_correction", "%.1f µm", 1e6),
          cell("press_contact_losses", "%d", 1), cell("pressing_time", "%.2f", 1)
      }'
  done
done
