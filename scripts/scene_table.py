#!/usr/bin/env python3
"""Markdown table from `factory-bench scene ... --json` lines (scripts/bench_scene.sh output)."""
import json, sys

print("| bolt SDF | worlds | mu | simulated s | ms/frame (contacts + solver) | handling ms | solve ms | pair-s per wall-s | nut descent mm (turns) | frictionless analytic mm | max penetration mm | finite |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for l in open(sys.argv[1]):
    if not l.strip():
        continue
    r = json.loads(l)
    analytic = f"{r['analytic_descent_mm']:.4f}" if r["mu"] == 0 else "-"
    print(f"| {r['sdf']} | {r['worlds']} | {r['mu']} | {r['seconds']:.2f} | {r['ms_per_frame']:.1f} | "
          f"{r.get('handling_ms_per_frame', float('nan')):.1f} | {r.get('solve_ms_per_frame', float('nan')):.1f} | "
          f"{r['pair_seconds_per_wall_second']:.2f} | {r['nut_descent_mm']:.4f} ({r['nut_turns']:.3f}) | {analytic} | "
          f"{r['max_penetration_mm']:.4f} | {r['finite']} |")
