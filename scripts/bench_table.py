#!/usr/bin/env python3
"""Markdown table from `factory-bench contacts --json` lines (scripts/bench_contacts.sh output)."""
import json, sys

rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
print("| pair | worlds | query tris | SDF tris | candidates/pair | contacts/pair (max) | patches/pair | handling ms/frame (GPU: lavapipe) | CPU twin ms/frame | ms per pair (GPU) | GPU/CPU time |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for r in rows:
    name = r["pair"]
    if "/" in name:
        name = "Factory's " + ("M16 tight nut-bolt" if "bolt" in name else "4 mm tight peg-hole") + " meshes"
    if r.get("sdf") == "analytic":
        name += " (analytic bolt SDF)"
    cpu = r.get("cpu_twin_ms_per_frame")
    ratio = f"{r['handling_ms_per_frame'] / cpu:.2f}" if cpu else "-"
    cpu_s = f"{cpu:.1f}" if cpu else "-"
    print(f"| {name} | {r['worlds']} | {r['query_triangles']} | {r['sdf_triangles']} | {r['candidates_per_pair']:.0f} | "
          f"{r['contacts_per_pair']:.0f} ({r['max_contacts_per_pair']}) | {r['patches_per_pair']:.1f} | "
          f"{r['handling_ms_per_frame']:.1f} | {cpu_s} | {r['handling_ms_per_frame'] / r['worlds']:.2f} | {ratio} |")
