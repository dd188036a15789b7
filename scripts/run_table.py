#!/usr/bin/env python3
"""A training run's metrics.csv as a Markdown table per window of updates (docs/RESULTS.md, BENCHMARKS.md).

Usage: scripts/run_table.py RUN_DIR/metrics.csv [WINDOW]   (WINDOW: updates per row, default 50)

Per window: the episodes that ended in it and how (metrics.csv's `ended_by`, e.g. "fallen=1 success=2"),
the share seated, and the pace: env steps per second of wall time (the window's env steps over the growth
of `wall_seconds`, which a resumed run carries on from its checkpoint), with the rollout's and the
learner's shares of it. A last line gives the whole run's totals.
"""
import csv
import sys
from collections import Counter


def parse_ended(s):
    c = Counter()
    for item in s.split():
        cause, _, n = item.partition("=")
        c[cause] += int(n)
    return c


def main():
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    path = sys.argv[1]
    window = int(sys.argv[2]) if len(sys.argv) == 3 else 50
    if window < 1:
        sys.exit(f"WINDOW must be at least 1, got {window}")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{path}: no updates")
    for key in ("update", "env_steps", "wall_seconds", "rollout_seconds", "learn_seconds", "ended_by"):
        if key not in rows[0]:
            sys.exit(f"{path}: no column `{key}` (columns: {', '.join(rows[0])})")
    print("| updates | episodes | seated | how the others ended | env steps/s | rollout share | learn share |")
    print("|---|---|---|---|---|---|---|")
    prev_wall, prev_steps = 0.0, 0
    total = Counter()
    for start in range(0, len(rows), window):
        chunk = rows[start:start + window]
        ended = Counter()
        for r in chunk:
            ended += parse_ended(r["ended_by"])
        total += ended
        wall = float(chunk[-1]["wall_seconds"]) - prev_wall
        steps = int(chunk[-1]["env_steps"]) - prev_steps
        roll = sum(float(r["rollout_seconds"]) for r in chunk)
        learn = sum(float(r["learn_seconds"]) for r in chunk)
        prev_wall, prev_steps = float(chunk[-1]["wall_seconds"]), int(chunk[-1]["env_steps"])
        episodes = sum(ended.values())
        seated = ended.get("success", 0)
        others = ", ".join(f"{k} {v}" for k, v in sorted(ended.items()) if k != "success") or "-"
        share = f"{seated} ({100 * seated / episodes:.0f}%)" if episodes else "-"
        print(f"| {chunk[0]['update']}-{chunk[-1]['update']} | {episodes} | {share} | {others} | "
              f"{steps / wall:.0f} | {roll / wall:.2f} | {learn / wall:.2f} |")
    last = rows[-1]
    wall = float(last["wall_seconds"])
    episodes = sum(total.values())
    print(f"\n{last['update']} updates, {last['env_steps']} env steps in {wall:.0f} s ({wall / 3600:.2f} h): "
          f"{int(last['env_steps']) / wall:.0f} env steps/s; {episodes} episodes, "
          f"{total.get('success', 0)} seated")


if __name__ == "__main__":
    main()
