#!/usr/bin/env python3
"""The paper's own sheep (Herds From Video §7.1.3, issue #46), both protocols in one command.

    python3 scripts/sheep-narrow.py [--herdfit target/release/herdfit] [--out out/sheep-narrow]
                                    [--protocol paper|reference|both] [--seeds 16]
                                    [--fit-args='--loss fields']

Input: ../shared/data/herds-from-video/sheep_narrow/ (the public reference implementation's
extraction output of the clip, imported as it is by `herdfit import-reference`).

- **paper**: fit the first half (frames 0..99) with the defaults, validate the held-out second
  half on a 10 × 10 grid with 16 seeds, paired against the all-0.5 set and against the
  reference's optimisation start; prints the measures, the count in view and the verdicts.
- **reference**: the reference's logging protocol — 100 frames from the clip's start, the
  reference's own measures (`validate --frames 0..101 --measures reference`) — for the
  reference's optimisation start, the two sets its Unity scene stores (`Parameters before
  Optimization`, which its `Not_Optimized.txt` log ran, and `Parameters after Optimization`,
  its `Optimized.txt`), and herdfit's fitted set; each beside the mean of the reference's logs.

Every number printed is read from the report folders the commands write under --out.
"""
import argparse
import json
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
DATA = os.environ.get("HERDFIT_SHARED_DATA", os.path.join(REPO, "..", "shared", "data"))
CLIP = os.path.join(DATA, "herds-from-video", "sheep_narrow")
PREFIX = os.path.join(CLIP, "04_20_21_12")
LOGS = os.path.join(CLIP, "errorlog")

# The reference's parameter sets, in its Parameters.cs order: avoidance, cohesion, alignment,
# obstacle, each (weight, radial range, angular range). Start: DemoSheepNarrow.cs; the two
# stored sets: Optimization_Unity/Assets/Scenes/BoidsOnFlat.unity ("Parameters before/after
# Optimization" under DemoSheepNarrow).
REFERENCE_SETS = {
    "reference-start": [1, 1, 1, 0.1, 1, 1, 0.1, 1, 1, 0.15, 1, 0.5],
    "reference-not-optimized": [
        0.24936901, 0.6998846, 0.9999944, 0.15065786, 1, 0.5000645,
        0.15966761, 1, 0.5023714, 0.15, 1, 0.5,
    ],
    "reference-optimized": [
        0.74183106, 0.526222, 1, 0.50474095, 1, 0.96481836,
        0.49948117, 1, 1, 0.15290348, 1, 0.50019324,
    ],
}
ORDER = ["avoidance", "cohesion", "alignment", "obstacle"]
MEASURES = ["density", "velocity", "polarization", "angular_momentum", "aspect_ratio"]
LOG_COLUMNS = {"density": 1, "velocity": 2, "polarization": 5, "angular_momentum": 8, "aspect_ratio": 11}


def run(herdfit, *args):
    cmd = [herdfit, *args]
    print("$ herdfit " + " ".join(args), flush=True)
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if r.returncode != 0:
        sys.exit(f"sheep-narrow: herdfit failed: {r.stderr.strip()}")
    return r.stdout


def params_file(path, values, like):
    """A herdfit.params/1 file with the reference's 12 values (its order) and `like`'s constants
    and speed model."""
    p = json.load(open(like))
    for k in ("physical", "provenance", "uncertainty"):
        p.pop(k, None)
    for g, force in enumerate(ORDER):
        for j, key in enumerate(["weight", "radial", "angular"]):
            v = values[3 * g + j]
            p["forces"][force][key] = v if key == "weight" else max(v, 1e-3)
    json.dump(p, open(path, "w"), indent=1)


def outside(count, video):
    """Frames where the simulated count leaves the issue's band: ±10 % of the video's, ±3 animals
    where the video holds fewer than 30. Returns "k of n"."""
    bad = sum(abs(c - v) > (3 if v < 30 else 0.1 * v) for c, v in zip(count, video))
    return f"{bad} of {len(video)}"


