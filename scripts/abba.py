#!/usr/bin/env python3
"""Times two polymap builds against each other on a noisy machine: ABBA.

Each round runs `polymap bench SEQ --backend cpu --json` four times, in the order old,
new, new, old, so that a drift of the machine during a round weighs on both builds alike,
and takes new/old of each stage's median (the two runs of each build summed). Prints the
median of those ratios over the rounds, per stage. Stages the change did not touch show
how far the machine moved: a ratio is news only beyond their spread.

    scripts/abba.py OLD_POLYMAP NEW_POLYMAP mock_frames/straight_320 [--frames 300]
        [--threads 1] [--rounds 4]
"""

import argparse
import json
import statistics
import subprocess

STAGES = ["diffusion", "normals", "edges", "regions", "contours", "ransac", "polygons", "total"]


def stage_medians(polymap, args):
    out = subprocess.run(
        [polymap, "bench", args.sequence, "--backend", "cpu", "--frames", str(args.frames),
         "--threads", str(args.threads), "--json"],
        capture_output=True, text=True, check=True,
    ).stdout
    stages = json.loads(out)["stages_ms"]
    return {s: stages[s]["median"] for s in STAGES}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("old")
    p.add_argument("new")
    p.add_argument("sequence")
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=4)
    args = p.parse_args()
    ratios = {s: [] for s in STAGES}
    totals = {"old": [], "new": []}
    for _ in range(args.rounds):
        old_a, new_a, new_b, old_b = (stage_medians(b, args) for b in (args.old, args.new, args.new, args.old))
        for s in STAGES:
            ratios[s].append((new_a[s] + new_b[s]) / (old_a[s] + old_b[s]))
        totals["old"] += [old_a["total"], old_b["total"]]
        totals["new"] += [new_a["total"], new_b["total"]]
    print(f"{args.sequence}, {args.threads} threads, {args.rounds} rounds of old new new old, "
          f"{args.frames} frames a run: new/old, the median over rounds")
    for s in STAGES:
        print(f"{s:>10} {statistics.median(ratios[s]):.3f}  (rounds {min(ratios[s]):.3f} to {max(ratios[s]):.3f})")
    print(f"fastest total: old {min(totals['old']):.3f} ms, new {min(totals['new']):.3f} ms")


if __name__ == "__main__":
    main()
