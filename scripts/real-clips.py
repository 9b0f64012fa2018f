#!/usr/bin/env python3
"""Issue #15 item 4: the fit's objective, window, optimiser and global phase compared on real clips.

Each clip is fitted on its first half (from the generic all-0.5 start, as a bare `herdfit fit`
does) with one setting changed at a time, then every fitted set, the generic start and a
disordered start (no cohesion, no alignment, the strongest avoidance) are validated on the second
half (`herdfit validate --split 0.5 --seeds 16`). Printed: one Markdown table row per clip ×
setting with the held-out density and velocity errors, the sum of the four emergent-measure
errors, and the polarization / angular momentum (centroid) of the simulation vs the clip's own
mean ± STD, whether the fitted set beats each baseline seed by seed beyond the noise
(`validate --baseline`: the paired difference and the 95 % t-interval over the common-random-number
seeds); then each setting's mean ratio to the generic start over the clips (lower is better).

Clips (made first, see --make): fish = the trajectorytools 15-fish school through import-tracks,
students = ETH/UCY students003 through import-tracks, testA = idtracker.ai's test_A.avi through
extract. Uses only the herdfit CLI and the Python standard library; every command is echoed.

    python3 scripts/real-clips.py --herdfit target/release/herdfit --work /tmp/rc [--make]
        [--clips fish,students,testA] [--settings default,fields,...] [--out rc.json]
        [--constants leader_max_neighbours=0] [--start-from disordered] [--validate-tracks H]

The `tracks` setting fits from the clip's tracked animals (`fit --tracks CLIP/tracks.csv`, which
import-tracks writes); `--validate-tracks H` validates every set from them too (`validate --tracks`,
restarted every H frames), on the clips that have tracks.
"""
import argparse
import json
import os
import subprocess
import sys
import time

SETTINGS = {
    "default": [],
    "paper": ["--loss", "paper"],
    "fields": ["--loss", "fields"],
    "ensemble": ["--loss", "ensemble", "--replicas", "2"],
    "w1": ["--window", "1"],
    "w16": ["--window", "16"],
    "normalized": ["--optimizer", "normalized"],
    "averaged": ["--optimizer", "averaged"],
    "starts4": ["--starts", "4"],
    # Every window from the tracked animals (fit --tracks; import-tracks' tracks.csv).
    "tracks": ["--tracks", "{clip}/tracks.csv"],
}
MEASURES = ["polarization", "angular_momentum_centroid", "angular_momentum_frame_centre",
            "aspect_ratio"]


def run(cmd):
    print("$ " + " ".join(cmd), file=sys.stderr, flush=True)
    t0 = time.time()
    subprocess.run(["nice", "-n", "10"] + cmd, check=True, stdout=subprocess.DEVNULL)
    return time.time() - t0


def make_clips(h, w, repo):
    shared = os.environ.get("HERDFIT_SHARED_DATA", "/work/shared/data")
    run([h, "import-tracks", f"{repo}/.testdata/trajectorytools/trajectories_with_points.npy",
         "--body-length-px", "57", "--arena", "border", "--out", f"{w}/fish"])
    run([h, "import-tracks", f"{shared}/pedestrians/eth-ucy/students003.txt", "--fps", "2.5",
         "--body-length-m", "0.3", "--out", f"{w}/students"])
    # Fish ≈ 60 px long; --body-pixels calibrated so that the 8 fish count ≈ 8 per frame.
    run([h, "extract", f"{repo}/.testdata/idtrackerai/test_A.avi", "--body-length-px", "60",
         "--body-pixels", "440", "--grid", "12", "--out", f"{w}/testA"])


def baselines(w, template, constants=""):
    """generic.json (every force 0.5) and disordered.json from a fitted set's file, with the
    model constants `constants` (k=v,…) set."""
    d = json.load(open(template))
    for k in ("provenance", "physical", "uncertainty"):
        d.pop(k, None)
    for kv in filter(None, constants.split(",")):
        k, v = kv.split("=")
        d["constants"][k] = json.loads(v)
    for g in d["forces"].values():
        for k in g:
            g[k] = 0.5
    json.dump(d, open(f"{w}/generic.json", "w"), indent=1)
    d["forces"]["cohesion"]["weight"] = 0.0
    d["forces"]["alignment"]["weight"] = 0.0
    d["forces"]["avoidance"]["weight"] = 1.0
    json.dump(d, open(f"{w}/disordered.json", "w"), indent=1)


