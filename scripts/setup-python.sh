#!/usr/bin/env bash
# Builds and installs the Python package (python/, `import herdfit`) into .venv-python/
# (git-ignored; it sees the system Python's numpy, matplotlib and Jupyter packages that
# scripts/setup-debian.sh installs) with the pinned python/requirements.txt, for the pytest suite
# (python/tests) and the notebooks. The build runs in the workspace's target/ with the release
# profile and the test build's features (python/Cargo.toml), so after
# `cargo test --release --workspace` only pyo3's crates and the bindings compile. Idempotent: the venv is remade only when the
# requirements change; the package is rebuilt every time (cargo skips what is current).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
VENV="$ROOT/.venv-python"
REQ="$ROOT/python/requirements.txt"
if ! cmp -s "$REQ" "$VENV/requirements.txt" 2>/dev/null; then
  echo "setup-python: installing python/requirements.txt into .venv-python (pip)"
  rm -rf "$VENV"
  python3 -m venv --system-site-packages "$VENV"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r "$REQ"
  cp "$REQ" "$VENV/requirements.txt"
fi
# Without OpenCV the package is built without the `video` feature (herdfit.missing_features()
# says so).
ARGS=""
pkg-config --exists opencv4 2>/dev/null || ARGS="--no-default-features"
echo "setup-python: pip install ./python (maturin, target/) $ARGS"
PATH="$VENV/bin:$PATH" MATURIN_PEP517_ARGS="$ARGS" CARGO_TARGET_DIR="$ROOT/target" "$VENV/bin/python" -m pip install --quiet \
  --disable-pip-version-check --no-build-isolation --no-deps --force-reinstall "$ROOT/python"
"$VENV/bin/python" -c "import herdfit; print('setup-python: herdfit', herdfit.__version__, herdfit.features())"
