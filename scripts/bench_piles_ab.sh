#!/usr/bin/env bash
# Small pile scenes of two builds side by side (docs/BENCHMARKS.md,
# "Piles of parts"): 32 toruses for 0.5 s, 8 bowls and 8 nuts for 1 s, coloured solver, build A then build B each.
# Usage: scripts/bench_piles_ab.sh BIN_A BIN_B OUT.jsonl (factory-bench binaries built at two commits).
set -euo pipefail
a=$1 b=$2 out=$3
: > "$out"
for scene in "pile-toruses --bodies 32 --seconds 0.5" "pile-bowls --bodies 8 --seconds 1" "pile-nuts --bodies 8 --seconds 1"; do
  for bin in "$a" "$b"; do
    # shellcheck disable=SC2086
    "$bin" scene $scene --pile-solver coloured --json 2>/dev/null |
      python3 -c "import json,sys; d=json.load(sys.stdin); print(json.dumps({'build': sys.argv[1], **d}))" "$bin" >> "$out"
  done
done
