#!/usr/bin/env python3
"""One or more `factory-eval --json` reports as Markdown table rows, and their sum (docs/RESULTS.md).

Usage: scripts/eval_table.py REPORT.json [REPORT.json ...]

Each file holds the JSON objects `factory-eval --json` prints, one per line (one run, or several appended).
Each row is named by its file and by what acted (the policy or a baseline, with mean or sampled actions).
Per report and, when every report is of the same actor (independent episodes, e.g. chunks run with
different --seed), for all of them together: episodes, seated with
the share and its 95% Wilson score interval, mean env steps to seat (over the seated episodes), mean
return (over all episodes) and how the others ended. The joint-torque norm is a mean over every world's
steps, whose count a report does not give, so the sum row shows the chunks' range instead of a mean.
"""
import json
import math
import sys
from collections import Counter


def wilson(k, n, z=1.959964):
    """95% Wilson score interval of k successes in n trials."""
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return mid - half, mid + half


def row(name, n, seated, steps, ret, causes, torque):
    lo, hi = wilson(seated, n)
    others = ", ".join(f"{c} {k}" for c, k in sorted(causes.items()) if c != "success") or "-"
    return (
        f"| {name} | {n} | {seated} ({100 * seated / n:.1f}%) | {100 * lo:.1f}-{100 * hi:.1f}% | "
        f"{steps:.0f} | {ret:.1f} | {torque} | {others} |"
    )


def main():
    paths = sys.argv[1:]
    if not paths:
        sys.exit(__doc__)
    print("| report | episodes | seated | 95% interval (Wilson) | mean steps to seat | mean return | "
          "mean joint-torque norm [N m] | how the others ended |")
    print("|---|---|---|---|---|---|---|---|")
    tot_n = tot_seated = 0
    tot_steps = tot_ret = 0.0
    tot_causes = Counter()
    torques = []
    actors = set()
    reports = []
    for path in paths:
        try:
            lines = [l for l in open(path) if l.strip()]
            reports += [(path, json.loads(l)) for l in lines]
        except (OSError, ValueError) as e:
            sys.exit(f"{path}: not factory-eval --json output ({e})")
    for path, r in reports:
        try:
            actor = r.get("actor", "policy")
            how = "sampled" if r["stochastic"] else "mean"
            if actor == "constant":
                how = "[" + ", ".join(f"{a:g}" for a in r["constant_action"]) + "]"
            elif actor in ("zero", "scripted"):
                how = "-"
            actors.add((actor, how))
            n = int(r["episodes"])
            seated = round(r["success_rate"] * n)
            causes = Counter(r["ended_by"])
        except (OSError, ValueError, KeyError, TypeError) as e:
            sys.exit(f"{path}: not a factory-eval --json report ({e})")
        if causes.get("success", 0) != seated:
            sys.exit(f"{path}: success_rate x episodes = {seated} but ended_by.success = {causes.get('success')}")
        steps = r["mean_steps_to_success"] if seated else float("nan")
        name = f"{actor} ({how}), {path.rsplit('/', 1)[-1]}"
        print(row(name, n, seated, steps, r["mean_return"], causes, f"{r['mean_joint_torque_norm']:.2f}"))
        tot_n += n
        tot_seated += seated
        tot_steps += steps * seated if seated else 0.0
        tot_ret += r["mean_return"] * n
        tot_causes += causes
        torques.append(r["mean_joint_torque_norm"])
    if len(reports) > 1 and len(actors) == 1:
        steps = tot_steps / tot_seated if tot_seated else float("nan")
        torque = f"{min(torques):.2f}-{max(torques):.2f}"
        print(row("all", tot_n, tot_seated, steps, tot_ret / tot_n, tot_causes, torque))


if __name__ == "__main__":
    main()
