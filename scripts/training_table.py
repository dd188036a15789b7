#!/usr/bin/env python3
"""The whole-run training benchmark's table (docs/BENCHMARKS.md, "Training pace") from the JSON lines of
scripts/bench_training.sh.

Per checkout (label) and phase: env steps/s over the counted updates (all but each run's first, a warm-up),
learning included (rl_games' "fps total"). The whole-run rate weighs the phases by their share w_i of a whole
run's env steps: total time = sum_i w_i / rate_i, so a speed-up in one phase does not change its own weight.
The shares come from a file with task-progress counts (`--weights-from`: a factory-eval JSON or a run's
metrics.csv, whose `progress_steps` count world-steps per tenth of the nut's descent), each tenth going to
the last phase whose start lies at or below the tenth's centre (the starts' progress: tip 0, first thread
0.12, half-way 0.52, near seated 0.84 of the descent from the tip's 25 mm); or `--weights a,b,c,d`.
The stage shares (contacts, solve, controller, task, policy, learn, other) are whole-run weighted the same
way. The last column is each checkout's whole-run rate over the first label's.

Usage: scripts/training_table.py OUT.jsonl (--weights-from FILE | --weights a,b,c,d)
"""
import argparse
import csv
import json
import sys
from collections import defaultdict

PHASES = ["tip", "first_thread", "half_way", "near_seated"]
# Each phase's start as a fraction of the descent from resting on the tip (25 mm above the seat) to seated:
# the first full thread at 22 mm, 5 turns of 2 mm further down at 12 mm, 9 turns at 4 mm.
STARTS = [0.0, 1 - 22 / 25, 1 - 12 / 25, 1 - 4 / 25]
STAGES = ["contacts", "solve", "controller", "task", "policy", "learn", "rollout_other"]


def weights_from(path):
    if path.endswith(".csv"):
        counts = [0] * 10
        with open(path) as f:
            for row in csv.DictReader(f):
                cells = (row.get("progress_steps") or "").split()
                for k, c in enumerate(cells):
                    counts[k] += int(c)
    else:
        with open(path) as f:
            text = f.read().strip()
        report = json.loads(text.splitlines()[-1])
        counts = report.get("progress_steps") or report.get("report", {}).get("progress_steps")
    if not counts or sum(counts) == 0:
        sys.exit(f"{path}: no progress_steps counts (an env that reports task progress, a build that records it)")
    w = [0.0] * len(PHASES)
    for k, c in enumerate(counts):
        centre = (k + 0.5) / len(counts)
        phase = max(i for i, s in enumerate(STARTS) if s <= centre)
        w[phase] += c
    total = sum(w)
    return [x / total for x in w]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("jsonl")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--weights-from")
    g.add_argument("--weights")
    args = ap.parse_args()
    w = weights_from(args.weights_from) if args.weights_from else [float(x) for x in args.weights.split(",")]
    if len(w) != len(PHASES) or min(w) < 0 or sum(w) <= 0:
        sys.exit(f"weights: {w}; expected {len(PHASES)} non-negative numbers, one per phase ({', '.join(PHASES)})")
    w = [x / sum(w) for x in w]
    # label -> phase -> [env steps, seconds, {stage: seconds}] over the counted updates.
    acc = defaultdict(lambda: defaultdict(lambda: [0, 0.0, defaultdict(float)]))
    labels, commits = [], {}
    for line in open(args.jsonl):
        rec = json.loads(line)
        r = rec["report"]
        label, phase = rec["label"], rec["phase"]
        if label not in labels:
            labels.append(label)
        commits[label] = rec.get("commit", "?")
        if r["update"] == 1:
            continue
        a = acc[label][phase]
        a[0] += r["env_steps"] // r["update"]
        a[1] += r["rollout_seconds"] + r["learn_seconds"]
        for k, v in r.get("stage_seconds", {}).items():
            a[2][k] += v
    print("phase weights (share of a whole run's env steps): " + ", ".join(f"{p} {x:.3f}" for p, x in zip(PHASES, w)))
    print()
    head = ["checkout", "commit"] + [f"{p} steps/s" for p in PHASES] + ["whole-run steps/s", "vs " + labels[0]]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    base = None
    shares = {}
    for label in labels:
        rates, per_step_stage = [], defaultdict(float)
        for i, p in enumerate(PHASES):
            steps, seconds, stages = acc[label].get(p) or (0, 0.0, {})
            if seconds == 0:
                sys.exit(f"{args.jsonl}: no counted update for {label} / {p}")
            rates.append(steps / seconds)
            for k, v in stages.items():
                per_step_stage[k] += w[i] * v / steps
        whole = 1 / sum(wi / ri for wi, ri in zip(w, rates))
        base = base or whole
        cells = [label, commits[label]] + [f"{r:.1f}" for r in rates] + [f"{whole:.1f}", f"{whole / base:.2f}x"]
        print("| " + " | ".join(cells) + " |")
        total = sum(per_step_stage.values())
        shares[label] = {k: v / total for k, v in per_step_stage.items()} if total else {}
    print()
    head = ["checkout"] + STAGES
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for label in labels:
        print("| " + " | ".join([label] + [f"{100 * shares[label].get(s, 0):.0f}%" for s in STAGES]) + " |")


if __name__ == "__main__":
    main()
