#!/usr/bin/env python3
"""Issue #15: can the held-out half of a real clip tell parameter sets apart at all?

For each clip (made by `scripts/real-clips.py --make` in the same --work folder), N parameter
sets drawn uniformly in [0.05, 0.95]^12 plus the generic (all 0.5) and the disordered (no
cohesion, no alignment, the strongest avoidance) sets are validated on the held-out half with 2K
seeds (`herdfit validate --seeds 2K`). The report's per-seed errors (`seed_errors`) are split
into two disjoint groups of K seeds, A = seeds 0..K-1 and B = seeds K..2K-1; for the density
error, the velocity error and the sum of the four emergent-measure errors (Σ 4):

- the between-set spread of the sets' true errors, sqrt(cov(A, B)) over the sets (0 when the
  covariance is negative), against the noise of one K-seed mean, sqrt(var(A - B) / 2);
- the rank correlation of A and B over the sets: how well K seeds reproduce the ranking;
- with --train, each set also run freely on the first half (a copy of the clip cut to its first
  half, validated on that copy's second half, K seeds), and the rank correlation of that
  training-half score with the held-out one: whether choosing a set by how it runs on the
  training frames would pick a better set for the held-out ones.

Prints one Markdown table; --out writes every number as JSON. Needs numpy for --train only.

    python3 scripts/real-clip-noise.py --work /tmp/rc [--clips fish,students,testA] [--sets 30]
        [--seeds 16] [--constants fish:leader_max_neighbours=0] [--train]
        [--validate-extra "--horizon 8" --tag=-h8] [--out noise.json]
"""
import argparse
import importlib.util
import json
import os
import random
import statistics
import sys

GROUPS = {"density": [0], "velocity": [1], "sum4": [2, 3, 4, 5]}
NAMES = [f"{g}.{k}" for g in ("cohesion", "avoidance", "alignment", "obstacle")
         for k in ("weight", "radial", "angular")]


def _real_clips():
    """scripts/real-clips.py as a module: its command runner and its baseline sets."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "real-clips.py")
    spec = importlib.util.spec_from_file_location("real_clips", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


RC = _real_clips()
run = RC.run


def per_seed(h, clip, params, out, seeds, extra=()):
    """The per-seed [density, velocity, Σ 4] errors of one set on the clip's held-out half."""
    run([h, "validate", clip, "--params", params, "--split", "0.5", "--seeds", str(seeds),
         "--no-video", "--out", out] + list(extra))
    rows = json.load(open(f"{out}/report.json"))["sets"][0]["seed_errors"]
    return [[sum(r[i] for i in idx) for idx in GROUPS.values()] for r in rows]


def ranks(x):
    order = sorted(range(len(x)), key=lambda i: x[i])
    r = [0] * len(x)
    for j, i in enumerate(order):
        r[i] = j
    return r


def spearman(a, b):
    return statistics.correlation(ranks(a), ranks(b))


