#!/usr/bin/env bash
# Nut-bolt speed of two builds side by side in one run (docs/BENCHMARKS.md):
# for each world count, build A then build B, each at mu 0.05 and 0 (coarse nut: 48 segments per turn,
# 4 descent iterations). Usage: scripts/bench_nut_bolt_ab.sh BIN_A BIN_B OUT.jsonl
# (BIN_*: factory-bench binaries, e.g. copies of target/release/factory-bench built at two commits; each
# line's `build` is the binary's path). The general form, with labels, options and rounds:
# scripts/bench_nut_bolt_runs.sh.
set -euo pipefail
exec "$(dirname "$0")/bench_nut_bolt_runs.sh" "$3" "$1|$1|" "$2|$2|"
