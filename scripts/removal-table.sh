#!/usr/bin/env bash
# The removal comparison on one raster (docs/removal.md): the same part, program and removal model
# (scenario raster-wavy-100, or the one given), five ways of pressing: the robust law, the paper's law, fixed-offset
# impedance (tunings/impedance.toml), a pure position path with no force control (a tuning written
# here: an impedance so stiff that it holds a fixed offset), and the robust law with a sensor drifting
# 0.5 N/min. Prints the Markdown table and writes the maps side by side.
#
# Usage: scripts/removal-table.sh [OUT] [SCENARIO]
#   (default out/removal-table and raster-wavy-100; needs a release build: cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-out/removal-table}
scenario=${2:-raster-wavy-100}
bin=${FORCECELL:-target/release/forcecell}
mkdir -p "$out/cases"
cat > "$out/position.toml" <<'TOML'
name = "position"
description = "A pure position path: the tool held 2 mm into the pad beyond the programmed path (20 N on the nominal 10 N/mm pad), no force control: an impedance so stiff that the force barely moves it"

[law]
kind = "impedance"
impedance = { f_r = 0.0, m_d = 8.0, b_d = 4000.0, k_d = 500000.0 }
x_r = 0.003

[loop]
force_sign = 1.0
max_step = 0.01
max_offset = 0.05
TOML
sed -e "s/^name = \"$scenario\"/name = \"$scenario-drift\"/" "scenarios/$scenario.toml" > "$out/drift.toml"
printf '\n[sensor]\ndrift_per_min = 0.5        # N/min: the B6 drift\n' >> "$out/drift.toml"

run() { # LABEL SCENARIO TUNING
  rm -rf "$out/cases/$1"
  "$bin" sim --scenario "$2" --tuning "$3" --out "$out/cases/$1" > "$out/cases/$1.txt" 2>&1 || true
  local rec
  rec=$(ls "$out/cases/$1"/*.mcap | grep -v -- '-removal.mcap' | head -1)
  cp "$rec" "$out/$1.mcap"
}
run robust "$scenario" robust
run paper "$scenario" paper
run impedance "$scenario" impedance
run position "$scenario" "$out/position.toml"
run robust-drift "$out/drift.toml" robust
"$bin" removal "$out"/{robust,paper,impedance,position,robust-drift}.mcap --config "$scenario" \
  --out "$out/maps" --compare "$out/removal-comparison.png" | sed -n '/^| case/,$p'
