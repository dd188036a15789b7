#!/usr/bin/env bash
# Whole-frame benchmark of the pile scenes (paper III-D; contacts + solver on the GPU) behind
# docs/BENCHMARKS.md: toruses at 8, 16 and 32 bodies in one world, 8 toruses in each of 16 worlds, and 8
# bowls and 8 nuts, each at the paper's Table II solver settings for the scene.
# Usage: scripts/bench_piles.sh OUT.jsonl
set -euo pipefail
out=${1:-bench_piles.jsonl}
bin=${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench
"$bin" scene pile-toruses --bodies 8 --seconds 5 --json >> "$out"
"$bin" scene pile-toruses --bodies 16 --seconds 3 --json >> "$out"
"$bin" scene pile-toruses --bodies 32 --seconds 2 --json >> "$out"
"$bin" scene pile-toruses --bodies 8 --worlds 16 --seconds 1 --json >> "$out"
"$bin" scene pile-bowls --bodies 8 --seconds 5 --json >> "$out"
"$bin" scene pile-nuts --bodies 8 --seconds 5 --json >> "$out"
