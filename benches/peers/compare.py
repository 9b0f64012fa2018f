#!/usr/bin/env python3
"""herdfit's model step against the JAX peer (`jax_step.py`), in one run, side by side.

For each agent count: `herdfit bench` (fused forces, then `--reference-forces`; forward+backward
both with live decisions and replaying recorded ones), and the JAX peer's forward and
forward+backward, all at T unrolled steps, f32; prints a Markdown table with
the ratios (peer time / herdfit time: > 1 means herdfit is faster) and writes the raw figures as
JSON (`herdfit.peer-compare/1`).

    python3 benches/peers/compare.py --herdfit target/release/herdfit --out peers.json

Run it on a quiet machine: each figure is a median over repeats, but other processes competing
for the same cores change every figure.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile


def herdfit_bench(exe, n, steps, repeats, reference):
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "b.json")
        cmd = [exe, "bench", "--agents", str(n), "--steps", str(steps),
               "--repeats", str(repeats), "--json", out]
        if reference:
            cmd.append("--reference-forces")
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        with open(out) as f:
            return json.load(f)


def peer(n, steps, repeats, k):
    here = os.path.dirname(os.path.abspath(__file__))
    cmd = [sys.executable, os.path.join(here, "jax_step.py"), "--agents", str(n),
           "--steps", str(steps), "--repeats", str(repeats), "--k", str(k)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--herdfit", default="target/release/herdfit")
    ap.add_argument("--agents", type=int, nargs="+", default=[500, 1500, 5000])
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--k", type=int, default=16, help="the peer's padded list width K")
    ap.add_argument("--out", help="write the raw figures here (JSON)")
    a = ap.parse_args()
    if not os.access(a.herdfit, os.X_OK):
        sys.exit(f"error: {a.herdfit}: not an executable (build with cargo build --release)")
    rows = []
    for n in a.agents:
        fused = herdfit_bench(a.herdfit, n, a.steps, a.repeats, False)
        ref = herdfit_bench(a.herdfit, n, a.steps, a.repeats, True)
        p = peer(n, a.steps, a.repeats, a.k)
        rows.append({"agents": n, "herdfit": fused, "herdfit_reference": ref, "jax": p})
        print(f"done: {n} agents", file=sys.stderr)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"T = {a.steps}, f32, median of {a.repeats}; jax {rows[0]['jax']['jax']}")
    print()
    print("| agents | herdfit sim (fused) | herdfit fwd+bwd (fused) | herdfit fwd+bwd replay "
          "(fused) | herdfit fwd+bwd (tensor ops) | JAX fwd | JAX fwd+bwd | "
          "JAX fwd+bwd / herdfit fwd+bwd | JAX fwd+bwd / herdfit replay | "
          "JAX fwd / herdfit sim |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        h, t, j = r["herdfit"], r["herdfit_reference"], r["jax"]
        jfb = j["forward_backward_ms_per_step"]
        print(f"| {r['agents']:,} | {h['sim_ms_per_step']:.3f} | {h['grad_ms_per_step']:.3f} | "
              f"{h['replay_grad_ms_per_step']:.3f} | "
              f"{t['grad_ms_per_step']:.3f} | {j['forward_ms_per_step']:.3f} | {jfb:.3f} | "
              f"{jfb / h['grad_ms_per_step']:.2f}× | "
              f"{jfb / h['replay_grad_ms_per_step']:.2f}× | "
              f"{j['forward_ms_per_step'] / h['sim_ms_per_step']:.2f}× |")
    print()
    print("ms per step. herdfit fwd+bwd: perception with occlusion on every step, included; "
          "herdfit replay: the same pass replaying decisions (occlusion-aware lists, roles, noise) "
          "recorded by an untimed run, as `fit` does after its plan; JAX: lists without "
          "occlusion, precomputed outside the timed function.")
    if a.out:
        with open(a.out + ".tmp", "w") as f:
            json.dump({"schema": "herdfit.peer-compare/1", "steps": a.steps,
                       "repeats": a.repeats, "rows": rows}, f, indent=1)
        os.replace(a.out + ".tmp", a.out)


if __name__ == "__main__":
    main()
