#!/usr/bin/env python3
"""Can the held-out measures tell the truth from a wrong parameter set? (RESULTS.md, issue 6)

Makes synthetic clips like the demo's (300 agents, 120 frames, 16×10 cells of 3 BL; seeds 7, 8, 9)
and validates the true parameters θ* against each of 17 sets that move one cohesion, avoidance
or alignment parameter by ±0.2, and against the generic start (every value 0.5), with
`herdfit validate CLIP --params θ* --baseline P --seeds K --no-video` plus `--extra`. Prints how
often θ* has the smaller mean error (per measure and overall; 0.5 is chance) and, per clip, on
how many of the 6 measures θ* beats the generic start. Uses the herdfit CLI and the standard
library.

    python3 scripts/validation_power.py [--herdfit target/release/herdfit] [--seeds 4]
        [--extra "--warmup 60"] [--jobs 2]
"""
import argparse, itertools, json, os, subprocess, tempfile
from concurrent.futures import ThreadPoolExecutor

NAMES = [f"{f}.{p}" for f in ("cohesion", "avoidance", "alignment", "obstacle")
         for p in ("weight", "radial", "angular")]
MEASURES = ["density", "velocity", "polarization", "ang. mom. centroid",
            "ang. mom. frame centre", "aspect ratio"]

ap = argparse.ArgumentParser()
ap.add_argument("--herdfit", default="target/release/herdfit")
ap.add_argument("--seeds", type=int, default=4)
ap.add_argument("--extra", default="")
ap.add_argument("--jobs", type=int, default=2)
a = ap.parse_args()
tmp = tempfile.mkdtemp(prefix="herdfit-vpower-")
clips = []
for seed in (7, 8, 9):
    d = os.path.join(tmp, f"clip{seed}")
    subprocess.run([a.herdfit, "synth", "--agents", "300", "--frame-count", "120", "--grid-size", "16x10",
                    "--cell-size", "3", "--seed", str(seed), "--out", d],
                   check=True, capture_output=True)
    clips.append(d)
truth = json.load(open(os.path.join(clips[0], "truth.json")))
truth.pop("physical", None)
truth_path = os.path.join(tmp, "truth.json")
json.dump(truth, open(truth_path, "w"))
alts = {}
for n in NAMES[:9]:
    f, p = n.split(".")
    for d in (-0.2, 0.2):
        if 0.001 <= truth["forces"][f][p] + d <= 1.0:
            q = json.loads(json.dumps(truth))
            q["forces"][f][p] = round(q["forces"][f][p] + d, 6)
            alts[f"{n}{d:+.1f}"] = q
q = json.loads(json.dumps(truth))
for n in NAMES:
    f, p = n.split(".")
    q["forces"][f][p] = 0.5
alts["generic start"] = q
for name, q in alts.items():
    json.dump(q, open(os.path.join(tmp, f"{name}.json"), "w"))


def run(job):
    clip, name = job
    out = os.path.join(tmp, f"report-{os.path.basename(clip)}-{name}")
    subprocess.run([a.herdfit, "validate", clip, "--params", truth_path, "--baseline",
                    os.path.join(tmp, f"{name}.json"), "--seeds", str(a.seeds), "--no-video",
                    "--out", out] + a.extra.split(), check=True, capture_output=True)
    r = json.load(open(os.path.join(out, "report.json")))
    err = lambda s, m: r["sets"][s]["rows"][m]["error"]["mean"]
    return clip, name, [err(0, m) < err(1, m) for m in range(6)]


with ThreadPoolExecutor(a.jobs) as ex:
    res = list(ex.map(run, itertools.product(clips, alts)))
moves = [w for _, n, w in res if n != "generic start"]
wins = sum(sum(w) for w in moves)
print(f"θ* has the smaller error in {wins} of {6 * len(moves)} comparisons with ±0.2 moves "
      f"({wins / (6 * len(moves)):.2f}; chance 0.5)")
for m, name in enumerate(MEASURES):
    print(f"  {name}: {sum(w[m] for w in moves) / len(moves):.2f}")
print("θ* beats the generic start on " +
      ", ".join(f"{sum(w)}/6 measures ({os.path.basename(c)})"
                for c, n, w in res if n == "generic start"))
