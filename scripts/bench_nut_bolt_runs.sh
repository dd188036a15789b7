#!/usr/bin/env bash
# Nut-bolt speed of several builds or settings side by side in one run (docs/BENCHMARKS.md): for each world
# count, each run in turn, each at mu 0.05 and 0 (coarse nut: 48 segments per turn, 4 descent iterations).
# Usage: scripts/bench_nut_bolt_runs.sh OUT.jsonl 'LABEL|BIN|EXTRA ARGS' ...
#   e.g. 'before|/tmp/bins/base|' 'after, 4 per invocation|target/release/factory-bench|--per 4'
# Worlds: WORLDS (default "1 64 1024"); rounds: ROUNDS (default 1), the runs alternating within each round.
set -euo pipefail
out=$1
shift
: > "$out"
for round in $(seq "${ROUNDS:-1}"); do
  for w in ${WORLDS:-1 64 1024}; do
    secs=0.25; [ "$w" = 1 ] && secs=1
    for spec in "$@"; do
      IFS='|' read -r label bin extra <<< "$spec"
      for mu in 0.05 0; do
        # shellcheck disable=SC2086
        "$bin" scene nut-bolt --worlds "$w" --seconds "$secs" --mu "$mu" --segments-per-turn 48 \
          --descent-iters 4 $extra --json 2>/dev/null |
          python3 -c "import json,sys; d=json.load(sys.stdin); print(json.dumps({'build': sys.argv[1], 'round': int(sys.argv[2]), **d}))" \
            "$label" "$round" >> "$out"
      done
    done
  done
done
