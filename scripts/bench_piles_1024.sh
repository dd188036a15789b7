#!/usr/bin/env bash
# The paper's piles (III-D, Tables I and II): 1024 toruses, 1024 M16 nuts and 1024 bowls, each falling into
# a pile in one world, on the coloured many-body solver at the paper's Table II settings per scene.
# Slow on a 2-core CPU (lavapipe): about 2-5 s per frame, so SECONDS (default 5) of simulation take
# 10-30 minutes per pile. Usage: scripts/bench_piles_1024.sh OUT.jsonl [SECONDS] [SCENES...]
set -euo pipefail
out=${1:-bench_piles_1024.jsonl}
seconds=${2:-5}
shift $(( $# > 2 ? 2 : $# ))
scenes=${*:-pile-toruses pile-nuts pile-bowls}
bin=${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench
for scene in $scenes; do
  "$bin" scene "$scene" --bodies 1024 --seconds "$seconds" --json >> "$out"
done
