#!/usr/bin/env bash
# Installs the JAX peer's Python packages (CPU build of JAX; scipy comes with it).
# Only the peer benchmark needs them: CI does not run it.
set -euo pipefail
python3 -m pip install --quiet "jax[cpu]"
python3 -c "import jax, scipy; print('jax', jax.__version__, 'scipy', scipy.__version__)"
