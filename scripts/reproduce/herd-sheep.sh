#!/usr/bin/env bash
# README, "Herds from video": the paper's own sheep-narrow clip (the public extractor's fields),
# fitted on its first 100 frames from the generic start and validated on the rest. About a minute.
#   bash scripts/reproduce/herd-sheep.sh [OUT]
source "$(dirname "$0")/common.sh"
run import-reference "$DATA/herds-from-video/sheep_narrow/04_20_21_12" --out sheep
run fit sheep --frames 0..100 --out sheep-params.json
run validate sheep --params sheep-params.json --out sheep-report
