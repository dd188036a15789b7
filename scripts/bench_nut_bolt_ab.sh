#!/usr/bin/env bash
# Nut-bolt speed of two builds side by side in one run (docs/BENCHMARKS.md, "The solver's storage reads"):
# for each world count, build A then build B, each at mu 0.05 and 0 (coarse nut: 48 segments per turn,
# 4 descent iterations). Usage: scripts/bench_nut_bolt_ab.sh BIN_A BIN_B OUT.jsonl
# (BIN_*: factory-bench binaries, e.g. copies of target/release/factory-bench built at two commits).
set -euo pipefail
a=$1 b=$2 out=$3
: > "$out"
for w in 1 64 1024; do
  secs=0.25; [ "$w" = 1 ] && secs=1
  for bin in "$a" "$b"; do
    for mu in 0.05 0; do
      "$bin" scene nut-bolt --worlds "$w" --seconds "$secs" --mu "$mu" --segments-per-turn 48 \
        --descent-iters 4 --json 2>/dev/null |
        python3 -c "import json,sys; d=json.load(sys.stdin); d={'build': sys.argv[1], **d}; print(json.dumps(d))" "$bin" >> "$out"
    done
  done
done
