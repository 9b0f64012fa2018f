#!/usr/bin/env python3
"""Loss landscape around the truth (RESULTS.md): for a synthetic clip, the change of the fit's
losses E_mean and E_var (one epoch of the fit's schedule, no updates, same herd and noise) when one
parameter moves by ±0.2 from its true value. A parameter is identifiable by a loss only if both
moves raise it.

    python3 scripts/landscape.py [--herdfit target/release/herdfit] [--scenario crossing|drift]
        [--key e_mean,e_var|e_fields] [--extra "--loss ensemble --replicas 16"]
"""
import argparse, json, os, subprocess, tempfile

from scenario import CROSSING_CELLS, DRIFT_CELLS, crossing_truth

NAMES = [f"{f}.{p}" for f in ("cohesion", "avoidance", "alignment", "obstacle")
         for p in ("weight", "radial", "angular")]

ap = argparse.ArgumentParser()
ap.add_argument("--herdfit", default="target/release/herdfit")
ap.add_argument("--extra", default="")
ap.add_argument("--scenario", choices=["crossing", "drift"], default="crossing",
                help="the clip of scripts/recovery.py")
ap.add_argument("--key", default="e_mean,e_var",
                help="logged losses to report (e_mean, e_var, e_fields)")
a = ap.parse_args()
keys = a.key.split(",")
tmp = tempfile.mkdtemp(prefix="herdfit-landscape-")
clip = os.path.join(tmp, "clip")
cells = os.path.join(tmp, "cells.json")
crossing = a.scenario == "crossing"
json.dump({"cells": CROSSING_CELLS if crossing else DRIFT_CELLS}, open(cells, "w"))
cmd = [a.herdfit, "synth", "--agents", "300", "--frame-count", "200" if crossing else "100",
       "--grid-size", "14x10", "--cell-size", "4", "--obstacles", cells, "--seed", "11", "--out", clip]
if crossing:
    cmd += ["--params", crossing_truth(a.herdfit, tmp)[0]]
subprocess.run(cmd, check=True, capture_output=True)
truth = json.load(open(os.path.join(clip, "truth.json")))


def loss(p):
    init = os.path.join(tmp, "init.json")
    json.dump(p, open(init, "w"))
    out = os.path.join(tmp, "q.json")
    subprocess.run([a.herdfit, "fit", clip, "--out", out, "--start", init, "--epochs", "1",
                    "--lr", "1e-12"] + a.extra.split(), check=True, capture_output=True)
    q = json.load(open(out))["provenance"]
    return q["loss"]["start"], q["evaluation"]["start"]


base, ev = loss(truth)
print(f"truth: " + ", ".join(f"{k} {base[k]:.4f}" for k in keys) +
      f", density error {ev['density_error']:.4f}, velocity error {ev['velocity_error']:.4f}")
print("| parameter | truth | " + " | ".join(f"Δ{k} (−0.2) | Δ{k} (+0.2)" for k in keys) + " |")
print("|---|---:|" + "---:|---:|" * len(keys))
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
    print(f"| {n} | {truth['forces'][f][k]} | " +
          " | ".join(f"{fmt(cols[0], key)} | {fmt(cols[1], key)}" for key in keys) + " |", flush=True)
