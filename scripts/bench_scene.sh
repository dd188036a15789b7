#!/usr/bin/env bash
# Whole-frame benchmark of the nut-bolt scene (contacts + solver on the GPU) behind docs/BENCHMARKS.md:
# the paper's settings (dt 1/60 s, 1 substep, 20 position and 1 velocity iteration, mu 0.05) at 1, 64 and
# 1024 worlds, with the exact analytic bolt SDF and with a 256 grid; plus a frictionless accuracy run.
# Usage: scripts/bench_scene.sh OUT.jsonl
set -euo pipefail
out=${1:-bench_scene.jsonl}
bin=${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench
"$bin" scene nut-bolt --mu 0 --seconds 1 --json >> "$out"
for sdf in analytic 256; do
  "$bin" scene nut-bolt --sdf-res $sdf --worlds 1 --seconds 1 --json >> "$out"
  "$bin" scene nut-bolt --sdf-res $sdf --worlds 64 --seconds 0.5 --json >> "$out"
  "$bin" scene nut-bolt --sdf-res $sdf --worlds 1024 --seconds 0.1 --json >> "$out"
done
