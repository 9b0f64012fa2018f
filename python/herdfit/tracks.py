"""Tracked animals (``herdfit.tracks/1``: CSV + JSON sidecar) as columns, numpy arrays, pandas
DataFrames and the ``movement`` package's xarray dataset; TRex per-animal ``.npz`` and
idtracker.ai ``trajectories.h5``/``.npy`` read directly."""

from __future__ import annotations

import glob
import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _herdfit
from .errors import ConfigError, FileError

__all__ = ["Tracks", "read_tracks", "as_tracks", "to_movement", "from_movement", "read_trex_npz", "read_idtracker"]

PathLike = Union[str, os.PathLike]


@dataclass
class Tracks:
    """One row per animal and frame: ``frame``, ``time`` (s), ``id``, ``pos [n, dimension]``,
    optional ``vel``; ``units`` is ``"BL"``, ``"m"`` or ``"px"`` (y down)."""

    frame: np.ndarray
    time: np.ndarray
    id: np.ndarray
    pos: np.ndarray
    fps: float
    units: str = "px"
    vel: Optional[np.ndarray] = None
    provenance: Any = None
    role: Optional[List[str]] = field(default=None, repr=False)

    @property
    def dimension(self) -> int:
        """2 or 3 (the columns of ``pos``)."""
        return int(self.pos.shape[1])

    def save(self, path: PathLike) -> None:
        """Writes the tracks CSV and its sidecar (rows sorted by frame and id; atomically)."""
        meta = {"schema": "herdfit.tracks/1", "units": self.units, "fps": float(self.fps),
                "dimension": self.dimension, "provenance": self.provenance}
        vel = None if self.vel is None else np.ascontiguousarray(self.vel, np.float64)
        _herdfit.tracks_save(os.fspath(path), json.dumps(meta), np.ascontiguousarray(self.frame, np.uint64),
                             np.ascontiguousarray(self.time, np.float64), np.ascontiguousarray(self.id, np.uint64),
                             np.ascontiguousarray(self.pos, np.float64), vel)

    def to_dataframe(self) -> Any:
        """A pandas DataFrame with columns frame, time, id, x, y[, z][, vx, vy[, vz]]."""
        import pandas as pd

        axes = "xyz"[: self.dimension]
        cols: Dict[str, Any] = {"frame": self.frame, "time": self.time, "id": self.id}
        cols.update({a: self.pos[:, k] for k, a in enumerate(axes)})
        if self.vel is not None:
            cols.update({"v" + a: self.vel[:, k] for k, a in enumerate(axes)})
        return pd.DataFrame(cols)

    def to_array(self) -> np.ndarray:
        """Positions as ``[frames, individuals, dimension]`` (NaN where an animal is missing),
        frames from the first to the last, individuals in sorted id order."""
        ids = np.unique(self.id)
        f0 = int(self.frame.min())
        out = np.full((int(self.frame.max()) - f0 + 1, len(ids), self.dimension), np.nan)
        out[self.frame.astype(np.int64) - f0, np.searchsorted(ids, self.id)] = self.pos
        return out

    @classmethod
    def from_array(cls, positions: np.ndarray, fps: float, units: str = "px", ids: Optional[Sequence[int]] = None,
                   first_frame: int = 0, provenance: Any = None) -> "Tracks":
        """Tracks from ``[frames, individuals, 2 or 3]`` positions; NaN rows are missing."""
        p = np.asarray(positions, dtype=np.float64)
        if p.ndim != 3 or p.shape[2] not in (2, 3):
            raise ConfigError(f"positions: shape {p.shape}; [frames, individuals, 2 or 3] expected", "positions")
        f, n, _ = p.shape
        ids_arr = np.arange(n, dtype=np.uint64) if ids is None else np.asarray(ids, dtype=np.uint64)
        fr, ind = np.meshgrid(np.arange(f), np.arange(n), indexing="ij")
        ok = np.isfinite(p).all(axis=2)
        frame = (fr[ok] + first_frame).astype(np.uint64)
        return cls(frame, frame / float(fps), ids_arr[ind[ok]], p[ok], float(fps), units, provenance=provenance)

    @classmethod
    def from_dataframe(cls, df: Any, fps: float, units: str = "px", provenance: Any = None) -> "Tracks":
        """Tracks from a DataFrame with columns frame, id, x, y[, z] (``time`` optional)."""
        for c in ("frame", "id", "x", "y"):
            if c not in df.columns:
                raise ConfigError(f"{c}: missing column (frame, id, x, y[, z] needed)", c)
        axes = ["x", "y"] + (["z"] if "z" in df.columns else [])
        df = df.dropna(subset=axes)
        frame = df["frame"].to_numpy().astype(np.uint64)
        time = df["time"].to_numpy(np.float64) if "time" in df.columns else frame / float(fps)
        return cls(frame, time, df["id"].to_numpy().astype(np.uint64), df[axes].to_numpy(np.float64), float(fps), units,
                   provenance=provenance)


