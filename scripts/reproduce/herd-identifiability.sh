#!/usr/bin/env bash
# RESULTS.md, "Herds: the fit, and what the fields determine": five fits from random starts
# (seed 2026) of four 900-agent corridor clips jointly (ensemble loss, averaged step, 16-step
# windows, 8 epochs), then every start and end point simulated in the generating process and
# scored against 8 clips relative to θ* (Δ > 0: θ* reproduces the clips better). About an hour
# on 2 cores.
#   bash scripts/reproduce/herd-identifiability.sh [OUT]
source "$(dirname "$0")/common.sh"
echo "+ python3 scripts/recovery.py …" >&2
python3 "$ROOT/scripts/recovery.py" --herdfit "$HERDFIT" --scenario corridor --agents 900 \
    --clips 4 --windows 16 --jobs 2 \
    --extra "--loss ensemble --replicas 4 --guidance-scale inf --optimizer averaged" --out REC.json
echo "+ python3 scripts/identifiability.py …" >&2
python3 "$ROOT/scripts/identifiability.py" --herdfit "$HERDFIT" --agents 900 \
    --obstacles "$(python3 -c 'print([[x, y] for x in range(14) for y in (0, 1, 8, 9)])')" \
    --sets REC.json --k 16 --clips 8
