#!/usr/bin/env python3
"""Ground-truth recovery by the track objective (issue #49; the protocol of RESULTS §6 with
`fit --objective tracks`): the crossing clip of scripts/recovery.py (300 agents at 2 BL/s through
obstacle cells, 200 frames at 25 fps = 8 s, 14×10 cells of 4 BL, seed 11), fitted from its
trajectories from recovery.py's random starts (rng 2026, uniform 0.05–0.95), each with the
identifiability estimate. Reports, per run and over the runs:

- the parameters the estimate calls determined and their errors |θ − θ*| (target ≤ 0.06 each, at
  least 6 of 12 determined);
- coverage: θ* within 2 reported std (within the one-sided interval for a parameter at a bound) in
  every parameter × run case (target ≥ 90 %);
- behaviour: the fields of the fitted forces against θ*'s with common random numbers (`synth`
  with θ*'s speed model, herd and seed; Σ(ρ' − ρ)²/Σρ² + Σ‖m' − m‖²/Σ‖m‖² over every cell and
  frame, m = ρV), mean ± sd over --behaviour-seeds seeds, beside θ* moved by ±0.06 per parameter
  (random signs, rng 17, --moves draws): "as close as θ* ± 0.06" when a fit's mean is at most
  the moves' mean.

    python3 scripts/track-recovery.py [--herdfit target/release/herdfit] [--starts 5]
        [--extra "--epochs 16"] [--jobs 2] [--behaviour-seeds 16] [--moves 4] [--out rec.json]
        [--work DIR [--reuse]]

--reuse keeps the clip and the fits already in --work (a run cut short goes on where it stopped;
their wall times are then unknown and printed as "–").
"""
import argparse, json, os, random, subprocess, sys, tempfile, time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from recovery import NAMES, vec, with_vec
from scenario import CROSSING_CELLS, crossing_truth


