#!/usr/bin/env bash
# Long fuzz runs of issue #14: each named target of tests/fuzz.rs for S seconds of CPU (default
# 600) — rounds of HERDFIT_FUZZ_CASES cases (default 10,000), round r seeded with r — one target
# at a time, on one thread. Prints each target's summary line ("fuzz NAME: N cases in R round(s),
# W s wall, C s CPU (…)") and its result; exits non-zero if any target failed.
#
#   bash scripts/fuzz-long.sh [SECONDS] [TARGET …]     # no TARGET: every target of tests/fuzz.rs
#
# The test binary is built once and copied, so later edits of the tree do not rebuild it mid-run.
set -euo pipefail
cd "$(dirname "$0")/.."
secs="${1:-600}"
shift || true
bin="$(cargo test --release --test fuzz --no-run --message-format=json 2>/dev/null \
  | python3 -c 'import json,sys
for l in sys.stdin:
    m = json.loads(l)
    if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "fuzz" and m.get("executable"):
        print(m["executable"])')"
copy="$(mktemp -d)/fuzz"
cp "$bin" "$copy"
if [ "$#" -eq 0 ]; then
  mapfile -t targets < <("$copy" --list 2>/dev/null | sed -n 's/: test$//p' \
    | grep -v glb_with_nan_values_or_bad_indices_is_an_error)
else
  targets=("$@")
fi
fails=0
for t in "${targets[@]}"; do
  if HERDFIT_FUZZ_CPU_SECONDS="$secs" "$copy" --exact "$t" --nocapture --test-threads 1 \
       > "$copy.$t.log" 2>&1; then
    echo "ok     $t: $(grep -o 'fuzz .*' "$copy.$t.log")"
  else
    fails=$((fails + 1))
    echo "FAILED $t:"; tail -n 20 "$copy.$t.log"
  fi
done
exit "$fails"
