#!/usr/bin/env bash
# Whole-frame benchmark of the pile scenes (paper III-D; contacts + solver on the GPU) behind
# docs/BENCHMARKS.md: the serial solver (fixed pair list, one invocation per world) and the coloured
# many-body solver side by side on the same small piles (8 and 32 toruses, 8 bowls, 8 nuts), and 8
# toruses in each of 16 worlds; each at the paper's Table II solver settings for the scene.
# The paper's 1024-body piles: scripts/bench_piles_1024.sh.
# Usage: scripts/bench_piles.sh OUT.jsonl
set -euo pipefail
out=${1:-bench_piles.jsonl}
bin=${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench
for solver in serial coloured; do
  "$bin" scene pile-toruses --bodies 8 --seconds 5 --pile-solver $solver --json >> "$out"
  "$bin" scene pile-toruses --bodies 32 --seconds 2 --pile-solver $solver --json >> "$out"
  "$bin" scene pile-toruses --bodies 8 --worlds 16 --seconds 1 --pile-solver $solver --json >> "$out"
  "$bin" scene pile-bowls --bodies 8 --seconds 5 --pile-solver $solver --json >> "$out"
  "$bin" scene pile-nuts --bodies 8 --seconds 5 --pile-solver $solver --json >> "$out"
done
