#!/usr/bin/env bash
# BENCHMARKS.md, "3D lift": a synthetic 200-bird flock over 1000 frames (200,000 points, every
# point in view), lifted frame by frame and over the whole sequence, each timed. About a minute.
#   bash scripts/reproduce/lift-big.sh [OUT]
source "$(dirname "$0")/common.sh"
echo '{"birds":200,"frames":1000,"hfov":80,"crop":false}' >big.json
run lift synth --out big --config big.json
for method in frame sequence; do
    echo "+ /usr/bin/time herdfit lift run … --method $method" >&2
    /usr/bin/time -f "$method: %e s wall, %U s user, %M KB peak RSS" "$HERDFIT" lift run \
        big/tracks2d.csv --camera big/camera.json --method "$method" --out "$method.csv" \
        --v-target 0.3333333333333333 --d-near 20 --d-far 400
done
