#!/usr/bin/env python3
"""Markdown table from `factory-bench scene pile-* --json` lines (scripts/bench_piles*.sh output)."""
import json, sys

print("| scene | solver | bodies x worlds | near pairs (colours) | simulated s | ms/frame | handling ms | solve ms | body-s per wall-s | "
      "contacts before / after reduction, patches (last frame) | fastest body m/s (free fall) | energy gain | "
      "last-second drift mm | final speed m/s | pile height mm | max penetration mm | finite |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for l in open(sys.argv[1]):
    if not l.strip():
        continue
    r = json.loads(l)
    finite = "yes" if r["finite"] else ("flagged" if r["over_loop_budget"] else "no")
    solver = r.get("pile_solver", "serial")
    near = f"{r['near_pairs']} ({r['colours']})" if "near_pairs" in r else "-"
    height = f"{r['pile_height_mm']:.0f}" if "pile_height_mm" in r else "-"
    print(f"| {r['scene']} | {solver} | {r['bodies']} x {r['worlds']} | {near} | {r['seconds']:.2f} | {r['ms_per_frame']:.0f} | "
          f"{r['handling_ms_per_frame']:.0f} | {r['solve_ms_per_frame']:.0f} | {r['body_seconds_per_wall_second']:.2f} | "
          f"{r['contacts_before']} / {r['contacts_after']}, {r['patches']} | {r['max_speed_m_s']:.2f} ({r['free_fall_speed_m_s']:.2f}) | "
          f"{r['max_energy_gain']:.1e} | {r['last_second_max_drift_mm']:.2f} | {r['final_max_speed_m_s']:.4f} | {height} | "
          f"{r['max_penetration_mm']:.2f} | {finite} |")
