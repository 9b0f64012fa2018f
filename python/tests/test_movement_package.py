"""The movement package itself (when installed; CI does not install it, its dependencies cost
about 2 minutes: `pip install movement==0.15.0` into the package's venv, then this file): a
dataset built by movement's own loader reads into herdfit unchanged, and herdfit's dataset goes
through movement's DeepLabCut writer and reader and its kinematics."""

import numpy as np
import pytest

import herdfit
from herdfit import tracks as ht

movement = pytest.importorskip("movement")


def test_movement_datasets_cross_both_ways_on_the_real_fish(fish_npy, tmp_path):
    from movement.io import load_poses, save_poses
    from movement.kinematics import compute_velocity

    fish = ht.read_idtracker(fish_npy)
    arr = fish.to_array()  # [1000 frames, 15 fish, 2], NaN where a fish was lost
    ids = np.unique(fish.id)
    theirs = load_poses.from_numpy(
        position_array=arr.transpose(0, 2, 1)[:, :, None, :],
        confidence_array=np.where(np.isfinite(arr).all(axis=2), 1.0, np.nan)[:, None, :],
        individual_names=[f"id_{i}" for i in ids],
        keypoint_names=["centroid"],
        fps=32,
        source_software="idtracker.ai",
    )
    from_theirs = herdfit.from_movement(theirs)
    assert from_theirs.fps == 32 and np.array_equal(from_theirs.to_array(), arr, equal_nan=True)
    assert np.array_equal(from_theirs.id, fish.id) and np.array_equal(from_theirs.frame, fish.frame)

    ours = herdfit.to_movement(fish)
    save_poses.to_dlc_file(ours, tmp_path / "fish.h5", split_individuals=False)
    back = herdfit.from_movement(load_poses.from_dlc_file(tmp_path / "fish.h5", fps=32))
    assert np.allclose(back.to_array(), arr, equal_nan=True, rtol=0, atol=1e-9)
    v = compute_velocity(ours["position"])
    assert v.shape == (1000, 2, 1, 15)
    # px/s: the median speed of the school, finite where both neighbouring frames are tracked.
    speed = np.sqrt((v.values[:, :, 0, :] ** 2).sum(axis=1))
    assert 10 < np.nanmedian(speed) < 2000
