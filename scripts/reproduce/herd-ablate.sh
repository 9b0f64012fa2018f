#!/usr/bin/env bash
# RESULTS.md, "Herds: ablations": the paper's §7.2 switches (Table 4) on the synthetic corridor,
# and (when .testdata has it, scripts/fetch-testdata.sh) on the real 15-fish school. The
# corridor takes about 1.5 min on 2 cores, the fish about 5 min.
#   bash scripts/reproduce/herd-ablate.sh [OUT]
source "$(dirname "$0")/common.sh"
# The crossing protocol's truth (scripts/scenario.py: the built-in set at 2 BL/s) and the
# corridor's walls (CORRIDOR_CELLS).
python3 - "$ROOT/scripts" "$HERDFIT" <<'PY'
import json, sys
sys.path.insert(0, sys.argv[1])
from scenario import CORRIDOR_CELLS, crossing_truth
crossing_truth(sys.argv[2], ".")
json.dump({"cells": CORRIDOR_CELLS}, open("cells.json", "w"))
PY
run synth --params truth-in.json --agents 300 --frame-count 200 --grid-size 14x10 --cell-size 4 \
    --obstacles cells.json --seed 11 --out corridor
run ablate corridor --out abl-corridor --epochs 4 --seeds 3
FISH=$ROOT/.testdata/trajectorytools/trajectories_with_points.npy
if [ -f "$FISH" ]; then
    run import-tracks "$FISH" --body-length-px 57 --arena border --out fish
    run ablate fish --out abl-fish --epochs 4 --seeds 3
fi