def fmt_wall(w):
    return "–" if w is None else f"{w:.0f}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--starts", type=int, default=5)
    ap.add_argument("--extra", default="", help="more flags for fit --objective tracks")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--behaviour-seeds", type=int, default=16)
    ap.add_argument("--moves", type=int, default=4, help="draws of θ* ± 0.06")
    ap.add_argument("--work", default="")
    ap.add_argument("--reuse", action="store_true",
                    help="keep the clip and fit<k>.json already in --work")
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    tmp = a.work or tempfile.mkdtemp(prefix="herdfit-track-recovery-")
    os.makedirs(tmp, exist_ok=True)
    cells = os.path.join(tmp, "cells.json")
    json.dump({"cells": CROSSING_CELLS}, open(cells, "w"))
    truth_in, truth = crossing_truth(a.herdfit, tmp)
    clip = os.path.join(tmp, "clip")

    def synth(out, seed, params):
        cmd = [a.herdfit, "synth", "--agents", "300", "--frame-count", "200", "--grid-size",
               "14x10", "--cell-size", "4", "--obstacles", cells, "--params", params,
               "--seed", str(seed), "--out", out]
        print("$ " + " ".join(cmd), file=sys.stderr)
        subprocess.run(cmd, check=True, capture_output=True)

    if not (a.reuse and os.path.isfile(os.path.join(clip, "trajectories.csv"))):
        synth(clip, 11, truth_in)
    t = vec(truth)
    rng = random.Random(2026)
    starts = [[round(rng.uniform(0.05, 0.95), 4) for _ in NAMES] for _ in range(a.starts)]
    for k, s in enumerate(starts):
        json.dump(with_vec(truth, s), open(os.path.join(tmp, f"init{k}.json"), "w"))

    def fit(k):
        out = os.path.join(tmp, f"fit{k}.json")
        # synth's herds are made with the leader rule (§5.1): the fit models it.
        cmd = [a.herdfit, "fit", clip, "--objective", "tracks", "--leaders", "field", "--out",
               out, "--start", os.path.join(tmp, f"init{k}.json"), "--seed", str(k)] + a.extra.split()
        print("$ " + " ".join(cmd), file=sys.stderr)
        if a.reuse and os.path.isfile(out):
            print(f"  (reused {out})", file=sys.stderr)
            wall, stdout = None, ""
        else:
            t0 = time.time()
            stdout = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
            wall = time.time() - t0
        f = json.load(open(out))
        u = f["uncertainty"]
        params = []
        for i, n in enumerate(NAMES):
            err = vec(f)[i] - t[i]
            b, sd = u["bounds"].get(n), u["std"][n]
            if b is not None:
                covered = b["within"][0] - 1e-12 <= t[i] <= b["within"][1] + 1e-12
            else:
                covered = sd is not None and abs(err) <= 2 * sd
            params.append({"name": n, "error": err, "std": sd, "bound": b,
                           "determined": n in u["determined"], "covered": covered})
        det = [q for q in params if q["determined"]]
        print(f"run {k}: {fmt_wall(wall)} s, mean |θ−θ*| {np.mean(np.abs(np.array(starts[k]) - t)):.3f} → "
              f"{np.mean([abs(q['error']) for q in params]):.3f}; determined "
              f"{[(q['name'], round(q['error'], 3)) for q in det]}; covered "
              f"{sum(q['covered'] for q in params)}/12", file=sys.stderr)
        return {"start": k, "wall_s": wall, "fitted": vec(f), "params": params,
                "objective": f["provenance"]["objective_value"], "stdout": stdout}

    with ThreadPoolExecutor(a.jobs) as ex:
        runs = list(ex.map(fit, range(a.starts)))

    # Behaviour: common random numbers against θ*'s clip, seed by seed.
    mv = random.Random(17)
    moves = []
    for _ in range(a.moves):
        moves.append([min(1.0, max(0.001, x + (0.06 if mv.random() < 0.5 else -0.06))) for x in t])
    sets = [("truth", t)] + [(f"fit{r['start']}", r["fitted"]) for r in runs] + \
           [(f"move{j}", m) for j, m in enumerate(moves)]
    seeds = [100 + s for s in range(a.behaviour_seeds)]
    jobs = []
    for name, v in sets:
        pf = os.path.join(tmp, f"b-{name}.json")
        json.dump(with_vec(truth, v), open(pf, "w"))
        jobs += [(os.path.join(tmp, f"b-{name}-s{s}"), s, pf) for s in seeds]
    with ThreadPoolExecutor(a.jobs) as ex:
        list(ex.map(lambda j: synth(*j), jobs))

    def fields(d):
        z = np.load(os.path.join(d, "fields.npz"))
        r = z["density"].astype(float)
        return r, r[..., None] * z["velocity"].astype(float)

    base = {s: fields(os.path.join(tmp, f"b-truth-s{s}")) for s in seeds}
    dist = {}
    for name, _ in sets[1:]:
        d = []
        for s in seeds:
            r0, m0 = base[s]
            r, m = fields(os.path.join(tmp, f"b-{name}-s{s}"))
            d.append(((r - r0) ** 2).sum() / (r0 ** 2).sum() + ((m - m0) ** 2).sum() / (m0 ** 2).sum())
        dist[name] = (float(np.mean(d)), float(np.std(d, ddof=1)))
    move_mean = float(np.mean([dist[f"move{j}"][0] for j in range(a.moves)]))

    cases = [q for r in runs for q in r["params"]]
    det = [q for q in cases if q["determined"]]
    summary = {
        "truth": t, "starts": starts, "runs": runs, "behaviour": dist,
        "behaviour_moves_mean": move_mean,
        "coverage": sum(q["covered"] for q in cases) / len(cases),
        "determined_per_run": [sum(q["determined"] for q in r["params"]) for r in runs],
        "determined_max_error": max((abs(q["error"]) for q in det), default=None),
        "settings": vars(a),
    }
    if a.out:
        json.dump(summary, open(a.out, "w"), indent=1)
    print("| run | mean abs error start → fitted | determined (error) | θ* within 2 std | behaviour distance | wall s |")
    print("|---:|---|---|---:|---:|---:|")
    for r in runs:
        d = [q for q in r["params"] if q["determined"]]
        e0 = np.mean(np.abs(np.array(starts[r["start"]]) - t))
        e1 = np.mean([abs(q["error"]) for q in r["params"]])
        b = dist[f"fit{r['start']}"]
        print(f"| {r['start']} | {e0:.3f} → {e1:.3f} | {len(d)}: " +
              ", ".join(f"{q['name']} ({q['error']:+.3f})" for q in d) +
              f" | {sum(q['covered'] for q in r['params'])}/12 | {b[0]:.4f} ± {b[1]:.4f} | {fmt_wall(r['wall_s'])} |")
    print(f"\nθ* ± 0.06 ({a.moves} draws): " + ", ".join(
        f"{dist[f'move{j}'][0]:.4f} ± {dist[f'move{j}'][1]:.4f}" for j in range(a.moves)) +
        f"; mean {move_mean:.4f}")
    print(f"coverage {summary['coverage']:.3f} of {len(cases)} parameter × run cases; "
          f"determined per run {summary['determined_per_run']}; largest error of a determined "
          f"parameter {summary['determined_max_error']}")
    print(f"work folder: {tmp}")


if __name__ == "__main__":
    main()
