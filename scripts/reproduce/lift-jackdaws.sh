#!/usr/bin/env bash
# RESULTS.md, "3D lift": both jackdaw flights seen by a ground observer, and the synthetic boids
# flock, each scored for the four estimates (true mean depth, constant depth, frame by frame,
# whole sequence). About half a minute.
#   bash scripts/reproduce/lift-jackdaws.sh [OUT]
source "$(dirname "$0")/common.sh"
run lift camera --out cam_transit.json --position=3.6,-65.1,-16.8 --look-at=3.6,-5.1,-0.7
run lift camera --out cam_mob.json --position=-7.3,-59.5,-17.9 --look-at=-7.3,0.6,3.9
run lift evaluate "$DATA/jackdaws/transit_05.csv" --camera cam_transit.json --out ev_transit \
    --v-target 0.15 --d-near 10 --d-far 150
run lift evaluate "$DATA/jackdaws/mob_10.csv" --camera cam_mob.json --out ev_mob \
    --v-target 0.15 --d-near 10 --d-far 150
echo '{"birds":12,"frames":150,"hfov":40}' >boids.json
run lift synth --out syn --config boids.json
run lift evaluate syn/truth3d.csv --camera syn/camera.json --crop --out ev_syn \
    --v-target 0.3333333333333333 --d-near 20 --d-far 400