def read_tracks(path: PathLike) -> Tracks:
    """Reads any tracks file herdfit reads (tracks CSV + sidecar, idtracker.ai ``.npy``, …)."""
    meta, frame, time, ids, pos, vel, role = _herdfit.tracks_load(os.fspath(path))
    m = json.loads(meta)
    d = int(m["dimension"])
    return Tracks(frame, time, ids, pos[:, :d], m["fps"], m["units"], None if vel is None else vel[:, :d],
                  m.get("provenance"), role)


def as_tracks(obj: Any, fps: Optional[float] = None, units: str = "px") -> Tracks:
    """A :class:`Tracks` from a Tracks, a file path, a DataFrame, a ``[frames, individuals, d]``
    array or a movement dataset."""
    if isinstance(obj, Tracks):
        return obj
    if isinstance(obj, (str, os.PathLike)):
        return read_tracks(obj)
    if hasattr(obj, "data_vars") and "position" in getattr(obj, "data_vars", {}):
        return from_movement(obj)
    if fps is None:
        raise ConfigError("fps: give the frame rate of the tracks", "fps")
    if hasattr(obj, "columns"):
        return Tracks.from_dataframe(obj, fps, units)
    return Tracks.from_array(np.asarray(obj), fps, units)


def to_movement(tracks: Tracks, keypoint: str = "centroid") -> Any:
    """The movement package's poses dataset: ``position`` with dims (time, space, keypoints,
    individuals) and ``confidence`` (time, keypoints, individuals; NaN where missing); time in
    seconds, individuals ``id_<n>``. Needs xarray."""
    import xarray as xr

    arr = tracks.to_array()  # [frames, individuals, d]
    ids = np.unique(tracks.id)
    f0 = int(tracks.frame.min())
    time = (np.arange(arr.shape[0]) + f0) / float(tracks.fps)
    space = ["x", "y", "z"][: tracks.dimension]
    pos = arr.transpose(0, 2, 1)[:, :, None, :]  # time, space, keypoints, individuals
    conf = np.where(np.isfinite(arr).all(axis=2), 1.0, np.nan)[:, None, :]
    coords = {"time": time, "space": space, "keypoints": [keypoint], "individuals": [f"id_{i}" for i in ids]}
    return xr.Dataset(
        {"position": (("time", "space", "keypoints", "individuals"), pos),
         "confidence": (("time", "keypoints", "individuals"), conf)},
        coords=coords,
        attrs={"fps": float(tracks.fps), "time_unit": "seconds", "source_software": "herdfit", "ds_type": "poses",
               "units": tracks.units},
    )


def from_movement(ds: Any, keypoint: Optional[str] = None, units: Optional[str] = None) -> Tracks:
    """Tracks from a movement dataset (``position`` with dims time, space, keypoints,
    individuals): one keypoint (``keypoint``, or the mean over all keypoints)."""
    pos = ds["position"]
    if "keypoints" in pos.dims:
        pos = pos.sel(keypoints=keypoint) if keypoint is not None else pos.mean("keypoints", skipna=False)
    pos = pos.transpose("time", "individuals", "space")
    fps = ds.attrs.get("fps")
    t = np.asarray(ds["time"].values, dtype=float)
    if ds.attrs.get("time_unit", "frames") == "seconds":
        if fps is None:
            fps = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0
        first = int(round(t[0] * fps))
    else:
        first = int(t[0])
        fps = fps or 1.0
    names = [str(x) for x in ds["individuals"].values]
    ids = [int(n.split("_")[-1]) if n.split("_")[-1].isdigit() else i for i, n in enumerate(names)]
    return Tracks.from_array(pos.values, float(fps), units or ds.attrs.get("units", "px"), ids=ids, first_frame=first,
                             provenance={"source": "movement", "source_software": ds.attrs.get("source_software")})


