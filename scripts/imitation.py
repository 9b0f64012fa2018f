#!/usr/bin/env python3
"""The crowd system's imitation of herdfit's own herd model (issue #20, the paper's Reynolds
experiment), as one command.

Sources: `herdfit simulate --agents 100 --steps 120 --guidance 1,0 --seed S` for S = F..F+N-1
(F = --first-seed, default 0; another F gives a fresh set of sources).
Scale: the mean 1-Wasserstein distance of speed, nearest-neighbour distance, turning rate and
polarization between every pair of sources (their run-to-run spread). Each configuration learns
from the first --train sources (default 1: `crowd learn src0.csv --config C`) and imitates each
remaining source S from its
first frame (`crowd simulate --entries srcS.csv --no-goals --seed S+offset`) once per offset;
the table gives the mean W1 over those runs and its ratio to 2x the spread (<= 1: within).

    python3 scripts/imitation.py --herdfit target/release/herdfit [--sources 9] [--first-seed 0]
        [--offsets 0,100]
        [--config '{"action":{"k":30}}' ...] [--json out.json]
"""

import argparse
import itertools
import json
import os
import subprocess
import sys
import tempfile

MEASURES = ["speed", "nearest_neighbour", "turning_rate", "polarization"]
DEFAULT_CONFIGS = [
    "{}",
    '{"features":{"weights":{"alignment":100}}}',
    '{"action":{"k":30}}',
    '{"action":{"k":30},"features":{"weights":{"alignment":30}}}',
    '{"action":{"k":30},"features":{"weights":{"alignment":100}}}',
]


def run(herdfit, *args):
    r = subprocess.run([herdfit, *args], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"herdfit {' '.join(args)}: {r.stderr.strip()}")


def compare(herdfit, a, b, tmp):
    out = os.path.join(tmp, "compare.json")
    run(herdfit, "crowd", "compare", a, b, "--json", out)
    with open(out) as f:
        m = {x["name"]: x["wasserstein"] for x in json.load(f)["measures"]}
    return [m[k] for k in MEASURES]


def mean(rows):
    return [sum(c) / len(rows) for c in zip(*rows)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--sources", type=int, default=9)
    ap.add_argument("--first-seed", type=int, default=0, help="seed of the first source")
    ap.add_argument("--train", type=int, default=1, help="learn from the first N sources")
    ap.add_argument("--offsets", default="0,100", help="imitation seed offsets")
    ap.add_argument("--config", action="append", help="learn config JSON (repeatable)")
    ap.add_argument("--json", help="write the table as JSON here")
    a = ap.parse_args()
    if a.sources < 3 or not 1 <= a.train < a.sources:
        sys.exit("--sources must be >= 3 and --train in 1..sources-1")
    offsets = [int(x) for x in a.offsets.split(",")]
    configs = a.config or DEFAULT_CONFIGS
    with tempfile.TemporaryDirectory() as tmp:
        src = []
        for s in range(a.sources):
            p = os.path.join(tmp, f"src{s}.csv")
            run(a.herdfit, "simulate", "--agents", "100", "--steps", "120", "--guidance", "1,0",
                "--seed", str(a.first_seed + s), "--out", p)
            src.append(p)
        pairs = [compare(a.herdfit, src[i], src[j], tmp)
                 for i, j in itertools.combinations(range(a.sources), 2)]
        spread = mean(pairs)
        limit = [2 * x for x in spread]
        print(f"source spread (mean W1 over {len(pairs)} pairs of {a.sources} sources, seeds "
              f"{a.first_seed}-{a.first_seed + a.sources - 1}): "
              + ", ".join(f"{k} {v:.4f}" for k, v in zip(MEASURES, spread)))
        print()
        print("| learn config | " + " | ".join(MEASURES) + " | within 2x spread |")
        print("|---|" + "---:|" * (len(MEASURES) + 1))
        table = []
        for c in configs:
            cfg = os.path.join(tmp, "learn.json")
            with open(cfg, "w") as f:
                f.write(c)
            model = os.path.join(tmp, "model.json")
            run(a.herdfit, "crowd", "learn", *src[:a.train], "--config", cfg, "--out", model)
            rows = []
            for s, off in itertools.product(range(a.train, a.sources), offsets):
                out = os.path.join(tmp, "imitation.csv")
                run(a.herdfit, "crowd", "simulate", model, "--entries", src[s], "--no-goals",
                    "--seed", str(a.first_seed + s + off), "--out", out)
                rows.append(compare(a.herdfit, src[s], out, tmp))
            m = mean(rows)
            ratio = [x / l for x, l in zip(m, limit)]
            within = sum(r <= 1 for r in ratio)
            print(f"| `{c}` | "
                  + " | ".join(f"{x:.4f} ({r:.2f}x)" for x, r in zip(m, ratio))
                  + f" | {within} of {len(MEASURES)} |")
            table.append({"config": json.loads(c), "runs": len(rows),
                          "mean_w1": dict(zip(MEASURES, m)),
                          "ratio_to_limit": dict(zip(MEASURES, ratio))})
        if a.json:
            with open(a.json, "w") as f:
                json.dump({"spread": dict(zip(MEASURES, spread)), "pairs": len(pairs),
                           "limit": dict(zip(MEASURES, limit)), "configs": table}, f, indent=1)


if __name__ == "__main__":
    main()
