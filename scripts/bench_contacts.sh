#!/usr/bin/env bash
# Contact-handling benchmark behind docs/BENCHMARKS.md: our generated M16 nut-bolt and 4 mm peg-hole, and
# Factory's own meshes (from $FACTORY_PEER_ASSETS, Factory's asset tree; for cross-checks only), at 1, 64
# and 1024 worlds.
# Usage: scripts/bench_contacts.sh OUT.jsonl
set -euo pipefail
out=${1:-bench_contacts.jsonl}
bin=${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench
mesh=${FACTORY_PEER_ASSETS:?set FACTORY_PEER_ASSETS to the Factory asset tree, meshes under factory/mesh}/factory/mesh
frames() { case $1 in 1) echo 20;; 64) echo 3;; *) echo 1;; esac; }
for w in 1 64 1024; do
  cpu=""; [ "$w" != 1024 ] && cpu="--cpu"
  "$bin" contacts --pair nut-bolt --size M16 --fit tight --worlds $w --frames $(frames $w) $cpu --json >> "$out"
  "$bin" contacts --pair nut-bolt --size M16 --fit tight --sdf analytic --worlds $w --frames $(frames $w) $cpu --json >> "$out"
  "$bin" contacts --mesh-a "$mesh/factory_nut_m16_tight_subdiv_3x.obj" --mesh-b "$mesh/factory_bolt_m16_tight.obj" \
    --pitch-mm 2 --worlds $w --frames $(frames $w) $cpu --json >> "$out"
  "$bin" contacts --pair peg-hole --size 4 --fit tight --worlds $w --frames $(frames $w) $cpu --json >> "$out"
  "$bin" contacts --mesh-a "$mesh/factory_round_peg_4mm_tight.obj" --mesh-b "$mesh/factory_round_hole_4mm_subdiv_3x.obj" \
    --pitch-mm 0 --worlds $w --frames $(frames $w) $cpu --json >> "$out"
done