def read_trex_npz(paths: Union[PathLike, Sequence[PathLike]], fps: Optional[float] = None, units: str = "px") -> Tracks:
    """TRex's per-animal exports (``<video>_<fish|id>N.npz`` with arrays X, Y, frame and, when
    exported, time): a folder or glob pattern or a list of files; missing frames (inf/NaN) are
    dropped. ``fps`` from the time column when not given."""
    if isinstance(paths, (str, os.PathLike)):
        p = os.fspath(paths)
        files = sorted(glob.glob(os.path.join(p, "*.npz"))) if os.path.isdir(p) else sorted(glob.glob(p))
    else:
        files = [os.fspath(x) for x in paths]
    if not files:
        raise FileError(f"{paths}: no .npz files", os.fspath(paths) if isinstance(paths, (str, os.PathLike)) else None)
    cols: Dict[str, List[np.ndarray]] = {"frame": [], "time": [], "id": [], "pos": []}
    for i, f in enumerate(files):
        with np.load(f) as z:
            for k in ("X", "Y", "frame"):
                if k not in z:
                    raise FileError(f"{f}: no array '{k}' (a TRex per-animal .npz has X, Y, frame)", f)
            x, y, fr = np.asarray(z["X"], float), np.asarray(z["Y"], float), np.asarray(z["frame"], float)
            tm = np.asarray(z["time"], float) if "time" in z else None
        ok = np.isfinite(x) & np.isfinite(y) & np.isfinite(fr)
        if fps is None and tm is not None and ok.sum() > 1:
            dt = np.diff(tm[ok]) / np.diff(fr[ok])
            fps = float(1.0 / np.median(dt[np.isfinite(dt) & (dt > 0)]))
        cols["frame"].append(fr[ok].astype(np.uint64))
        cols["id"].append(np.full(ok.sum(), i, np.uint64))
        cols["pos"].append(np.stack([x[ok], y[ok]], axis=1))
    if fps is None:
        raise ConfigError("fps: the .npz files have no time column; give fps", "fps")
    frame = np.concatenate(cols["frame"])
    return Tracks(frame, frame / fps, np.concatenate(cols["id"]), np.concatenate(cols["pos"]), float(fps), units,
                  provenance={"source": "TRex", "files": [os.path.basename(f) for f in files]})


def read_idtracker(path: PathLike, fps: Optional[float] = None) -> Tracks:
    """idtracker.ai's trajectories: ``trajectories.h5`` (needs h5py; dataset ``trajectories``
    ``[frames, individuals, 2]``, attribute or dataset ``frames_per_second``) or the pickled
    ``.npy`` dict (``trajectories``, ``frames_per_second``). Pixels, y down; NaN gaps dropped."""
    p = os.fspath(path)
    if p.endswith((".h5", ".hdf5")):
        try:
            import h5py
        except ImportError as e:
            raise FileError(f"{p}: reading .h5 needs h5py (pip install h5py)", p) from e
        with h5py.File(p, "r") as h:
            if "trajectories" not in h:
                raise FileError(f"{p}: no dataset 'trajectories'", p)
            traj = np.asarray(h["trajectories"], dtype=float)
            f = h.attrs.get("frames_per_second", h["frames_per_second"][()] if "frames_per_second" in h else None)
    else:
        d = np.load(p, allow_pickle=True).item()
        traj, f = np.asarray(d["trajectories"], dtype=float), d.get("frames_per_second")
    fps = fps if fps is not None else (float(np.asarray(f)) if f is not None else None)
    if fps is None:
        raise ConfigError("fps: the file has no frames_per_second; give fps", "fps")
    return Tracks.from_array(traj, fps, "px", provenance={"source": "idtracker.ai", "file": os.path.basename(p)})
