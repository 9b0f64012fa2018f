"""Shared fixtures: the CLI binary the package is compared with, and a small synthetic clip."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cli():
    """Runs the herdfit binary (HERDFIT_BIN or target/release/herdfit); returns its stdout."""
    binary = os.environ.get("HERDFIT_BIN", str(ROOT / "target" / "release" / "herdfit"))
    if not os.path.exists(binary):
        pytest.fail(f"{binary}: no herdfit binary (cargo build --release, or set HERDFIT_BIN)")

    def run(*args, cwd=None):
        r = subprocess.run([binary, *map(str, args)], capture_output=True, text=True, cwd=cwd)
        assert r.returncode == 0, r.stderr
        return r.stdout

    return run


@pytest.fixture(scope="session")
def clip_dir(tmp_path_factory):
    """A 20-frame synthetic clip of 60 agents on 6 × 6 cells of 2 BL (herdfit.synth)."""
    import herdfit

    out = tmp_path_factory.mktemp("clip") / "clip"
    herdfit.synth(out, agents=60, frame_count=20, grid_size=[6, 6], cell_size=2.0, seed=3, progress=False)
    return out


@pytest.fixture(scope="session")
def fish_npy():
    """The 15 tracked fish of PyPI trajectorytools 0.4.2 (scripts/fetch-testdata.sh)."""
    p = ROOT / ".testdata" / "trajectorytools" / "trajectories_with_points.npy"
    if not p.exists():
        pytest.fail(f"{p}: missing; run scripts/fetch-testdata.sh")
    return p


@pytest.fixture(scope="session")
def shared_data():
    """The real data: $HERDFIT_SHARED_DATA, else <repo>/../shared/data, else /work/shared/data."""
    for p in (os.environ.get("HERDFIT_SHARED_DATA"), ROOT.parent / "shared" / "data", "/work/shared/data"):
        if p and pathlib.Path(p).is_dir():
            return pathlib.Path(p)
    pytest.fail("no shared data (set HERDFIT_SHARED_DATA)")
