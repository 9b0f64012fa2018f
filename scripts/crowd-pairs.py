#!/usr/bin/env python3
"""Walking pairs of a real ETH/UCY scene's second part and how far apart the simulation keeps them.

A real pair: two people within 0.8 m of each other in at least 15 frames of the second part (the
frames from a `crowd holdout` report's `split_frame` on). A detected pair: two entries that
`crowd simulate` groups (enter and are last seen within 1 m and 2 frames of each other; groups
are formed around their first member, so this counts pairs, an upper bound). Prints the median of
each pair's median distance, real and simulated.

    herdfit crowd holdout $D/students001.txt --out sim.csv --json report.json
    python3 scripts/crowd-pairs.py $D/students001.txt sim.csv report.json
"""
import collections
import csv
import json
import sys

import numpy as np


def tracks(path, split):
    a = np.loadtxt(path)
    step = np.median(np.diff(np.unique(a[:, 0])))
    out = collections.defaultdict(dict)
    for f, i, x, y in a:
        k = int(round(f / step))
        if k >= split:
            out[int(i)][k - split] = (x, y)
    return out


def simulated(path):
    out = collections.defaultdict(dict)
    for r in csv.DictReader(open(path)):
        out[int(r["id"])][int(r["frame"])] = (float(r["x"]), float(r["y"]))
    return out


def distances(tr):
    by_frame = collections.defaultdict(list)
    for i, d in tr.items():
        for f, p in d.items():
            by_frame[f].append((i, p))
    dist = collections.defaultdict(list)
    for here in by_frame.values():
        for a in range(len(here)):
            for b in range(a + 1, len(here)):
                (i, p), (j, q) = here[a], here[b]
                dist[(min(i, j), max(i, j))].append(np.hypot(p[0] - q[0], p[1] - q[1]))
    return dist


def detected(tr, metres=1.0, frames=2):
    e = [(i, min(d), d[min(d)], max(d), d[max(d)]) for i, d in tr.items()]
    out = set()
    for a in range(len(e)):
        for b in range(a + 1, len(e)):
            i, s0, p0, e0, q0 = e[a]
            j, s1, p1, e1, q1 = e[b]
            if (abs(s0 - s1) <= frames and abs(e0 - e1) <= frames
                    and np.hypot(p0[0] - p1[0], p0[1] - p1[1]) <= metres
                    and np.hypot(q0[0] - q1[0], q0[1] - q1[1]) <= metres):
                out.add((min(i, j), max(i, j)))
    return out


def main():
    scene, sim_csv, report = sys.argv[1:4]
    real = tracks(scene, json.load(open(report))["split_frame"])
    r, s = distances(real), distances(simulated(sim_csv))
    pairs = {k for k, v in r.items() if sum(np.array(v) < 0.8) >= 15}
    found = detected(real)

    def line(name, keys):
        keys = [k for k in keys if k in r and k in s]
        if not keys:
            print(f"{name}: none")
            return
        med = lambda d: np.median([np.median(d[k]) for k in keys])
        print(f"{name}: {len(keys)}, median distance real {med(r):.2f} m, simulated {med(s):.2f} m")

    print(f"real pairs {len(pairs)}; detected pairs {len(found)}, of them real pairs {len(found & pairs)}")
    line("real pairs", pairs)
    line("detected pairs", found)
    line("real pairs not detected", pairs - found)


if __name__ == "__main__":
    main()
