"""Round trips: clip arrays ↔ files, parameter sets ↔ JSON, tracks ↔ files and the movement
dataset, and the real fish of trajectorytools."""

import json

import numpy as np
import pytest

import herdfit
from herdfit import tracks as ht


def test_version_and_features():
    assert herdfit.__version__ == "0.1.0"
    assert set(herdfit.features()) <= {"video", "gpu"}
    assert "gpu" in herdfit.features()  # the package is always built with the GPU backend
    assert ("video" in herdfit.missing_features()) == ("video" not in herdfit.features())


def test_clip_arrays_round_trip_through_files(clip_dir, tmp_path):
    c = herdfit.Clip.load(clip_dir)
    assert c.density.shape == (20, 6, 6) and c.velocity.shape == (20, 6, 6, 2)
    assert c.density.dtype == np.float32 and c.obstacles.dtype == np.uint8
    # Density (agents/BL²) × cell area sums to the agents inside the 12 × 12 BL grid, frame by
    # frame, as synth's own trajectories say.
    counts = c.density.sum(axis=(1, 2)) * c.meta["cell_size"] ** 2
    t = np.genfromtxt(clip_dir / "trajectories.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    inside = (t["x"] >= 0) & (t["x"] < 12) & (t["y"] >= 0) & (t["y"] < 12)
    truth = np.bincount(t["frame"][inside], minlength=20)[:20]
    assert np.array_equal(np.round(counts), truth) and np.all(np.abs(counts - truth) < 1e-3)
    assert 0 < truth.min() and truth.max() <= 60
    c.save(tmp_path / "copy")
    d = herdfit.Clip.load(tmp_path / "copy")
    for k in ("density", "velocity", "dir_variance", "obstacles"):
        assert np.array_equal(getattr(c, k), getattr(d, k)), k
    assert d.meta == c.meta


def test_clip_built_from_arrays_saves_and_loads(tmp_path):
    dens = np.full((3, 2, 4), 0.25, np.float32)
    vel = np.zeros((3, 2, 4, 2), np.float32)
    vel[..., 0] = 1.0
    c = herdfit.Clip.from_arrays(dens, vel, fps=10, cell_size=2.0)
    c.save(tmp_path / "c")
    d = herdfit.Clip.load(tmp_path / "c")
    assert d.frames == 3 and d.meta["nx"] == 4 and d.meta["ny"] == 2
    assert np.array_equal(d.velocity, vel)
    # numpy reads the npz without herdfit.
    z = np.load(tmp_path / "c" / "fields.npz")
    assert np.array_equal(z["density"], dens)


def test_params_round_trip_json_and_the_files_bytes(tmp_path):
    p = herdfit.Params()
    q = herdfit.Params.from_json(p.to_json())
    assert q == p and len(q.values) == 12
    p.save(tmp_path / "a.json")
    b = herdfit.Params.load(tmp_path / "a.json")
    b.save(tmp_path / "b.json")
    # What the library writes is written again byte for byte.
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()
    r = p.with_values({"cohesion.weight": 0.25})
    assert r.values["cohesion.weight"] == 0.25
    assert json.loads(r.to_json())["forces"]["cohesion"]["weight"] == 0.25


def test_tracks_file_and_movement_round_trip_on_the_real_fish(fish_npy, tmp_path):
    fish = ht.read_idtracker(fish_npy)
    arr = fish.to_array()
    assert arr.shape == (1000, 15, 2) and fish.fps == 32
    ds = herdfit.to_movement(fish)
    assert ds["position"].dims == ("time", "space", "keypoints", "individuals")
    assert ds["position"].shape == (1000, 2, 1, 15)
    back = herdfit.from_movement(ds)
    assert np.array_equal(back.to_array(), arr, equal_nan=True)
    assert np.array_equal(back.id, fish.id) and np.array_equal(back.frame, fish.frame)
    fish.save(tmp_path / "fish.csv")
    again = herdfit.read_tracks(tmp_path / "fish.csv")
    assert again.units == "px" and again.fps == 32
    assert np.array_equal(again.to_array(), arr, equal_nan=True)
    df = again.to_dataframe()
    assert list(df.columns) == ["frame", "time", "id", "x", "y"] and len(df) == len(fish.frame)
    from_df = ht.Tracks.from_dataframe(df, fps=32)
    assert np.array_equal(from_df.to_array(), arr, equal_nan=True)


def test_trex_npz_files_read_as_one_animal_each(tmp_path):
    for i in range(3):
        x = np.arange(10.0) + i
        x[4] = np.inf  # TRex writes inf where the animal was lost
        np.savez(tmp_path / f"video_fish{i}.npz", X=x, Y=np.zeros(10), frame=np.arange(10.0), time=np.arange(10) / 25)
    t = ht.read_trex_npz(tmp_path)
    assert t.fps == pytest.approx(25) and sorted(set(t.id.tolist())) == [0, 1, 2]
    assert len(t.frame) == 27
    arr = t.to_array()
    assert np.isnan(arr[4]).all() and arr[5, 2, 0] == 7.0


def test_idtracker_h5_reads_like_the_npy(fish_npy, tmp_path):
    h5py = pytest.importorskip("h5py")
    d = np.load(fish_npy, allow_pickle=True).item()
    with h5py.File(tmp_path / "trajectories.h5", "w") as h:
        h["trajectories"] = d["trajectories"]
        h.attrs["frames_per_second"] = d["frames_per_second"]
    a = ht.read_idtracker(tmp_path / "trajectories.h5")
    b = ht.read_idtracker(fish_npy)
    assert np.array_equal(a.to_array(), b.to_array(), equal_nan=True)
