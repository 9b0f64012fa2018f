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
ap.add_argument("--frames", type=int, default=200)
ap.add_argument("--scale", type=int, default=1,
                help="cells per 4-BL cell along each axis (2: 28×20 cells of 2 BL)")
ap.add_argument("--blur", type=float, default=0.0,
                help="Gaussian blur σ (cells) applied to both fields before comparing; 0 = none")
ap.add_argument("--obstacles", default=json.dumps(CROSSING_CELLS),
                help="obstacle cells as JSON [[ix, iy], …] on the 14×10 grid")
ap.add_argument("--sets", default=None,
                help="a recovery.py --out JSON: also score each run's start and fitted forces "
                     "(the truth's speed model kept), instead of the ±0.2 moves")
a = ap.parse_args()
tmp = tempfile.mkdtemp(prefix="herdfit-ident-")
cells = os.path.join(tmp, "cells.json")
json.dump({"cells": [[ix * a.scale + dx, iy * a.scale + dy] for ix, iy in json.loads(a.obstacles)
                    for dx in range(a.scale) for dy in range(a.scale)]}, open(cells, "w"))
truth = crossing_truth(a.herdfit, tmp)[1]


def synth(out, seed, params):
    subprocess.run([a.herdfit, "synth", "--agents", str(a.agents), "--frame-count", str(a.frames), "--grid-size",
                    f"{14 * a.scale}x{10 * a.scale}", "--cell-size", str(4 / a.scale), "--obstacles", cells, "--seed", str(seed), "--out", out,
                    "--params", params], check=True, capture_output=True)


points = [("truth", None, 0.0)]
if a.sets:
    rec = json.load(open(a.sets))
    for r in rec["runs"]:
        points.append((f"start{r['start']}", "set", rec["starts"][r["start"]]))
        points.append((f"fitted{r['start']}", "set", r["fitted"]))
else:
    for n in NAMES:
        f, p = n.split(".")
        for d in (-0.2, 0.2):
            if 0.001 <= truth["forces"][f][p] + d <= 1.0:
                points.append((f"{n}{d:+.1f}", (f, p), d))
jobs = []
for name, fp, d in points:
    q = json.loads(json.dumps(truth))
    if fp == "set":
        for i, n in enumerate(NAMES):
            f, p = n.split(".")
            q["forces"][f][p] = round(float(d[i]), 6)
    elif fp:
        q["forces"][fp[0]][fp[1]] = round(q["forces"][fp[0]][fp[1]] + d, 6)
    pf = os.path.join(tmp, f"{name}.json")
    json.dump(q, open(pf, "w"))
    jobs += [(os.path.join(tmp, f"{name}-s{100 + s}"), 100 + s, pf) for s in range(a.k)]
jobs += [(os.path.join(tmp, f"clip{11 + c}"), 11 + c, os.path.join(tmp, "truth.json"))
         for c in range(a.clips)]
with ThreadPoolExecutor(a.jobs) as ex:
    list(ex.map(lambda j: synth(*j), jobs))


def blur(x):
    """Separable Gaussian blur of σ = --blur cells over the two grid axes (zero outside)."""
    if a.blur <= 0:
        return x
    def mat(n):
        i = np.arange(n)
        w = np.exp(-0.5 * ((i[:, None] - i[None, :]) / a.blur) ** 2)
        return w / w.sum(1, keepdims=True)
    by, bx = mat(x.shape[1]), mat(x.shape[2])
    return np.einsum("yj,fji...->fyi...", by, np.einsum("xi,fji...->fjx...", bx, x))


def fields(d):
    z = np.load(os.path.join(d, "fields.npz"))
    r = z["density"].astype(float)
    return blur(r), blur(r[..., None] * z["velocity"].astype(float))


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
if a.sets:
    print("\n| set | mean abs error | Δ unbiased, sum over clips | ± (std of the per-clip Δ × √clips) |")
    print("|---|---:|---:|---:|")
    t = np.array(json.load(open(a.sets))["truth"])
    for name, fp, d in points[1:]:
        du = np.array([table[(c, name)][1] - table[(c, 'truth')][1] for c in range(a.clips)])
        print(f"| {name} | {np.mean(np.abs(np.array(d) - t)):.3f} | {du.sum():+.4f} | "
              f"{du.std(ddof=1) * np.sqrt(a.clips) if a.clips > 1 else float('nan'):.4f} |")
    raise SystemExit
for kind, i in (("naive", 0), ("unbiased", 1)):
    wins = []
    for c in range(a.clips):
        ok = 0
        for n in NAMES:
            moves = [nm for nm, fp, _ in points[1:] if nm.startswith(n)]
            ok += all(table[(c, m)][i] > table[(c, 'truth')][i] for m in moves)
        wins.append(ok)
    print(f"\n{kind}: parameters for which θ* beats both moves, per clip: {wins} (of 12)")
