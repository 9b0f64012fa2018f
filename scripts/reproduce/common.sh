# Sourced by the scripts in scripts/reproduce/: the binary, the real data, the output folder.
#   HERDFIT   the binary (default: target/release/herdfit of this checkout)
#   DATA      the shared real data (default: ../shared/data beside the checkout, see its README)
# Every command is echoed before it runs, so the output shows what produced each figure.
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
HERDFIT=$(realpath "${HERDFIT:-$ROOT/target/release/herdfit}")
DATA=$(realpath "${DATA:-$ROOT/../shared/data}")
[ -x "$HERDFIT" ] || { echo "error: $HERDFIT: no binary (cargo build --release, or set HERDFIT)" >&2; exit 2; }
[ -d "$DATA" ] || { echo "error: $DATA: no shared data folder (set DATA)" >&2; exit 2; }
OUT=${1:-/tmp/herdfit-reproduce/$(basename "$0" .sh)}
mkdir -p "$OUT"
cd "$OUT"
run() {
    echo "+ herdfit $*" >&2
    "$HERDFIT" "$@"
}
