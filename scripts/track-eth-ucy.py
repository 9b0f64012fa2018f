#!/usr/bin/env python3
"""ETH/UCY leave-one-scene-out for the herd model fitted by the track objective (issue #49), on
the protocol of `herdfit crowd evaluate` (observe 8 steps, predict 12 = 4.8 s at 2.5 fps, every
complete 20-step window of every pedestrian, ADE/FDE in metres): for each test scene, the herd
model is fitted (`fit --objective tracks`) on the clips of the other scenes and the training-only
files, and scored on the test scene by `validate-tracks` (free rollouts of every pedestrian present
at the observation's end, neighbours simulated too) beside constant velocity. Each file is
imported as a clip with a body length of 0.3 m (`import-tracks --fps 2.5 --body-length-m 0.3`).

    python3 scripts/track-eth-ucy.py [--herdfit target/release/herdfit] [--data DIR]
        [--fit-extra "--rollout free"] [--seeds 4] [--scenes ETH,HOTEL,…] [--work DIR]
        [--crowd-report crowd.json] [--out eth-ucy.json]

`--crowd-report` takes the JSON of `herdfit crowd evaluate --json crowd.json` and prints its
model's and constant velocity's numbers beside the herd model's (the constant-velocity columns
of both must agree: the same windows).
"""
import argparse, json, os, subprocess, sys, tempfile, time

SCENES = {"ETH": ["biwi_eth"], "HOTEL": ["biwi_hotel"], "UNIV": ["students001", "students003"],
          "ZARA1": ["crowds_zara01"], "ZARA2": ["crowds_zara02"]}
TRAIN_ONLY = ["uni_examples", "crowds_zara03"]


def run(cmd):
    print("$ " + " ".join(cmd), file=sys.stderr)
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--data", default="/work/shared/data/pedestrians/eth-ucy")
    ap.add_argument("--fit-extra", default="", help="more flags for fit --objective tracks")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--start", default="", help="start parameter set (its constants are kept)")
    ap.add_argument("--work", default="")
    ap.add_argument("--crowd-report", default="")
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="herdfit-eth-ucy-")
    os.makedirs(work, exist_ok=True)
    files = sorted({f for v in SCENES.values() for f in v} | set(TRAIN_ONLY))
    for f in files:
        clip = os.path.join(work, f)
        if not os.path.isfile(os.path.join(clip, "clip.json")):
            run([a.herdfit, "import-tracks", os.path.join(a.data, f + ".txt"), "--fps", "2.5",
                 "--body-length-m", "0.3", "--out", clip])
    rows = []
    for scene in a.scenes.split(","):
        train = [os.path.join(work, f) for f in files if f not in SCENES[scene]]
        test = [os.path.join(work, f) for f in SCENES[scene]]
        fitted = os.path.join(work, f"fit-{scene}.json")
        t0 = time.time()
        cmd = [a.herdfit, "fit"] + train + ["--objective", "tracks", "--out", fitted,
                                            "--no-uncertainty"] + a.fit_extra.split()
        if a.start:
            cmd += ["--start", a.start]
        run(cmd)
        fit_s = time.time() - t0
        rep = os.path.join(work, f"eval-{scene}")
        run([a.herdfit, "validate-tracks"] + test + [
            "--params", fitted, "--split", "0", "--own-speed", "--observe", "8",
            "--horizons", "4.8", "--rollouts", "free", "--stride", "0", "--free-run", "0",
            "--seeds", str(a.seeds), "--out", rep])
        r = json.load(open(os.path.join(rep, "report.json")))
        m = r["metres_per_bl"]
        h = r["rollouts"][0]["horizons"][0]
        sets = {x["set"]: x for x in h["sets"]}
        row = {"scene": scene, "samples": h["samples"], "fit_s": fit_s,
               "herd": [sets[fitted_name(fitted)]["ade"] * m, sets[fitted_name(fitted)]["fde"] * m],
               "generic": [sets["generic"]["ade"] * m, sets["generic"]["fde"] * m],
               "default": [sets["default"]["ade"] * m, sets["default"]["fde"] * m],
               "cv": [h["constant_velocity"][0] * m, h["constant_velocity"][1] * m],
               "verdicts": h["verdicts"]}
        rows.append(row)
        print(f"{scene}: herd {row['herd'][0]:.3f}/{row['herd'][1]:.3f}, cv {row['cv'][0]:.3f}/"
              f"{row['cv'][1]:.3f} ({row['samples']} windows, fit {fit_s:.0f} s)", file=sys.stderr)
    crowd = {}
    if a.crowd_report:
        c = json.load(open(a.crowd_report))
        for f in c["folds"]:
            crowd[f["scene"]] = f
    print("| scene | windows | herd model ADE/FDE (m) | generic | default | constant velocity | crowd model | crowd's constant velocity |")
    print("|---|---:|---|---|---|---|---|---|")
    for r in rows:
        c = crowd.get(r["scene"])
        cm = f"{c['model']['ade']:.3f}/{c['model']['fde']:.3f}" if c else "—"
        cc = f"{c['constant_velocity']['ade']:.3f}/{c['constant_velocity']['fde']:.3f} ({c['windows']})" if c else "—"
        f2 = lambda v: f"{v[0]:.3f}/{v[1]:.3f}"
        print(f"| {r['scene']} | {r['samples']} | {f2(r['herd'])} | {f2(r['generic'])} | "
              f"{f2(r['default'])} | {f2(r['cv'])} | {cm} | {cc} |")
    n = len(rows)
    avg = lambda k, i: sum(r[k][i] for r in rows) / n
    print(f"| average | | {avg('herd', 0):.3f}/{avg('herd', 1):.3f} | "
          f"{avg('generic', 0):.3f}/{avg('generic', 1):.3f} | {avg('default', 0):.3f}/{avg('default', 1):.3f} | "
          f"{avg('cv', 0):.3f}/{avg('cv', 1):.3f} | " +
          (f"{sum(crowd[r['scene']]['model']['ade'] for r in rows) / n:.3f}/"
           f"{sum(crowd[r['scene']]['model']['fde'] for r in rows) / n:.3f}" if crowd else "—") + " | |")
    if a.out:
        json.dump({"rows": rows, "settings": vars(a), "work": work}, open(a.out, "w"), indent=1)


def fitted_name(path):
    return os.path.splitext(os.path.basename(path))[0]


if __name__ == "__main__":
    main()