def validate(h, clip, params, out, seeds, baseline=None, extra=()):
    cmd = [h, "validate", clip, "--params", params, "--split", "0.5", "--seeds", str(seeds),
           "--no-video", "--out", out] + list(extra)
    run(cmd + (["--baseline", baseline] if baseline else []))
    report = json.load(open(f"{out}/report.json"))
    rows = {r["measure"]: r for r in report["sets"][0]["rows"]}
    e = lambda m: rows[m]["error"]["mean"]
    res = {"density": e("density_error"), "velocity": e("velocity_error"),
           "measures": sum(e(m) for m in MEASURES)}
    for m in ("polarization", "angular_momentum_centroid"):
        v, s = rows[m]["video"], rows[m]["simulation"]
        res[m] = {"sim": s["mean"], "clip": v["mean"], "clip_std": v["std"],
                  "within": abs(s["mean"] - v["mean"]) <= v["std"]}
    if baseline:
        # herdfit validate's paired comparison: fitted − baseline per seed (common random
        # numbers), its standard error and the verdict of the 95 % t-interval.
        paired = {r["measure"]: r for r in report["paired"][0]["rows"]}
        res["paired"] = {k: paired[m] for k, m in (("density", "density_error"),
                                                    ("velocity", "velocity_error"),
                                                    ("measures", "sum_of_four_measures"))}
    return res


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--work", default="/tmp/herdfit-real-clips")
    ap.add_argument("--make", action="store_true", help="import/extract the clips first")
    ap.add_argument("--clips", default="fish,students,testA")
    ap.add_argument("--settings", default=",".join(SETTINGS))
    ap.add_argument("--extra", default="", help="flags added to every fit")
    ap.add_argument("--constants", default="",
                    help="model constants of every start and baseline, k=v,… (e.g. "
                         "leader_max_neighbours=0); the fits then start from generic.json")
    ap.add_argument("--start-from", default="generic", choices=["generic", "disordered"],
                    help="the baseline every fit starts from (default: the generic all-0.5 set, "
                         "as a bare fit does)")
    ap.add_argument("--seeds", type=int, default=16,
                    help="validation seeds (the paired verdicts need several)")
    ap.add_argument("--validate-tracks", type=int, default=None, metavar="H",
                    help="validate from the clip's tracks.csv (validate --tracks) where it has "
                         "one, the herd restarted from them every H frames (0: one run)")
    ap.add_argument("--tag", default="", help="suffix of this run's files")
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    h, w = os.path.abspath(a.herdfit), a.work
    os.makedirs(w, exist_ok=True)
    if a.make:
        make_clips(h, w, repo)
    res = {"settings": {k: SETTINGS[k] for k in a.settings.split(",")}, "clips": {}}
    for c in a.clips.split(","):
        clip = f"{w}/{c}"
        frames = json.load(open(f"{clip}/clip.json"))["frames"]
        half = frames // 2
        rc = res["clips"][c] = {"frames": frames, "fits": {}}
        t = a.tag
        ve = []
        if a.validate_tracks is not None and os.path.exists(f"{clip}/tracks.csv"):
            ve = ["--tracks", f"{clip}/tracks.csv"]
            ve += ["--horizon", str(a.validate_tracks)] if a.validate_tracks else []
        # The baselines from a parameter file of this clip (a one-epoch fit on 5 frames).
        tmpl = f"{w}/{c}{t}-template.json"
        run([h, "fit", clip, "--frames", "0..5", "--epochs", "1", "--eval-seeds", "1",
             "--no-uncertainty", "--out", tmpl])
        baselines(w, tmpl, a.constants)
        for b in ("generic", "disordered"):
            os.replace(f"{w}/{b}.json", f"{w}/{c}{t}-{b}.json")
        rc["baselines"] = {b: validate(h, clip, f"{w}/{c}{t}-{b}.json", f"{w}/{c}{t}-val-{b}",
                                       a.seeds, extra=ve)
                           for b in ("generic", "disordered")}
        start = (["--start", f"{w}/{c}{t}-{a.start_from}.json"]
                 if a.constants or a.start_from != "generic" else [])
        for name in a.settings.split(","):
            out = f"{w}/{c}{t}-{name}.json"
            wall = run([h, "fit", clip, "--frames", f"0..{half}", "--eval-seeds", "1", "--out",
                        out] + start + [x.format(clip=clip) for x in SETTINGS[name]]
                       + a.extra.split())
            v = validate(h, clip, out, f"{w}/{c}{t}-val-{name}", a.seeds, extra=ve)
            v["versus"] = {b: validate(h, clip, out, f"{w}/{c}{t}-val-{name}-vs-{b}", a.seeds,
                                       f"{w}/{c}{t}-{b}.json", extra=ve)["paired"]
                           for b in ("generic", "disordered")}
            fitted = json.load(open(out))
            v["wall_s"] = wall
            v["theta_at_bounds"] = sum(
                1 for g in fitted["forces"].values() for x in g.values() if x <= 0.0 or x >= 1.0)
            rc["fits"][name] = v
            print(f"{c} {name}: {json.dumps(v)}", file=sys.stderr, flush=True)
    if a.out:
        json.dump(res, open(a.out, "w"), indent=1)
    report(res)


