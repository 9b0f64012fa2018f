#!/usr/bin/env bash
# The README's first command: set up a fresh Debian machine (once), build, run `herdfit demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup-debian.sh
cargo run --release -- demo "$@"
