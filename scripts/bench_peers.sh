#!/usr/bin/env bash
# The nut-and-bolt scene in the peers and in factory-rs, one after another in one run (docs/BENCHMARKS.md,
# "Peers side by side"): these machines differ by 3x from one session to the next, so only figures taken
# in the same run compare. MuJoCo's procedural toy brackets the run (first and last) to show the machine
# held still. The peers' scripts are not part of this repository: PEERS_DIR holds them and their virtual
# environments; a peer whose environment is missing is skipped and says so.
# Usage: scripts/bench_peers.sh PEERS_DIR OUT.txt [FACTORY_BENCH] [ASSETS_DIR]
#   FACTORY_ARGS (environment): extra options for the factory-rs runs (e.g. "--per 4")
#   PEERS_DIR: folder with mujoco_nutbolt.py, newton_nutbolt.py and their .venv-mujoco / .venv-newton
#   ASSETS_DIR: Factory's meshes for the peers' M16 runs (default PEERS_DIR/../peer_assets)
# Output: one line per run, peers' own lines as they print them, factory-rs runs as JSON objects.
set -euo pipefail
peers=$1 out=$2
bin=${3:-${CARGO_TARGET_DIR:-$HOME/.cache/factory-rs/target}/release/factory-bench}
assets=${4:-$peers/../peer_assets}
mj=$peers/.venv-mujoco/bin/python nw=$peers/.venv-newton/bin/python
: > "$out"
say() { echo "# $*" >> "$out"; }
toy() {
  if [ -x "$mj" ]; then "$mj" "$peers/mujoco_nutbolt.py" --geom plugin "$@" >> "$out" 2>&1; else say "no MuJoCo venv"; fi
}
say "start $(date -u +%FT%TZ) $(uname -m) $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2) nproc $(nproc)"
toy --n 1 --T 2
toy --n 16 --T 0.5
if [ -x "$mj" ]; then
  "$mj" "$peers/mujoco_nutbolt.py" --geom factory --friction 0.05 --T 0.1 --assets "$assets" >> "$out" 2>&1 ||
    say "MuJoCo mesh SDF run failed"
fi
if [ -x "$nw" ]; then
  "$nw" "$peers/newton_nutbolt.py" --n 1 --T 0.25 >> "$out" 2>&1 || say "Newton run failed"
else
  say "no Newton venv"
fi
# factory-rs: the paper's solver settings (dt 1/60 s, 1 substep, 20 + 1 iterations), the coarse nut of
# "Model only what the scene needs" (48 segments per turn, 4 descent iterations), mu 0.05 and frictionless.
for w in 1 64 1024; do
  secs=0.25; [ "$w" = 1 ] && secs=1
  for mu in 0.05 0; do
    # shellcheck disable=SC2086
    "$bin" scene nut-bolt --worlds "$w" --seconds "$secs" --mu "$mu" --segments-per-turn 48 \
      --descent-iters 4 ${FACTORY_ARGS:-} --json 2>/dev/null >> "$out"
  done
done
toy --n 1 --T 2
say "end $(date -u +%FT%TZ)"
