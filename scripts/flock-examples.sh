#!/usr/bin/env bash
# Regenerates the synthetic flock examples in examples/flocks/ (V, U, J and line formations with
# noise and outliers; tracks CSV + sidecar with the wingspan; the role column holds the truth).
# The settings live in herdfit::flock::synth::shipped_examples(); tests/flock.rs checks that a
# fresh run gives the committed bytes.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo run --release --quiet -- flock synth --examples examples/flocks
