#!/usr/bin/env bash
# The whole-run training benchmark (docs/BENCHMARKS.md, "Training pace"): the Screw env trained for a few
# updates from each of four starts along the thread (resting on the bolt's tip, the first full thread, 5 and
# 9 turns further down: half-way and near seated), for one or more checkouts in one sitting, the phases
# interleaved so that a slow spell of a shared machine hits every checkout alike. Each update prints one JSON
# line (factory-train --json: env steps, rollout and learn time, time by stage), tagged here with the
# checkout's label, the phase and the round. scripts/training_table.py weighs the phases by their share of a
# whole run's env steps and prints the rates, their ratio and the stage shares.
#
# Usage: scripts/bench_training.sh OUT.jsonl LABEL=CHECKOUT[:FACTORY_TRAIN] ...
#   CHECKOUT: a checkout of the repository, whose configs/screw.toml is used (each commit with its own
#   defaults); FACTORY_TRAIN: its release build of factory-train (default CHECKOUT/target/release/...).
#   UPDATES=4 per phase (the first one warms up and is not counted), ROUNDS=1, ENVS=128.
# Example: scripts/bench_training.sh out.jsonl base=/tmp/base new=.:$HOME/.cache/factory-rs/target/release/factory-train
set -euo pipefail
out=${1:?usage: scripts/bench_training.sh OUT.jsonl LABEL=CHECKOUT[:FACTORY_TRAIN] ...}
shift
[ $# -gt 0 ] || { echo "name at least one LABEL=CHECKOUT" >&2; exit 2; }
updates=${UPDATES:-4}
rounds=${ROUNDS:-1}
envs=${ENVS:-128}
phases=(
  "tip|--set env.start_engaged=false"
  "first_thread|--set env.start_engaged=true"
  "half_way|--set env.start_engaged=true --set env.start_turns_down=5"
  "near_seated|--set env.start_engaged=true --set env.start_turns_down=9"
)
for spec in "$@"; do
  label=${spec%%=*}
  rest=${spec#*=}
  dir=${rest%%:*}
  bin=${rest#*:}
  [ "$bin" != "$rest" ] || bin=$dir/target/release/factory-train
  [ -x "$bin" ] || { echo "$label: no factory-train at $bin (build it: cargo build --release -p factory-rl --features wgpu)" >&2; exit 2; }
  [ -f "$dir/configs/screw.toml" ] || { echo "$label: no configs/screw.toml in $dir" >&2; exit 2; }
done
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for round in $(seq 1 "$rounds"); do
  for p in "${phases[@]}"; do
    phase=${p%%|*}
    read -r -a overrides <<< "${p#*|}"
    for spec in "$@"; do
      label=${spec%%=*}
      rest=${spec#*=}
      dir=${rest%%:*}
      bin=${rest#*:}
      [ "$bin" != "$rest" ] || bin=$dir/target/release/factory-train
      commit=$(git -C "$dir" rev-parse --short HEAD 2>/dev/null || echo unknown)
      echo "[bench_training] round $round, $phase, $label ($commit)" >&2
      "$bin" --config "$dir/configs/screw.toml" --updates "$updates" --envs "$envs" --json \
        --run-dir "$tmp/$label-$phase-$round" "${overrides[@]}" |
        sed "s/^{/{\"label\":\"$label\",\"commit\":\"$commit\",\"phase\":\"$phase\",\"round\":$round,/" >> "$out"
      rm -rf "${tmp:?}/$label-$phase-$round"
    done
  done
done
