#!/usr/bin/env bash
# Test set-up: fetches the package-shipped real data the tests and RESULTS.md use (never vendored,
# never fetched by the binary at run time) into .testdata/ (git-ignored):
#   .testdata/trajectorytools/trajectories_with_points.npy  15 fish, PyPI trajectorytools 0.4.2 (GPLv3)
#   .testdata/trajectorytools/test_trajectories_idtrackerai.npy  8 fish, same package
#   .testdata/idtrackerai/test_A.avi                       8 fish video, PyPI idtrackerai 6.0.14 (GPLv3+)
# Idempotent: files already present are not fetched again. Wheels are taken with --no-deps (only
# their data files are used; nothing is installed).
set -euo pipefail
cd "$(dirname "$0")/.."
DEST=.testdata
mkdir -p "$DEST/wheels" "$DEST/trajectorytools" "$DEST/idtrackerai"
fetch() { # package version member target
  local pkg=$1 ver=$2 member=$3 target=$4
  [ -s "$target" ] && return 0
  local whl="$DEST/wheels/${pkg}-${ver}-py3-none-any.whl"
  if [ ! -s "$whl" ]; then
    echo "fetch-testdata: downloading $pkg==$ver (pip, --no-deps)"
    python3 -m pip download --quiet --disable-pip-version-check --no-deps \
      --dest "$DEST/wheels" "${pkg}==${ver}"
  fi
  python3 - "$whl" "$member" "$target" <<'PY'
import sys, zipfile, os
whl, member, target = sys.argv[1:]
with zipfile.ZipFile(whl) as z:
    data = z.read(member)
tmp = target + ".part"
with open(tmp, "wb") as f:
    f.write(data)
os.replace(tmp, target)
PY
}
fetch trajectorytools 0.4.2 trajectorytools/data/trajectories_with_points.npy \
  "$DEST/trajectorytools/trajectories_with_points.npy"
fetch trajectorytools 0.4.2 trajectorytools/data/test_trajectories_idtrackerai.npy \
  "$DEST/trajectorytools/test_trajectories_idtrackerai.npy"
fetch idtrackerai 6.0.14 idtrackerai/data/test_A.avi "$DEST/idtrackerai/test_A.avi"