def train_half(clip, out):
    """A copy of `clip` cut to its first half (fields.npz and clip.json)."""
    import numpy as np
    meta = json.load(open(f"{clip}/clip.json"))
    half = meta["frames"] // 2
    z = np.load(f"{clip}/fields.npz")
    arrays = {k: (z[k][:half] if k != "obstacles" else z[k]) for k in z.files}
    os.makedirs(out, exist_ok=True)
    np.savez(f"{out}/fields.npz", **arrays)
    meta["frames"] = half
    json.dump(meta, open(f"{out}/clip.json", "w"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--work", default="/tmp/herdfit-real-clips")
    ap.add_argument("--clips", default="fish,students,testA")
    ap.add_argument("--sets", type=int, default=30)
    ap.add_argument("--seeds", type=int, default=16, help="2K: split into two groups of K")
    ap.add_argument("--constants", default="",
                    help="clip:k=v,… model constants of every set of a clip, ';' between clips")
    ap.add_argument("--train", action="store_true")
    ap.add_argument("--validate-extra", default="",
                    help="flags added to every validate, e.g. '--horizon 8'")
    ap.add_argument("--tag", default="", help="suffix of the working folders")
    ap.add_argument("--rng", type=int, default=7)
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    if a.seeds < 4 or a.seeds % 2:
        sys.exit("error: --seeds must be even and at least 4")
    h, w, k = os.path.abspath(a.herdfit), a.work, a.seeds // 2
    consts = {}
    for part in filter(None, a.constants.split(";")):
        c, kvs = part.split(":", 1)
        consts[c] = kvs
    res = {"sets": a.sets, "seeds": a.seeds, "constants": consts,
           "validate_extra": a.validate_extra, "clips": {}}
    for c in a.clips.split(","):
        clip, wd = f"{w}/{c}", f"{w}/noise-{c}{a.tag}"
        extra = a.validate_extra.split()
        os.makedirs(wd, exist_ok=True)
        run([h, "fit", clip, "--frames", "0..5", "--epochs", "1", "--eval-seeds", "1",
             "--no-uncertainty", "--out", f"{wd}/template.json"])
        # The generic and disordered sets of real-clips.py, with this clip's constants.
        RC.baselines(wd, f"{wd}/template.json", consts.get(c, ""))
        base = {b: json.load(open(f"{wd}/{b}.json")) for b in ("generic", "disordered")}
        tmpl = base["generic"]
        rng = random.Random(a.rng)
        sets = {b: [p["forces"][n.split(".")[0]][n.split(".")[1]] for n in NAMES]
                for b, p in base.items()}
        for i in range(a.sets):
            sets[f"random{i}"] = [rng.uniform(0.05, 0.95) for _ in range(12)]
        if a.train:
            train_half(clip, f"{wd}/train")
        rows = {}
        for name, vec in sets.items():
            p = json.loads(json.dumps(tmpl))
            for n, x in zip(NAMES, vec):
                g, key = n.split(".")
                p["forces"][g][key] = x
            path = f"{wd}/{name}.json"
            json.dump(p, open(path, "w"), indent=1)
            seeds = per_seed(h, clip, path, f"{wd}/val-{name}", a.seeds, extra)
            r = {"A": [statistics.fmean(s[j] for s in seeds[:k]) for j in range(3)],
                 "B": [statistics.fmean(s[j] for s in seeds[k:]) for j in range(3)]}
            if a.train:
                t = per_seed(h, f"{wd}/train", path, f"{wd}/train-{name}", k, extra)
                r["train"] = [statistics.fmean(s[j] for s in t) for j in range(3)]
            rows[name] = r
        summary = {}
        for j, g in enumerate(GROUPS):
            xa = [r["A"][j] for r in rows.values()]
            xb = [r["B"][j] for r in rows.values()]
            cov = statistics.covariance(xa, xb)
            noise = statistics.variance([x - y for x, y in zip(xa, xb)]) / 2
            s = {"between_set_sd": max(cov, 0.0) ** 0.5, "noise_sd_k_seeds": noise ** 0.5,
                 "spearman_a_b": spearman(xa, xb), "mean": statistics.fmean(xa + xb)}
            if a.train:
                held = [(x + y) / 2 for x, y in zip(xa, xb)]
                s["spearman_train_held"] = spearman([r["train"][j] for r in rows.values()], held)
            summary[g] = s
        res["clips"][c] = {"sets": rows, "summary": summary}
    if a.out:
        json.dump(res, open(a.out, "w"), indent=1)
    print(f"| clip | error | between-set sd | noise sd of a {k}-seed mean | rank corr. seeds "
          f"0..{k - 1} vs {k}..{2 * k - 1} |" + (" rank corr. training half vs held-out |"
                                                  if a.train else ""))
    print("|---|---|---:|---:|---:|" + ("---:|" if a.train else ""))
    for c, rc in res["clips"].items():
        for g, s in rc["summary"].items():
            line = (f"| {c} | {g} | {s['between_set_sd']:.4f} | {s['noise_sd_k_seeds']:.4f} | "
                    f"{s['spearman_a_b']:+.2f} |")
            if a.train:
                line += f" {s['spearman_train_held']:+.2f} |"
            print(line)


if __name__ == "__main__":
    main()
