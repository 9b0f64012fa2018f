#!/usr/bin/env bash
# RESULTS.md, "Crowds": a model learnt from every ETH/UCY file but students003 walks the 434
# pedestrians of students003 in where and when they entered, towards where and until when they
# left, and is compared with the real crowd. About 10 s.
#   bash scripts/reproduce/crowd-students003.sh [OUT]
source "$(dirname "$0")/common.sh"
D=$DATA/pedestrians/eth-ucy
run crowd learn "$D/students001.txt" "$D/biwi_eth.txt" "$D/biwi_hotel.txt" "$D/crowds_zara01.txt" \
    "$D/crowds_zara02.txt" "$D/crowds_zara03.txt" "$D/uni_examples.txt" --preset pedestrians \
    --out univ.json
run crowd simulate univ.json --entries "$D/students003.txt" --out s003.csv --png s003.png \
    --compare compare.json
run crowd compare "$D/students003.txt" s003.csv
