#!/usr/bin/env bash
# Golden outputs: runs a fixed set of herdfit commands on small test inputs with the binary BIN
# and writes the sha256 of every output file (recursively, stdout of each command included) to
# OUTDIR/hashes.txt. Two binaries that write the same hashes behave the same on these inputs:
#
#   scripts/golden.sh target/release/herdfit /tmp/golden-new
#   diff /work/team/golden-base/hashes.txt /tmp/golden-new/hashes.txt
#
# or give the base hashes as a third argument to have the script compare (exit 1 on a difference).
# Every command runs inside OUTDIR with relative paths, so the paths recorded in provenance are
# the same whatever OUTDIR is. Threads are pinned (RAYON_NUM_THREADS) because the bytes may
# depend on the thread count (DESIGN: "same inputs, seed and thread count"). Files whose bytes
# are not deterministic even for one binary are listed in NONDETERMINISTIC below with the reason,
# and hashed anyway (a diff there is expected). The commands use the flag names of the base
# (pre-#13) binary, so one script runs both; the renamed flags keep those names as aliases.
# scripts/golden-diff.py BASE_OUT NEW_OUT explains a difference file by file.
set -euo pipefail
if [ $# -lt 2 ]; then
    echo "usage: $0 BIN OUTDIR [BASE_HASHES]" >&2
    exit 2
fi
BIN=$(realpath "$1")
OUT=$2
BASE=${3:-}
REPO=$(cd "$(dirname "$0")/.." && pwd)
VTEST=${HERDFIT_VTEST:-/usr/share/doc/opencv-doc/examples/data/vtest.avi}
export RAYON_NUM_THREADS=2
rm -rf "$OUT"
mkdir -p "$OUT"
cd "$OUT"
mkdir -p stdout
t0=$(date +%s)

# run NAME ARGS…: runs the binary, its stdout kept in stdout/NAME.txt (stderr only shown on
# failure) with the wall-clock times it prints replaced by "…" (the identifiability estimate's
# "(estimated in 3.3 s)", the demo's "; 11 s", "animation (1 s)" and "agent-steps in 0.21 s"),
# its wall time appended to timings.txt (not hashed).
run() {
    local name=$1 t=$SECONDS
    shift
    if ! "$BIN" "$@" >"stdout/$name.raw" 2>"stdout/$name.err"; then
        echo "golden: '$name' failed: herdfit $*" >&2
        cat "stdout/$name.err" >&2
        exit 1
    fi
    sed -E -e 's/\(estimated in [0-9.]+ s\)/(estimated in … s)/' -e 's/; [0-9.]+ s$/; … s/' \
        -e 's/animation \([0-9.]+ s\)$/animation (… s)/' -e 's/agent-steps in [0-9.]+ s$/agent-steps in … s/' \
        "stdout/$name.raw" >"stdout/$name.txt"
    rm -f "stdout/$name.err" "stdout/$name.raw"
    echo "$name $((SECONDS - t)) s" >>timings.txt
}

# Inputs.
cat >init.csv <<'EOF'
id,x,y,vx,vy
0,0,0,1,0
1,1.5,0.2,0.9,0.1
2,0.3,1.4,1,0.2
3,-1.2,0.5,0.8,-0.1
4,2.4,1.6,1.1,0
5,-0.6,-1.5,1,0.3
6,1.1,-1.2,0.9,-0.2
7,3.2,-0.4,1,0
EOF
cat >cells.json <<'EOF'
{"cells": [[7, 3], [7, 4], [11, 6]]}
EOF
cp -r "$REPO/scenes" scenes
python3 - <<'EOF'
import json
for name, seconds in [("pasture", 3), ("anthill", 2)]:
    p = f"scenes/{name}.json"
    s = json.load(open(p))
    s["duration"] = seconds
    json.dump(s, open(p, "w"), indent=1)
EOF

# simulate: built-in random herd, initial CSV, record and replay.
run simulate-agents simulate --agents 60 --steps 20 --guidance 1,0 --seed 3 --out sim-agents.csv
run simulate-init simulate --init init.csv --steps 15 --speed-noise 0.1 --record rec.json --out sim-init.csv
run simulate-replay simulate --init init.csv --steps 15 --replay rec.json --out sim-replay.csv
run simulate-f64 simulate --agents 30 --steps 10 --precision f64 --seed 1 --out sim-f64.csv

# synth: fields only; with a video; with a moving camera and obstacles.
run synth synth --agents 80 --frames 24 --grid 16x8 --cell-size 2 --seed 1 --out synth
run synth-video synth --agents 80 --frames 24 --grid 16x8 --cell-size 2 --seed 1 \
    --video synth-video.avi --out synth-video
run synth-camera synth --agents 80 --frames 24 --grid 16x8 --cell-size 2 --seed 2 \
    --obstacles cells.json --heading 10 --video synth-camera.avi --camera-motion --out synth-camera

# extract: the synthetic video (static), the moving camera with anchors, OpenCV's vtest.avi.
run extract-synth extract synth-video.avi --out ex-synth --grid 16 --body-length-px 12 \
    --body-colour 235,235,225 --preview ex-synth-preview --preview-every 10
run extract-camera extract synth-camera.avi --out ex-camera --grid 16 --body-length-px 12 \
    --body-colour 235,235,225 --anchor center --smooth 5
run extract-vtest extract "$VTEST" --out ex-vtest --grid 16 --body-length-px 40 \
    --body-pixels 500 --frames 0..12 --preview ex-vtest-preview --preview-every 6
python3 -c 'import json; print(json.dumps(json.load(open("ex-synth/clip.json"))["provenance"]["settings"]))' \
    >extract-settings.json
run extract-config extract synth-video.avi --out ex-config --config extract-settings.json --frames 2..20

# fit: each loss and optimiser, several clips, a checkpointed run resumed.
FIT=(--window 4 --epochs 2 --eval-seeds 2 --frames 0..16)
run fit-paper fit synth --out fit-paper.json "${FIT[@]}"
run fit-fields fit synth --out fit-fields.json "${FIT[@]}" --loss fields --optimizer normalized
run fit-ensemble fit synth --out fit-ensemble.json "${FIT[@]}" --loss ensemble --replicas 2 \
    --optimizer averaged
run fit-options fit synth --out fit-options.json "${FIT[@]}" --joint-gradients --cell-mean \
    --settle 5 --guidance-scale 1.5 --init synth/truth.json --lr 0.05 --beta 0.5 --seed 4
run fit-two fit synth synth-camera --out fit-two.json --window 4 --epochs 1 --eval-seeds 1 \
    --log fit-two-log.csv --plot fit-two-loss.png
# A checkpointed run; the same run resumed from its epoch-1 checkpoint (rebuilt from the finished
# run's checkpoint: the normalised step keeps no optimiser state) must end with the same bytes.
CK=(--window 4 --epochs 2 --eval-seeds 1 --frames 0..12 --optimizer normalized)
run fit-ck fit synth --out fit-ck.json "${CK[@]}" --checkpoint ck
mkdir -p ck-resumed
python3 - <<'EOF2'
import json
k = json.load(open("ck/checkpoint.json"))
first = [r for r in k["log"] if r["epoch"] == 0]
k.update(epochs_done=1, theta=first[-1]["theta"], log=first)
open("ck-resumed/checkpoint.json", "w").write(json.dumps(k))
EOF2
run fit-resumed fit synth --out fit-resumed.json "${CK[@]}" --checkpoint ck-resumed --resume
run fit-finished fit synth --out fit-finished.json "${CK[@]}" --checkpoint ck --resume
cmp -s fit-ck.json fit-resumed.json || echo "golden: warning: the resumed fit differs from the uninterrupted one" >&2

# validate: fitted vs baseline with its video; the ensemble mean with a warm-up.
run validate validate synth --params fit-fields.json --baseline synth/truth.json --seeds 2 \
    --grid 4 --out val
run validate-ensemble validate ex-synth --params synth/truth.json --seeds 2 --ensemble-mean \
    --warmup 3 --settle 5 --guidance-scale inf --no-video --out val-ensemble

# author: both example scenes (shortened), one with its video.
run author-pasture author scenes/pasture.json --out author-pasture --video --px-per-bl 4
run author-anthill author scenes/anthill.json --out author-anthill

# gradcheck: the herd objective (f64, recorded; f32 replayed), the fit's losses.
run gradcheck gradcheck --agents 40 --steps 4 --record gc-rec.json --json gc.json
run gradcheck-f32 gradcheck --agents 40 --steps 4 --precision f32 --replay gc-rec.json --json gc-f32.json
run gradcheck-loss gradcheck --objective loss --clip synth --steps 3 --json gc-loss.json
run gradcheck-fields gradcheck --objective loss --clip synth --steps 3 --loss fields --json gc-fields.json
run gradcheck-ensemble gradcheck --objective loss --clip synth --steps 3 --loss ensemble \
    --replicas 2 --json gc-ensemble.json

# import-reference, fields-info.
run import import-reference "$REPO/tests/data/reference/sample" --out ref
run fields-info fields-info synth --json info.json
run fields-info-ref fields-info ref --json info-ref.json

# demo.
run demo demo --out demo

# Files whose bytes differ from run to run of one binary, and why (hashed anyway); none since
# run() blanks the wall-clock times printed on stdout.
NONDETERMINISTIC=()
printf '%s\n' "${NONDETERMINISTIC[@]+"${NONDETERMINISTIC[@]}"}" | sed '/^$/d' >nondeterministic.txt
find . -type f ! -name hashes.txt ! -name nondeterministic.txt ! -name timings.txt -print0 | LC_ALL=C sort -z |
    xargs -0 sha256sum >hashes.txt
echo "golden: $(wc -l <hashes.txt) files hashed in $(($(date +%s) - t0)) s; $OUT/hashes.txt"
if [ -n "$BASE" ]; then
    if diff <(grep -v -F -f nondeterministic.txt "$BASE") <(grep -v -F -f nondeterministic.txt hashes.txt); then
        if [ -s nondeterministic.txt ]; then
            echo "golden: same bytes as $BASE (apart from: $(tr "\n" " " <nondeterministic.txt))"
        else
            echo "golden: same bytes as $BASE (every file)"
        fi
    else
        echo "golden: outputs differ from $BASE" >&2
        exit 1
    fi
fi
