#!/usr/bin/env python3
"""Issue #50: candidate image statistics for the speed law v = c · Ω^(−p), measured leave one out.

For each candidate turning-rate statistic Ω of the 2D tracks, the law is fitted on one jackdaw
flight's 2 s windows (az 0 cameras, as `lift-validate.py` part 1) and predicts the other flight's
median speed on all six cameras; the law pooled over both flights predicts the synthetic flocks'
(seeds 1–5 for choosing, 6–10 held out). Prints, per candidate, how many predictions fall within
15 % of the truth's median. Candidates:

- `image-median`: the shipped estimator (median of |v × a| / |v|² of pixel positions);
- `image-weighted`: Σ|v × a| / Σ|v|² (slow image points weigh less);
- `image-mean-K`: time mean of Ω clipped at K rad/s;
- `image-median-lag0.2`: the median with 0.2 s differences;
- `plane-median`: the median on the horizontal plane (`lift::estimate::plane_turning`);
- and, per case, image Ω / plane Ω (`estimate.foreshortening` of the lift report);
- for the spacing ruler (depth = a prior nearest-neighbour distance / its angle in the image),
  each flight's true median 3D nearest-neighbour distance.

    python3 scripts/lift-vtarget-attempts.py --work /tmp/lva [--herdfit target/release/herdfit]
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

CAMS = [(60, 16, 0), (40, 10, 0), (100, 16, 0), (60, 40, 0), (60, 3, 0), (60, 16, 90)]
SYN = [(8, 1), (12, 2), (20, 3), (30, 4), (50, 5)]
SYN_CAMS = [(80, 38.3), (120, 38.3), (200, 38.3), (120, 20)]


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"{' '.join(cmd)}\n{r.stderr}")


def load(p):
    return np.genfromtxt(p, delimiter=",", names=True)


def project(h, work, tag, truth, target, dist, below, az=0.0):
    cam = f"{work}/cam_{tag}.json"
    a = np.radians(az)
    pos = np.asarray(target) + np.array([dist * np.sin(a), -dist * np.cos(a), -below])
    if not os.path.exists(cam):
        run([h, "lift", "camera", "--out", cam, f"--position={pos[0]},{pos[1]},{pos[2]}",
             f"--look-at={target[0]},{target[1]},{target[2]}"])
    p2 = f"{work}/p2d_{tag}.csv"
    if not os.path.exists(p2):
        run([h, "lift", "project", truth, "--camera", cam, "--out", p2, "--crop"])
    return p2, cam


def rates(p2, cam_path, truth, fps, lag_s, plane):
    """Per point |v × a| and |v|² (NaN without a window), the frames and the true speeds."""
    d = load(p2)
    fr, ids = d["frame"].astype(int), d["id"].astype(int)
    px = np.stack([d["x"], d["y"]], 1)
    if plane:
        cam = json.load(open(cam_path))
        rc = np.stack([(px[:, 0] - cam["cx"]) / cam["fx"], (px[:, 1] - cam["cy"]) / cam["fy"],
                       np.ones(len(px))], 1)
        rw = rc @ np.array(cam["rotation"])
        ok = np.abs(rw[:, 2]) > 0.02 * np.linalg.norm(rw, axis=1)
        px = np.where(ok[:, None], rw[:, :2] / np.where(ok, rw[:, 2], 1)[:, None], np.nan)
    key = {(f, i): k for k, (f, i) in enumerate(zip(fr, ids))}
    lag = max(1, int(round(lag_s * fps)))
    dt = 2 * lag / fps
    cr, vv = np.full(len(fr), np.nan), np.full(len(fr), np.nan)
    for k, (f, i) in enumerate(zip(fr, ids)):
        w = [key.get((f + o * lag, i)) for o in (-2, -1, 1, 2)]
        if any(x is None for x in w):
            continue
        a, b, c, e = w
        v = (px[c] - px[b]) / dt
        acc = (px[e] - 2 * px[k] + px[a]) / dt**2
        cr[k], vv[k] = abs(v[0] * acc[1] - v[1] * acc[0]), v @ v
    t = load(truth)
    sp = np.sqrt(t["vx"] ** 2 + t["vy"] ** 2 + t["vz"] ** 2)
    tk = {(f, i): s for f, i, s in zip(t["frame"].astype(int), t["id"].astype(int), sp)}
    return fr, cr, vv, np.array([tk[(f, i)] for f, i in zip(fr, ids)])


def stat(kind, cr, vv):
    m = ~np.isnan(cr) & ~np.isnan(vv) & (vv > 0)
    om = cr[m] / vv[m]
    if kind == "weighted":
        return cr[m].sum() / vv[m].sum()
    if kind.startswith("mean-"):
        return np.mean(np.minimum(om, float(kind[5:])))
    return np.median(om)


def fit(w):
    w = np.array(w)
    s, i = np.polyfit(np.log(w[:, 1]), np.log(w[:, 0]), 1)
    return float(np.exp(i)), float(-s)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", required=True)
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--data", default="/work/shared/data/jackdaws")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    cases = []  # (set, name, p2d, camera, truth, fps)
    for name in ["transit_05", "mob_10"]:
        path = f"{a.data}/{name}.csv"
        t = load(path)
        cen = [t["x"].mean(), t["y"].mean(), t["z"].mean()]
        for cam in CAMS:
            tag = f"{name}_{cam[0]}_{cam[1]}_{cam[2]}"
            p2, cp = project(a.herdfit, a.work, tag, path, cen, *cam)
            cases.append((name, f"{tag}", p2, cp, path, 60.0, cam in CAMS[:5]))
    for birds, seed in SYN:
        for off in (0, 5):
            sd = seed + off
            syn = f"{a.work}/syn_{birds}_{sd}"
            if not os.path.exists(syn + "/truth3d.csv"):
                with open(syn + ".json", "w") as f:
                    json.dump({"birds": birds, "frames": 300, "seed": sd}, f)
                run([a.herdfit, "lift", "synth", "--out", syn, "--config", syn + ".json"])
            for dist, below in SYN_CAMS:
                tag = f"syn_{birds}_{sd}_{dist}_{below}"
                p2, cp = project(a.herdfit, a.work, tag, syn + "/truth3d.csv", [0, 0, 40.0], dist, below)
                cases.append(("choose" if off == 0 else "held", tag, p2, cp, syn + "/truth3d.csv", 30.0, False))
    cands = [("image-median", 0.1, False), ("image-weighted", 0.1, False), ("image-mean-1", 0.1, False),
             ("image-mean-2", 0.1, False), ("image-mean-10", 0.1, False),
             ("image-median-lag0.2", 0.2, False), ("plane-median", 0.1, True)]
    print("| Ω statistic | law fitted on transit_05 (c, p) | on mob_10 | pooled | jackdaws, other flight's law | synthetic seeds 1–5, pooled | seeds 6–10 |")
    print("|---|---|---|---|---:|---:|---:|")
    per = {}
    for kind, lag, plane in cands:
        base = kind.replace("-lag0.2", "").split("-", 1)[1]
        r = {c[1]: rates(c[2], c[3], c[4], c[5], lag, plane) for c in cases}
        fits, pooled = {}, []
        for name in ["transit_05", "mob_10"]:
            win = []
            for c in cases:
                if c[0] != name or not c[6]:
                    continue
                fr, cr, vv, s = r[c[1]]
                for w0 in range(0, fr.max() + 1, 120):
                    m = (fr >= w0) & (fr < w0 + 120) & ~np.isnan(cr) & ~np.isnan(vv)
                    if m.sum() >= 30:
                        win.append((np.median(s[m]), stat(base, cr[m], vv[m])))
            fits[name] = fit(win)
            pooled += win
        fits["pooled"] = fit(pooled)
        ok = {"jack": [], "choose": [], "held": []}
        for c in cases:
            fr, cr, vv, s = r[c[1]]
            law = fits[{"transit_05": "mob_10", "mob_10": "transit_05"}.get(c[0], "pooled")]
            err = law[0] * stat(base, cr, vv) ** -law[1] / np.median(s) - 1
            ok["jack" if c[0] in ("transit_05", "mob_10") else c[0]].append(err)
            per.setdefault(c[1], {})[kind] = stat(base, cr, vv)
        f = lambda e: f"{sum(abs(x) <= 0.15 for x in e)} of {len(e)} ({100 * min(e):+.0f} to {100 * max(e):+.0f} %)"
        print(f"| {kind} | {fits['transit_05'][0]:.2f}, {fits['transit_05'][1]:.3f} | {fits['mob_10'][0]:.2f}, "
              f"{fits['mob_10'][1]:.3f} | {fits['pooled'][0]:.2f}, {fits['pooled'][1]:.3f} | {f(ok['jack'])} | "
              f"{f(ok['choose'])} | {f(ok['held'])} |")
    print("\n| case | image Ω (rad/s) | plane Ω (rad/s) | image / plane |")
    print("|---|---:|---:|---:|")
    for tag, s in per.items():
        print(f"| {tag} | {s['image-median']:.3f} | {s['plane-median']:.3f} | {s['image-median'] / s['plane-median']:.2f} |")
    print()
    for name in ["transit_05", "mob_10"]:
        d = load(f"{a.data}/{name}.csv")
        nn = []
        for fr in np.unique(d["frame"]):
            m = d["frame"] == fr
            p = np.stack([d["x"][m], d["y"][m], d["z"][m]], 1)
            if len(p) > 1:
                dd = np.linalg.norm(p[:, None] - p[None], axis=2)
                np.fill_diagonal(dd, np.inf)
                nn += list(dd.min(1))
        print(f"{name}: median 3D nearest-neighbour distance {np.median(nn):.2f} m")


if __name__ == "__main__":
    main()