def median(xs, w):
    """The centred running median of `xs` over `w` frames (shorter at the ends)."""
    h = w // 2
    return [sorted(xs[max(0, i - h):i + h + 1])[len(xs[max(0, i - h):i + h + 1]) // 2]
            for i in range(len(xs))]


def log_means(name):
    rows = [l.split() for l in open(os.path.join(LOGS, name)) if l.strip()][1:]
    return {m: sum(float(r[c]) for r in rows) / len(rows) for m, c in LOG_COLUMNS.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--herdfit", default=os.path.join(REPO, "target", "release", "herdfit"))
    ap.add_argument("--out", default=os.path.join(REPO, "out", "sheep-narrow"))
    ap.add_argument("--protocol", choices=["paper", "reference", "both"], default="both")
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--fit-args", default="",
                    help="extra arguments of the fit, e.g. --fit-args='--loss fields' (a fit already "
                         "in --out is reused: give each setting its own --out)")
    a = ap.parse_args()
    if not os.path.exists(PREFIX + "_data_frame.txt"):
        sys.exit(f"sheep-narrow: {PREFIX}_data_frame.txt not found (set HERDFIT_SHARED_DATA)")
    os.makedirs(a.out, exist_ok=True)
    clip = os.path.join(a.out, "clip")
    if not os.path.exists(os.path.join(clip, "clip.json")):
        run(a.herdfit, "import-reference", PREFIX, "--out", clip)
    fitted = os.path.join(a.out, "fitted.json")
    if not os.path.exists(fitted):
        run(a.herdfit, "fit", clip, "--frames", "0..99", *a.fit_args.split(), "--out", fitted)
    half = os.path.join(a.out, "all-0.5.json")
    params_file(half, [0.5] * 12, fitted)
    for name, values in REFERENCE_SETS.items():
        params_file(os.path.join(a.out, name + ".json"), values, fitted)

    if a.protocol in ("paper", "both"):
        print("\n## Paper protocol: fit frames 0..99, validate the held-out half (10 × 10 grid)\n")
        for base in ["all-0.5", "reference-start"]:
            rep = os.path.join(a.out, "paper-vs-" + base)
            run(a.herdfit, "validate", clip, "--params", fitted, "--baseline",
                os.path.join(a.out, base + ".json"), "--split", "0.5", "--coarse-grid", "10",
                "--seeds", str(a.seeds), "--no-video", "--out", rep)
            r = json.load(open(os.path.join(rep, "report.json")))
            video = r["boundary"]["video_count"] if r.get("boundary") else None
            print("| set | density err | velocity err | polarization err | ang. momentum err "
                  "(centroid) | frames outside the count band | same, vs the video's 5-frame median |")
            print("|---|---:|---:|---:|---:|---:|---:|")
            for s in r["sets"]:
                e = {row["measure"]: row["error"]["mean"] for row in s["rows"]}
                band = ["—", "—"]
                if video and s.get("population"):
                    c = s["population"]["count"]
                    band = [outside(c, video), outside(c, median(video, 5))]
                name = "fitted" if s["name"] == "fitted" else base
                print(f"| {name} | {e['density_error']:.4f} | {e['velocity_error']:.4f} | "
                      f"{e['polarization']:.4f} | {e['angular_momentum_centroid']:.4f} | {band[0]} | "
                      f"{band[1]} |")
            for p in r.get("paired", []):
                for row in p["rows"]:
                    if row["measure"] in ("density_error", "velocity_error", "polarization"):
                        print(f"  fitted − {base}, {row['measure']}: {row['difference']:+.4f} "
                              f"± {row['standard_error']:.4f} ({row['verdict']})")
            print()

    if a.protocol in ("reference", "both"):
        print("\n## Reference protocol: 100 frames from the clip's start, the reference's measures\n")
        rows = []
        for name in ["reference-start", "reference-not-optimized", "reference-optimized", "fitted"]:
            p = fitted if name == "fitted" else os.path.join(a.out, name + ".json")
            rep = os.path.join(a.out, "reference-" + name)
            run(a.herdfit, "validate", clip, "--params", p, "--frames", "0..101", "--measures",
                "reference", "--seeds", str(a.seeds), "--no-video", "--out", rep)
            r = json.load(open(os.path.join(rep, "report.json")))
            ref = r["sets"][0]["reference"]
            rows.append((f"herdfit, {name}", {x["measure"]: x["error"]["mean"] for x in ref["rows"]}))
        rows.append(("reference log Not_Optimized.txt", log_means("Not_Optimized.txt")))
        rows.append(("reference log Optimized.txt", log_means("Optimized.txt")))
        print("| run | " + " | ".join(MEASURES) + " |")
        print("|---|" + "---:|" * len(MEASURES))
        for name, e in rows:
            print(f"| {name} | " + " | ".join(f"{e[m]:.4f}" for m in MEASURES) + " |")


if __name__ == "__main__":
    main()
