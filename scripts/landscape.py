#!/usr/bin/env python3
"""Loss landscape around the truth (RESULTS.md): for a synthetic clip, the change of the fit's
losses E_mean and E_var (one epoch of the fit's schedule, no updates, same herd and noise) when one
parameter moves by ±0.2 from its true value. A parameter is identifiable by a loss only if both
moves raise it.

    python3 scripts/landscape.py [--herdfit target/release/herdfit] [--extra "--cell-mean"]
"""
import argparse, json, os, subprocess, tempfile

NAMES = [f"{f}.{p}" for f in ("cohesion", "avoidance", "alignment", "obstacle")
         for p in ("weight", "radial", "angular")]

ap = argparse.ArgumentParser()
ap.add_argument("--herdfit", default="target/release/herdfit")
ap.add_argument("--extra", default="")
a = ap.parse_args()
tmp = tempfile.mkdtemp(prefix="herdfit-landscape-")
clip = os.path.join(tmp, "clip")
cells = os.path.join(tmp, "cells.json")
json.dump({"cells": [[8, 4], [8, 5], [3, 8]]}, open(cells, "w"))
subprocess.run([a.herdfit, "synth", "--agents", "300", "--frames", "100", "--grid", "14x10",
                "--cell-size", "4", "--obstacles", cells, "--seed", "11", "--out", clip],
               check=True, capture_output=True)
truth = json.load(open(os.path.join(clip, "truth.json")))


def loss(p):
    init = os.path.join(tmp, "init.json")
    json.dump(p, open(init, "w"))
    out = os.path.join(tmp, "q.json")
    subprocess.run([a.herdfit, "fit", clip, "--out", out, "--init", init, "--epochs", "1",
                    "--lr", "1e-12"] + a.extra.split(), check=True, capture_output=True)
    q = json.load(open(out))["provenance"]
    return q["loss"]["start"], q["evaluation"]["start"]


base, ev = loss(truth)
print(f"truth: E_mean {base['e_mean']:.4f}, E_var {base['e_var']:.4f}, "
      f"density error {ev['density_error']:.4f}, velocity error {ev['velocity_error']:.4f}")
print("| parameter | truth | ΔE_mean (−0.2) | ΔE_mean (+0.2) | ΔE_var (−0.2) | ΔE_var (+0.2) |")
print("|---|---:|---:|---:|---:|---:|")
for n in NAMES:
    f, k = n.split(".")
    cols = []
    for d in (-0.2, 0.2):
        v = truth["forces"][f][k] + d
        if v < 0.001 or v > 1.0:
            cols.append(None)
            continue
        p = json.loads(json.dumps(truth))
        p["forces"][f][k] = round(v, 6)
        cols.append(loss(p)[0])
    fmt = lambda c, key: "—" if c is None else f"{c[key] - base[key]:+.4f}"
    print(f"| {n} | {truth['forces'][f][k]} | {fmt(cols[0], 'e_mean')} | {fmt(cols[1], 'e_mean')} | "
          f"{fmt(cols[0], 'e_var')} | {fmt(cols[1], 'e_var')} |")
