#!/usr/bin/env bash
# Installs what herdfit needs on a fresh Debian machine that has Rust: the system OpenCV and the
# clang it is bound with (cargo feature `video`), a font for plots, OpenCV's sample video
# vtest.avi (opencv-doc) that the extraction tests read, Mesa's Vulkan drivers (lavapipe, a
# software Vulkan on which tests/gpu.rs runs the GPU backend without a GPU), and the Python packages the tests and
# notebooks use, and the Khronos glTF validator (npm, into .ci/node_modules) that tests/lift.rs runs
# on every exported .glb. Idempotent: packages already present are not fetched again.
set -euo pipefail

APT_PACKAGES=(libopencv-dev clang libclang-dev pkg-config fonts-dejavu-core opencv-doc python3 python3-pip
  mesa-vulkan-drivers libvulkan1)
PIP_PACKAGES=(numpy matplotlib nbclient nbformat ipykernel)

missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
# Node.js and npm run the glTF validator (tests/lift.rs); Debian's packages only when no node or
# npm is on PATH already (one installed otherwise, e.g. by nvm, is used as it is).
command -v node >/dev/null 2>&1 || dpkg -s nodejs >/dev/null 2>&1 || missing+=(nodejs)
command -v npm >/dev/null 2>&1 || dpkg -s npm >/dev/null 2>&1 || missing+=(npm)
if ((${#missing[@]})); then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PY=python3
if ! $PY -c "import numpy, matplotlib, nbclient, nbformat, ipykernel" >/dev/null 2>&1; then
  echo "setup: installing ${PIP_PACKAGES[*]} (pip)"
  $PY -m pip install --quiet --disable-pip-version-check "${PIP_PACKAGES[@]}" \
    || $PY -m pip install --quiet --disable-pip-version-check --break-system-packages "${PIP_PACKAGES[@]}"
fi

# The Khronos glTF validator, pinned in .ci/package.json, installed into the project (not
# globally); tests/lift.rs runs it through scripts/validate-gltf.js.
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
if [ ! -f "$ROOT/.ci/node_modules/gltf-validator/package.json" ] \
  || [ "$ROOT/.ci/package-lock.json" -nt "$ROOT/.ci/node_modules/gltf-validator/package.json" ]; then
  echo "setup: installing gltf-validator (npm, .ci/node_modules)"
  npm ci --prefix "$ROOT/.ci" --no-audit --no-fund --silent
fi
node "$ROOT/scripts/validate-gltf.js" >/dev/null \
  || { echo "setup: the glTF validator does not load (node $(node --version))" >&2; exit 1; }
bash "$(dirname "$0")/fetch-testdata.sh"
# The many-clips workflow (workflow/): snakemake and its Slurm plugin, pinned, in .venv-workflow;
# Slurm and munge for its cluster test.
bash "$(dirname "$0")/setup-workflow.sh"
