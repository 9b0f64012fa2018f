#!/usr/bin/env python3
"""The split-in-time table of the crowd imitation on every ETH/UCY scene, in one command.

Each scene is cut in time at the frame that leaves half its agent-frames before it; a crowd model
learnt from the first half simulates the second half's entries (each individual enters where and
when it appeared, heads for where it was last seen and leaves when it was), and the second half is
compared with the simulation and with the first half (`herdfit crowd holdout`). A measure holds
when the simulation's 1-Wasserstein distance from the second half is at most 2x the first half's.

    python3 scripts/crowd-holdout.py --herdfit target/release/herdfit
    python3 scripts/crowd-holdout.py --out holdout/ -- --config my-learn.json

Arguments after `--` go to every `herdfit crowd holdout` call. Writes DIR/<scene>.json (the
reports) and DIR/table.md, prints the table, and exits 1 when a measure does not hold.
"""

import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = [
    "biwi_eth",
    "biwi_hotel",
    "crowds_zara01",
    "crowds_zara02",
    "crowds_zara03",
    "students001",
    "students003",
    "uni_examples",
]
# The scenes the `pedestrians` preset was chosen on (RESULTS, crowd holdout); the others report.
TUNING = {"biwi_hotel", "crowds_zara01", "students003"}
SHORT = {
    "speed": "speed",
    "nearest_neighbour": "nearest neighbour",
    "turning_rate": "turning rate",
    "polarization": "polarization",
}


def default_data():
    shared = os.environ.get("HERDFIT_SHARED_DATA")
    if shared:
        return os.path.join(shared, "pedestrians/eth-ucy")
    sibling = os.path.join(ROOT, "..", "shared", "data")
    base = sibling if os.path.isdir(sibling) else "/work/shared/data"
    return os.path.join(base, "pedestrians", "eth-ucy")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--herdfit", default=os.path.join(ROOT, "target/release/herdfit"))
    ap.add_argument("--data", default=default_data(), help="folder of the ETH/UCY .txt files")
    ap.add_argument("--out", default="crowd-holdout", help="folder for the reports and table")
    ap.add_argument("rest", nargs="*", help="extra arguments of `crowd holdout` (after --)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows, failed = [], 0
    for scene in SCENES:
        src = os.path.join(a.data, scene + ".txt")
        rep = os.path.join(a.out, scene + ".json")
        cmd = [a.herdfit, "crowd", "holdout", src, "--json", rep, *a.rest]
        r = subprocess.run(cmd, capture_output=True, text=True)
        if r.returncode != 0:
            sys.exit(f"crowd-holdout: {' '.join(cmd)} failed: {r.stderr.strip()}")
        with open(rep) as f:
            report = json.load(f)
        cells = []
        for m in report["measures"]:
            failed += not m["holds"]
            cells.append(
                f"{m['ratio']:.2f}{'' if m['holds'] else ' ✗'} "
                f"({m['simulated']:.3f} / {m['halves']:.3f})"
            )
        role = "tuning" if scene in TUNING else "report"
        rows.append(f"| {scene} | {role} | {report['agents']} | " + " | ".join(cells) + " |")
    names = [SHORT.get(m["name"], m["name"]) for m in report["measures"]]
    head = (
        "| scene | chosen on / reported | simulated individuals | "
        + " | ".join(f"{n}: ratio (W1 sim / W1 halves)" for n in names)
        + " |\n|---|---|---:|"
        + "---:|" * len(names)
    )
    table = head + "\n" + "\n".join(rows) + "\n"
    total = len(rows) * len(names)
    summary = f"{total - failed} of {total} within 2x the distance between the real halves\n"
    with open(os.path.join(a.out, "table.md"), "w") as f:
        f.write(table + "\n" + summary)
    print(table)
    print(summary, end="")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
