#!/usr/bin/env python3
"""Benchmark: `simulate` of 1,500 agents × 250 steps from Python (herdfit.simulate, in process,
arrays out) against the CLI (`herdfit simulate`, a process writing the trajectory CSV), runs
interleaved, median and min of each; prints a Markdown row for BENCHMARKS.md.

    .venv-python/bin/python python/bench/simulate.py [--runs 7] [--bin target/release/herdfit]
"""

import argparse
import os
import pathlib
import statistics
import subprocess
import tempfile
import time

import herdfit

ROOT = pathlib.Path(__file__).resolve().parents[2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--agents", type=int, default=1500)
    ap.add_argument("--steps", type=int, default=250)
    ap.add_argument("--bin", default=str(ROOT / "target" / "release" / "herdfit"))
    a = ap.parse_args()
    env = dict(os.environ, RAYON_NUM_THREADS=os.environ.get("RAYON_NUM_THREADS", "2"))
    os.environ.update(env)
    py, cli = [], []
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "t.csv")
        cmd = [a.bin, "simulate", "--agents", str(a.agents), "--steps", str(a.steps), "--seed", "1", "--out", out]
        subprocess.run(cmd, check=True, capture_output=True, env=env)  # warm the page cache
        for _ in range(a.runs):
            t = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, env=env)
            cli.append(time.perf_counter() - t)
            t = time.perf_counter()
            _, frames = herdfit.simulate(agents=a.agents, steps=a.steps, seed=1, progress=False)
            py.append(time.perf_counter() - t)
            assert frames.shape == (a.steps + 1, a.agents, 5)
    mp, mc = statistics.median(py), statistics.median(cli)
    print(f"python  median {mp:.3f} s  min {min(py):.3f} s  runs {[round(x, 3) for x in py]}")
    print(f"cli     median {mc:.3f} s  min {min(cli):.3f} s  runs {[round(x, 3) for x in cli]}")
    print(f"python / cli: median {mp / mc:.3f}, min {min(py) / min(cli):.3f}")
    print(f"| simulate {a.agents} agents × {a.steps} steps, Python vs CLI | {mp:.2f} s vs {mc:.2f} s "
          f"(median of {a.runs}; ratio {mp / mc:.3f}) | `.venv-python/bin/python python/bench/simulate.py` |")


if __name__ == "__main__":
    main()