def report(res):
    print("| clip | set | density err | velocity err | Σ 4 measure errors | polarization sim (clip ± STD) "
          "| ang. momentum sim (clip ± STD) | beats generic & disordered (d/v/Σ) "
          "| vs generic, paired (d/v/Σ) | vs disordered, paired (d/v/Σ) | fit wall s |")
    print("|---|---|---:|---:|---:|---:|---:|---|---|---|---:|")
    mark = {"better": "B", "worse": "W", "within noise": "=", "same": "S"}
    ratios = {}
    for c, rc in res["clips"].items():
        g, dis = rc["baselines"]["generic"], rc["baselines"]["disordered"]
        for name, v in list(rc["baselines"].items()) + list(rc["fits"].items()):
            p, m = v["polarization"], v["angular_momentum_centroid"]
            beats, vs = "", {"generic": "", "disordered": ""}
            if "versus" in v:
                vs = {b: "/".join(mark[v["versus"][b][k]["verdict"]]
                                  for k in ("density", "velocity", "measures"))
                      for b in vs}
            if name in rc["fits"]:
                beats = "/".join("yes" if v[k] < g[k] and v[k] < dis[k] else "no"
                                 for k in ("density", "velocity", "measures"))
                r = sum(v[k] / g[k] for k in ("density", "velocity", "measures")) / 3
                ratios.setdefault(name, []).append(r)
            print(f"| {c} | {name} | {v['density']:.4f} | {v['velocity']:.4f} | {v['measures']:.4f} | "
                  f"{p['sim']:.3f} ({p['clip']:.3f} ± {p['clip_std']:.3f}){'' if p['within'] else ' ✗'} | "
                  f"{m['sim']:.3f} ({m['clip']:.3f} ± {m['clip_std']:.3f}){'' if m['within'] else ' ✗'} | "
                  f"{beats} | {vs['generic']} | {vs['disordered']} | {v.get('wall_s', 0):.0f} |")
    print()
    print("Paired: fitted − baseline seed by seed (`herdfit validate --baseline`); B better, W worse, "
          "= within the seeds' noise (95 % t-interval holds 0).")
    print()
    print("| setting | mean over clips of (d, v, Σ) ratios to the generic start |")
    print("|---|---:|")
    for name, r in sorted(ratios.items(), key=lambda x: sum(x[1]) / len(x[1])):
        print(f"| {name} | {sum(r) / len(r):.4f} |")


if __name__ == "__main__":
    main()
