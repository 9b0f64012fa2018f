#!/usr/bin/env python3
"""Checks the identifiability report against ground truth (issue #15 item 2, "Recovery where the
data can tell"): simulates a synthetic clip of scripts/recovery.py's protocols, fits it from random
starts (and, with --truth-start, from θ* itself) with the uncertainty estimate on, and reports per
run which parameters and directions the report calls determined, |θ − θ*| for them, and whether θ*
lies within 2 std (within the one-sided interval for a parameter at a bound). Uses only the
herdfit CLI and the Python standard library.

    python3 scripts/identify_check.py [--herdfit target/release/herdfit] [--scenario crossing]
        [--agents 300] [--starts 3] [--truth-start] [--extra "--epochs 8"] [--out check.json]
"""
import argparse, json, os, random, subprocess, sys, tempfile, time

from recovery import NAMES, vec, with_vec
from scenario import CORRIDOR_CELLS, CROSSING_CELLS, DRIFT_CELLS, crossing_truth


def make_clip(a, tmp):
    cells = os.path.join(tmp, "cells.json")
    sq = {"drift": DRIFT_CELLS, "crossing": CROSSING_CELLS, "corridor": CORRIDOR_CELLS}[a.scenario]
    with open(cells, "w") as f:
        json.dump({"cells": sq}, f)
    clip = os.path.join(tmp, "clip")
    cmd = [a.herdfit, "synth", "--agents", str(a.agents), "--frame-count", str(a.frames),
           "--grid-size", "14x10", "--cell-size", "4", "--obstacles", cells, "--seed", "11",
           "--out", clip]
    if a.scenario != "drift":
        cmd += ["--params", crossing_truth(a.herdfit, tmp)[0]]
    subprocess.run(cmd, check=True, capture_output=True)
    return clip


def judge(fitted, truth):
    """Per parameter and per direction: determined, error, θ* within 2 std (or the interval)."""
    u = fitted["uncertainty"]
    theta = vec(fitted)
    params = []
    for i, n in enumerate(NAMES):
        err = theta[i] - truth[i]
        b = u["bounds"].get(n)
        sd = u["std"][n]
        if b is not None:
            covered = b["within"][0] - 1e-12 <= truth[i] <= b["within"][1] + 1e-12
        else:
            covered = abs(err) <= 2 * sd
        params.append({"name": n, "value": theta[i], "truth": truth[i], "error": err,
                       "std": sd, "bound": b, "determined": n in u["determined"],
                       "covered": covered})
    dirs = []
    for d in u["directions"]:
        proj = sum(d["vector"][n] * (theta[i] - truth[i]) for i, n in enumerate(NAMES))
        dirs.append({"eigenvalue": d["eigenvalue"], "std": d["std"], "determined": d["determined"],
                     "projected_error": proj,
                     "covered": d["std"] is not None and abs(proj) <= 2 * d["std"]})
    return params, dirs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--scenario", choices=["crossing", "drift", "corridor"], default="crossing")
    ap.add_argument("--agents", type=int, default=300)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--starts", type=int, default=3)
    ap.add_argument("--truth-start", action="store_true", help="also fit from θ* itself")
    ap.add_argument("--extra", default="")
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="herdfit-identify-")
    clip = make_clip(a, tmp)
    truth_params = json.load(open(os.path.join(clip, "truth.json")))
    truth = vec(truth_params)
    rng = random.Random(2026)  # the starts of scripts/recovery.py
    starts = [[round(rng.uniform(0.05, 0.95), 4) for _ in NAMES] for _ in range(a.starts)]
    if a.truth_start:
        starts.append(truth)
    runs = []
    for k, s in enumerate(starts):
        init = os.path.join(tmp, f"init{k}.json")
        with open(init, "w") as f:
            json.dump(with_vec(truth_params, s), f)
        out = os.path.join(tmp, f"fit{k}.json")
        t0 = time.time()
        p = subprocess.run([a.herdfit, "fit", clip, "--out", out, "--start", init,
                            "--seed", str(k)] + a.extra.split(),
                           check=True, capture_output=True, text=True)
        wall = time.time() - t0
        fitted = json.load(open(out))
        params, dirs = judge(fitted, truth)
        det = [q for q in params if q["determined"]]
        print(f"run {k} ({'θ*' if s is truth else 'random'} start, {wall:.0f} s): "
              f"mean |θ−θ*| {sum(abs(q['error']) for q in params) / 12:.3f}; determined "
              f"{[q['name'] for q in det]}; covered {sum(q['covered'] for q in params)}/12; "
              f"determined directions {sum(d['determined'] for d in dirs)}", file=sys.stderr)
        runs.append({"start": s, "truth_start": s is truth, "wall_s": wall, "params": params,
                     "directions": dirs, "stdout": p.stdout})
    cases = [q for r in runs for q in r["params"]]
    free = [q for q in cases if q["bound"] is None]
    det = [q for q in cases if q["determined"]]
    ddet = [d for r in runs for d in r["directions"] if d["determined"]]
    summary = {
        "runs": len(runs),
        "coverage_all": sum(q["covered"] for q in cases) / len(cases),
        "coverage_free": sum(q["covered"] for q in free) / max(len(free), 1),
        "cases": len(cases), "free_cases": len(free),
        "at_bound_cases": len(cases) - len(free),
        "determined_params": [(q["name"], round(q["error"], 4), q["std"]) for q in det],
        "determined_mean_abs_error": (sum(abs(q["error"]) for q in det) / len(det)) if det else None,
        "determined_directions": [(round(d["projected_error"], 4), d["std"]) for d in ddet],
        "direction_coverage": (sum(d["covered"] for r in runs for d in r["directions"] if d["std"] is not None)
                               / max(1, sum(1 for r in runs for d in r["directions"] if d["std"] is not None))),
    }
    print(json.dumps(summary, indent=1))
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"settings": vars(a), "truth": truth, "runs": runs, "summary": summary}, f, indent=1)


if __name__ == "__main__":
    main()
