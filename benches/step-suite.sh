#!/usr/bin/env bash
# The model-step benchmarks of BENCHMARKS.md ("Fused force op") in one go, for a quiet machine:
# herdfit bench (fused and --reference-forces) at 500 / 1,500 / 5,000 / 20,000 agents, the
# 100,000-agent simulation, the 1,000,000-agent no-grad run with its memory, the JAX peer in the
# same run (benches/peers/compare.py), criterion (benches/step.rs) and the 300-agent fit before
# and after. Writes everything under OUT (default bench-out/).
#
#   bash benches/peers/setup.sh     # once: JAX for the peer
#   bash benches/step-suite.sh [OUT]
set -euo pipefail
out=${1:-bench-out}
mkdir -p "$out"
cargo build --release
h=target/release/herdfit
uptime | tee "$out/load.txt"
for n in 500 1500 5000 20000; do
  $h bench --agents $n --steps 20 --json "$out/fused-$n.json"
  $h bench --agents $n --steps 20 --reference-forces --json "$out/reference-$n.json"
done
$h bench --agents 100000 --steps 10 --sim-only --json "$out/fused-100000-sim.json"
$h bench --agents 100000 --steps 10 --sim-only --reference-forces --json "$out/reference-100000-sim.json"
$h bench --agents 1000000 --steps 3 --sim-only --repeats 1 --json "$out/fused-1000000-sim.json"
python3 benches/peers/compare.py --herdfit $h --out "$out/peers.json" | tee "$out/peers.md"
cargo bench --bench step -- 'perception_kernel|sim_step|forward_backward' 2>&1 | tee "$out/criterion.txt"
clip="$out/clip300"
rm -rf "$clip"
$h synth --agents 300 --frames 201 --grid 14x10 --cell-size 4 --seed 3 --out "$clip"
for p in f32 f64; do
  /usr/bin/time -f "fit $p fused: %e s, %M KB" $h fit "$clip" --seed 1 --precision $p \
    --out "$out/fit-$p-fused.json" 2>&1 | tail -1 | tee -a "$out/fit.txt"
  /usr/bin/time -f "fit $p reference: %e s, %M KB" $h fit "$clip" --seed 1 --precision $p \
    --reference-forces --out "$out/fit-$p-reference.json" 2>&1 | tail -1 | tee -a "$out/fit.txt"
done
uptime | tee -a "$out/load.txt"
