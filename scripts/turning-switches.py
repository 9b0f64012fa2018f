#!/usr/bin/env python3
"""Where the imitation's turning-rate gap comes from (issue #20): the herd model's role switches.

herdfit's herd model makes an agent a leader when at most `leader_max_neighbours` neighbours
are in its front cone; a leader takes the guidance direction, so a follower that becomes a
leader (or the reverse) turns sharply in one frame. The learnt crowd agents have no roles. This
script makes a set of sources (`herdfit simulate --agents 100 --steps 120 --guidance 1,0 --seed
S`, S = F..F+8), learns from the first three (`crowd learn --config C`), imitates the other six
(`crowd simulate --entries srcS.csv --no-goals --seed S+offset`, offsets 0 and 100) and prints
the turning-rate 1-Wasserstein distance between each source and its imitation, with every turn
counted and with the source's turns at a role switch (the role differs among the three frames
of the turn) left out; the sources' own spread (mean over their 36 pairs) both ways for scale.

Turning rates as `herdfit crowd compare` computes them (`crowd::measure`): |angle
between consecutive steps| / dt, both steps faster than 0.05 units/s; W1 exactly, from the
empirical distributions.

    python3 scripts/turning-switches.py --herdfit target/release/herdfit [--first-seed 200]
        [--config '{"action":{"k":20},"max_samples":40000,"features":{"weights":{"alignment":100}}}']
"""

import argparse
import collections
import csv
import itertools
import math
import os
import subprocess
import sys
import tempfile

STILL = 0.05


def run(herdfit, *args):
    r = subprocess.run([herdfit, *args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"herdfit {' '.join(args)}: {r.stderr.strip()}")


def turns(path):
    """(turning rate, whether the source's role changed during the turn) of every turn."""
    tracks = collections.defaultdict(list)
    times = {}
    with open(path) as f:
        for r in csv.DictReader(f):
            fr = int(r["frame"])
            times[fr] = float(r["time"])
            tracks[r["id"]].append((fr, float(r["x"]), float(r["y"]), r.get("role", "")))
    frames = sorted(times)
    dt = times[frames[1]] - times[frames[0]]
    out = []
    for v in tracks.values():
        v.sort()
        for j in range(2, len(v)):
            e = (v[j - 1][1] - v[j - 2][1], v[j - 1][2] - v[j - 2][2])
            d = (v[j][1] - v[j - 1][1], v[j][2] - v[j - 1][2])
            if math.hypot(*d) > STILL * dt and math.hypot(*e) > STILL * dt:
                a = math.atan2(e[0] * d[1] - e[1] * d[0], e[0] * d[0] + e[1] * d[1])
                out.append((abs(a) / dt, len({v[j - 2][3], v[j - 1][3], v[j][3]}) > 1))
    return out


def w1(a, b):
    """Exact 1-Wasserstein distance of two empirical distributions (∫ |F_a − F_b|)."""
    a, b = sorted(a), sorted(b)
    pts = sorted(set(a) | set(b))
    i = j = 0
    w = 0.0
    for x, nxt in zip(pts, pts[1:]):
        while i < len(a) and a[i] <= x:
            i += 1
        while j < len(b) and b[j] <= x:
            j += 1
        w += abs(i / len(a) - j / len(b)) * (nxt - x)
    return w


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--first-seed", type=int, default=200)
    ap.add_argument("--config", default='{"action":{"k":20},"max_samples":40000,'
                    '"features":{"weights":{"alignment":100}}}')
    a = ap.parse_args()
    seeds = [a.first_seed + s for s in range(9)]
    with tempfile.TemporaryDirectory() as tmp:
        src = {}
        for s in seeds:
            p = os.path.join(tmp, f"src{s}.csv")
            run(a.herdfit, "simulate", "--agents", "100", "--steps", "120", "--guidance", "1,0",
                "--seed", str(s), "--out", p)
            src[s] = turns(p)
        cfg = os.path.join(tmp, "learn.json")
        with open(cfg, "w") as f:
            f.write(a.config)
        model = os.path.join(tmp, "m.json")
        run(a.herdfit, "crowd", "learn", *[os.path.join(tmp, f"src{s}.csv") for s in seeds[:3]],
            "--config", cfg, "--out", model)
        every = lambda t: [x for x, _ in t]
        kept = lambda t: [x for x, sw in t if not sw]
        pairs = list(itertools.combinations(seeds, 2))
        spread = [sum(w1(f(src[i]), f(src[j])) for i, j in pairs) / len(pairs)
                  for f in (every, kept)]
        full, drop, share = [], [], []
        for s in seeds[3:]:
            for off in (0, 100):
                out = os.path.join(tmp, f"im{s}-{off}.csv")
                run(a.herdfit, "crowd", "simulate", model, "--entries",
                    os.path.join(tmp, f"src{s}.csv"), "--no-goals", "--seed", str(s + off),
                    "--out", out)
                im = every(turns(out))
                full.append(w1(every(src[s]), im))
                drop.append(w1(kept(src[s]), im))
            share.append(sum(sw for _, sw in src[s]) / len(src[s]))
        mean = lambda v: sum(v) / len(v)
        print(f"sources {seeds[0]}-{seeds[-1]}, learnt from {seeds[0]}-{seeds[2]} with {a.config}")
        print(f"source turns at a role switch: {100 * mean(share):.1f} % "
              f"({100 * min(share):.1f}-{100 * max(share):.1f} %)")
        print("| turns of the source | sources' spread (36 pairs) | imitation W1 (12 runs) "
              "| ratio to 2x spread |")
        print("|---|---:|---:|---:|")
        for name, sp, v in (("all", spread[0], full), ("role switches left out", spread[1], drop)):
            print(f"| {name} | {sp:.4f} | {mean(v):.4f} | {mean(v) / (2 * sp):.2f}x |")


if __name__ == "__main__":
    main()
