#!/usr/bin/env bash
# Installs what the many-clips workflow (workflow/) and its tests need on a fresh Debian machine:
# the pinned Python packages (workflow/requirements.txt: snakemake, its Slurm executor plugin,
# matplotlib, pytest) into .venv-workflow/ (git-ignored, apart from the system Python's packages),
# and Debian's Slurm daemons, client and munge, with which workflow/tests start a one-node cluster.
# scripts/setup-debian.sh calls it. Idempotent: nothing is fetched when all is in place.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
VENV="$ROOT/.venv-workflow"
REQ="$ROOT/workflow/requirements.txt"

# python3-venv: Debian's python3 makes no venv without it (ensurepip).
APT_PACKAGES=(python3-venv slurmctld slurmd slurm-client munge)
missing=()
for p in "${APT_PACKAGES[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  echo "setup-workflow: installing ${missing[*]}"
  $SUDO apt-get update -qq
  # The packages' own services are not started here (the tests start their own cluster).
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The venv is current when it holds a copy of the requirements it was made from.
if ! cmp -s "$REQ" "$VENV/requirements.txt" 2>/dev/null; then
  echo "setup-workflow: installing workflow/requirements.txt into .venv-workflow (pip)"
  rm -rf "$VENV"
  python3 -m venv "$VENV"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps -r "$REQ"
  "$VENV/bin/python" -m pip check >/dev/null
  cp "$REQ" "$VENV/requirements.txt"
fi
"$VENV/bin/snakemake" --version >/dev/null
