#!/usr/bin/env bash
# Whether 64-nut piles come to rest, over several seeds and solver settings, for one or more builds
# (docs/BENCHMARKS.md, "Piles of parts"): one drop of 64 nuts decides little,
# since which nut ends on a flat or leans on a neighbour changes with every detail of the run, so compare
# builds over the same seeds. Settings: T2 (Table II: 1 substep, 16 + 1 iterations), S2 (2 substeps, 32 + 4:
# the 64-nut test's). Usage: scripts/bench_piles_seeds.sh OUT.jsonl SEEDS BIN... (SEEDS e.g. "1 2 3 4";
# BIN: factory-bench binaries, e.g. copies built at two commits). Then: python3 scripts/pile_seeds_table.py OUT.jsonl
set -euo pipefail
out=$1 seeds=$2
shift 2
: > "$out"
for setting in T2 S2; do
  args=""; [ "$setting" = S2 ] && args="--substeps 2 --pos-iters 32 --vel-iters 4"
  for seed in $seeds; do
    for bin in "$@"; do
      # shellcheck disable=SC2086
      "$bin" scene pile-nuts --bodies 64 --seconds 6 --seed "$seed" $args --json 2>/dev/null |
        python3 -c "import json,sys; d=json.load(sys.stdin); print(json.dumps({'build': sys.argv[1], 'setting': sys.argv[2], 'seed': int(sys.argv[3]), **d}))" \
          "$bin" "$setting" "$seed" >> "$out"
    done
  done
done
