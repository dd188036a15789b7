#!/usr/bin/env bash
# The Franka + nut-and-bolt row of docs/BENCHMARKS.md (paper Table II, eighth scene) and the controller cost:
# `factory-bench controllers` at 1, 16 and 128 worlds; the scripted franka-nut-bolt scene at the given world
# counts (whole episodes: pick, place, screw; 60 s limit); and, in the same run, the bare nut-bolt scene at
# the same world counts with the same solver settings (4 substeps, 32 position iterations, 0 velocity
# iterations, mu 0.3, 2 mm offset, the scene's 48-segment nut) for the robot's share of a frame.
# Usage: [FRANKA_SECONDS=S] scripts/bench_franka.sh OUT.jsonl [WORLDS...]   (default worlds: 1 16 128;
# FRANKA_SECONDS cuts the Franka episodes short, e.g. 10 for the pick-and-place part at many worlds)
set -euo pipefail
out=${1:-bench_franka.jsonl}
shift || true
worlds=${*:-1 16 128}
bin=${CARGO_TARGET_DIR:-target}/release/factory-bench
[ -x "$bin" ] || bin=${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench
for w in 1 16 128; do
  "$bin" controllers --worlds "$w" --json >> "$out"
done
for w in $worlds; do
  "$bin" scene nut-bolt --worlds "$w" --seconds 2 --substeps 4 --pos-iters 32 --vel-iters 0 --mu 0.3 \
    --offset-mm 2 --segments-per-turn 48 --json >> "$out"
  "$bin" scene franka-nut-bolt --worlds "$w" ${FRANKA_SECONDS:+--seconds $FRANKA_SECONDS} --json >> "$out"
done
