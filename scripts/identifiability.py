#!/usr/bin/env python3
"""What one clip's fields can tell about the 12 parameters (RESULTS.md §1).

Simulates the recovery protocol's clip ("crossing": 300 agents at 2 BL/s through obstacle cells,
200 frames, 14×10 cells of 4 BL) for several realisations (seeds), and, for the truth θ* and for
each parameter moved by ±0.2, an ensemble of K re-simulations with other seeds (the same seeds
for every parameter set: common random numbers). For each clip it reports, relative to θ*:

- naive: the mean over the ensemble of the plain field loss Σ(ρ' − ρ)²/Σρ² + Σ‖m' − m‖²/Σ‖m‖²,
  what a fit that simulates one herd minimises in expectation;
- unbiased: the ensemble-mean fields against the clip minus the ensemble's spread / K, an
  estimate of ‖E ρ'(θ) − ρ‖² (+ the same for momentum), what `--loss ensemble` minimises.

A positive Δ for both moves means θ* is preferred. Uses the herdfit CLI, the standard library and
numpy.

    python3 scripts/identifiability.py [--herdfit target/release/herdfit] [--k 8] [--clips 4]
        [--jobs 2]
"""
import argparse, json, os, subprocess, tempfile
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from scenario import CROSSING_CELLS, crossing_truth

NAMES = [f"{f}.{p}" for f in ("cohesion", "avoidance", "alignment", "obstacle")
         for p in ("weight", "radial", "angular")]

ap = argparse.ArgumentParser()
ap.add_argument("--herdfit", default="target/release/herdfit")
ap.add_argument("--k", type=int, default=8, help="re-simulations per parameter set")
ap.add_argument("--clips", type=int, default=4, help="clip realisations (seeds 11, 12, …)")
ap.add_argument("--jobs", type=int, default=2)
ap.add_argument("--agents", type=int, default=300)
ap.add_argument("--obstacles", default=json.dumps(CROSSING_CELLS),
                help="obstacle cells as JSON [[ix, iy], …] on the 14×10 grid")
a = ap.parse_args()
tmp = tempfile.mkdtemp(prefix="herdfit-ident-")
cells = os.path.join(tmp, "cells.json")
json.dump({"cells": json.loads(a.obstacles)}, open(cells, "w"))
truth = crossing_truth(a.herdfit, tmp)[1]


def synth(out, seed, params):
    subprocess.run([a.herdfit, "synth", "--agents", str(a.agents), "--frames", "200", "--grid", "14x10",
                    "--cell-size", "4", "--obstacles", cells, "--seed", str(seed), "--out", out,
                    "--params", params], check=True, capture_output=True)


points = [("truth", None, 0.0)]
for n in NAMES:
    f, p = n.split(".")
    for d in (-0.2, 0.2):
        if 0.001 <= truth["forces"][f][p] + d <= 1.0:
            points.append((f"{n}{d:+.1f}", (f, p), d))
jobs = []
for name, fp, d in points:
    q = json.loads(json.dumps(truth))
    if fp:
        q["forces"][fp[0]][fp[1]] = round(q["forces"][fp[0]][fp[1]] + d, 6)
    pf = os.path.join(tmp, f"{name}.json")
    json.dump(q, open(pf, "w"))
    jobs += [(os.path.join(tmp, f"{name}-s{100 + s}"), 100 + s, pf) for s in range(a.k)]
jobs += [(os.path.join(tmp, f"clip{11 + c}"), 11 + c, os.path.join(tmp, "truth.json"))
         for c in range(a.clips)]
with ThreadPoolExecutor(a.jobs) as ex:
    list(ex.map(lambda j: synth(*j), jobs))


def fields(d):
    z = np.load(os.path.join(d, "fields.npz"))
    r = z["density"].astype(float)
    return r, r[..., None] * z["velocity"].astype(float)


ens = {}
for name, _, _ in points:
    rs, ms = zip(*(fields(os.path.join(tmp, f"{name}-s{100 + s}")) for s in range(a.k)))
    ens[name] = (np.array(rs), np.array(ms))
table = {}
for c in range(a.clips):
    r0, m0 = fields(os.path.join(tmp, f"clip{11 + c}"))
    nr, nm = (r0 ** 2).sum(), (m0 ** 2).sum()
    for name, _, _ in points:
        R, M = ens[name]
        naive = np.mean([((R[k] - r0) ** 2).sum() / nr + ((M[k] - m0) ** 2).sum() / nm
                         for k in range(a.k)])
        rb, mb = R.mean(0), M.mean(0)
        spread = (((R - rb) ** 2).sum() / nr + ((M - mb) ** 2).sum() / nm) / (a.k - 1)
        unb = ((rb - r0) ** 2).sum() / nr + ((mb - m0) ** 2).sum() / nm - spread / a.k
        table[(c, name)] = (naive, unb)
print(f"K = {a.k} re-simulations per set; clips: seeds {', '.join(str(11 + c) for c in range(a.clips))}")
print("at θ*: " + "; ".join(f"clip {11 + c}: naive {table[(c, 'truth')][0]:.3f}, unbiased "
                            f"{table[(c, 'truth')][1]:.3f}" for c in range(a.clips)))
print()
print("| move | Δ naive (mean over clips) | Δ unbiased, per clip |")
print("|---|---:|---|")
for name, fp, _ in points[1:]:
    dn = np.mean([table[(c, name)][0] - table[(c, 'truth')][0] for c in range(a.clips)])
    du = [table[(c, name)][1] - table[(c, 'truth')][1] for c in range(a.clips)]
    print(f"| {name} | {dn:+.4f} | " + " ".join(f"{x:+.4f}" for x in du) + " |")
for kind, i in (("naive", 0), ("unbiased", 1)):
    wins = []
    for c in range(a.clips):
        ok = 0
        for n in NAMES:
            moves = [nm for nm, fp, _ in points[1:] if nm.startswith(n)]
            ok += all(table[(c, m)][i] > table[(c, 'truth')][i] for m in moves)
        wins.append(ok)
    print(f"\n{kind}: parameters for which θ* beats both moves, per clip: {wins} (of 12)")
