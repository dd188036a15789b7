#!/usr/bin/env bash
# Contact handling (generate + merge + normals) of builds side by side, round robin (docs/BENCHMARKS.md,
# "Contact handling"): M16 nut-bolt, coarse nut (48 segments per turn, 4 descent
# iterations), analytic bolt SDF, W worlds, 10 frames per run, R rounds.
# Usage: scripts/bench_contacts_ab.sh R W OUT.jsonl BIN...  (BIN: factory-bench binaries built at the commits
# compared, each optionally followed by '|' and extra options, e.g. 'target/release/factory-bench|--per 4').
# Prints the minimum and median handling ms per frame of each build.
set -euo pipefail
rounds=$1 worlds=$2 out=$3
shift 3
: > "$out"
for _ in $(seq "$rounds"); do
  for spec in "$@"; do
    IFS='|' read -r bin extra <<< "$spec"
    # shellcheck disable=SC2086
    "$bin" contacts --sdf analytic --segments-per-turn 48 --descent-iters 4 --worlds "$worlds" --frames 10 $extra --json 2>/dev/null |
      python3 -c "import json,sys; d=json.load(sys.stdin); print(json.dumps({'build': sys.argv[1], **d}))" "$spec" >> "$out"
  done
done
python3 - "$out" <<'PY'
import json, statistics, sys
rows = [json.loads(l) for l in open(sys.argv[1])]
for b in dict.fromkeys(r['build'] for r in rows):
    t = [r['handling_ms_per_frame'] for r in rows if r['build'] == b]
    r0 = next(r for r in rows if r['build'] == b)
    print(f"{b}: min {min(t):.1f} median {statistics.median(t):.1f} ms/frame over {len(t)} runs; "
          f"candidates {r0['candidates_per_pair']:.0f}, contacts {r0['contacts_per_pair']:.3f}, patches {r0['patches_per_pair']:.3f}")
PY
