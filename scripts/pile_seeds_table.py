#!/usr/bin/env python3
"""Markdown table from scripts/bench_piles_seeds.sh output: per build and setting, each seed's drift in the
last second [mm] and the fastest body's median speed over it [m/s], and how many seeds are at rest by the
pile tests' measure (drift < 1 mm and median < 0.01 m/s, bench/tests/piles.rs). A median that stays within 5%
in every second after the first is marked "steady": a motion that keeps up (such as a nut orbiting between two
poses), not settling."""
import json, sys
from collections import defaultdict

REST_DRIFT_MM, REST_SPEED = 1.0, 0.01
runs = defaultdict(list)
for l in open(sys.argv[1]):
    if l.strip():
        r = json.loads(l)
        runs[(r["build"], r["setting"])].append(r)
print("| build | setting | seeds: drift mm / median m/s | at rest |")
print("|---|---|---|---|")
for (build, setting), rs in runs.items():
    cells, rest = [], 0
    for r in sorted(rs, key=lambda r: r["seed"]):
        per = r["median_max_speed_per_second_m_s"][1:]
        steady = len(per) >= 3 and max(per) - min(per) < 0.05 * max(per)
        cells.append(f"{r['seed']}: {r['last_second_max_drift_mm']:.2f} / {r['last_second_median_max_speed_m_s']:.4f}"
                     + (" (steady)" if steady else ""))
        rest += r["last_second_max_drift_mm"] < REST_DRIFT_MM and r["last_second_median_max_speed_m_s"] < REST_SPEED
    print(f"| {build} | {setting} | {'; '.join(cells)} | {rest} of {len(rs)} |")
