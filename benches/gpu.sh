#!/usr/bin/env bash
# One command for a machine with a GPU (issue #53): builds herdfit with the GPU backend (cargo
# feature `gpu`) and runs `herdfit bench` on the CPU and on the GPU in the same window, then
# prints one Markdown table (ms per step) with the adapter wgpu chose. Set
# CUBECL_WGPU_DEFAULT_DEVICE to pick another adapter (e.g. Cpu for Mesa's lavapipe).
#
#   bash benches/gpu.sh [OUT_DIR]          # default OUT_DIR: bench-gpu/
#   SIZES="1500 5000" BIG="100000 1000000" bash benches/gpu.sh
#   HERDFIT=path/to/herdfit bash benches/gpu.sh   # skip the build
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-bench-gpu}"
SIZES="${SIZES:-1500 5000}"
BIG="${BIG:-100000 1000000}"
mkdir -p "$OUT"
if [ -n "${HERDFIT:-}" ]; then
  H="$HERDFIT" # a binary already built with --features gpu
else
  cargo build --release --features gpu --bin herdfit
  H=target/release/herdfit
fi
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
for n in $SIZES; do
  for d in cpu gpu; do
    "$H" bench --agents "$n" --steps 20 --repeats 3 --device "$d" --json "$OUT/$d-$n.json"
  done
done
for n in $BIG; do
  for d in cpu gpu; do
    "$H" bench --agents "$n" --steps 3 --sim-only --device "$d" --json "$OUT/$d-$n.json"
  done
done
python3 - "$OUT" $SIZES $BIG <<'PY'
import json, pathlib, subprocess, sys
out, sizes = pathlib.Path(sys.argv[1]), sys.argv[2:]
def get(d, n):
    p = out / f"{d}-{n}.json"
    return json.loads(p.read_text()) if p.exists() else {}
def ms(r, k):
    v = r.get(k)
    return "—" if v is None else f"{v:.3f}"
try:
    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                         capture_output=True, text=True).stdout.strip()
except OSError:
    gpu = ""
print(f"\nGPU: {gpu or 'the adapter wgpu chose (CUBECL_WGPU_DEFAULT_DEVICE to change it)'}\n")
print("| agents | device | simulation | fwd+bwd live | fwd+bwd replay | peak RSS (MB) |")
print("|---:|---|---:|---:|---:|---:|")
for n in sizes:
    for d in ("cpu", "gpu"):
        r = get(d, n)
        print(f"| {int(n):,} | {d} | {ms(r, 'sim_ms_per_step')} | {ms(r, 'grad_ms_per_step')} | "
              f"{ms(r, 'replay_grad_ms_per_step')} | {r.get('peak_rss_mb', 0):.0f} |")
PY
