"""Clip fields (``herdfit.clip/1``): per frame and cell, density (agents/BL²), mean velocity
(BL/s), direction variance (rad²), plus the obstacle mask and ``clip.json``'s meta."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, Optional, Union

import numpy as np

from . import _herdfit

__all__ = ["Clip"]


@dataclass
class Clip:
    """A clip's fields as numpy arrays: ``density [F, ny, nx]``, ``velocity [F, ny, nx, 2]``,
    ``dir_variance [F, ny, nx]`` (float32), ``obstacles [ny, nx]`` (uint8) and ``meta`` (the
    ``clip.json`` dict: fps, cell_size, nx, ny, frames, speed, …)."""

    density: np.ndarray
    velocity: np.ndarray
    dir_variance: np.ndarray
    obstacles: np.ndarray
    meta: Dict[str, Any] = field(default_factory=dict)

    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "Clip":
        """Reads a clip folder (``fields.npz`` + ``clip.json``)."""
        meta, d, v, dv, o = _herdfit.load_clip(os.fspath(path))
        return cls(d, v, dv, o, json.loads(meta))

    @classmethod
    def from_arrays(
        cls,
        density: np.ndarray,
        velocity: np.ndarray,
        dir_variance: Optional[np.ndarray] = None,
        obstacles: Optional[np.ndarray] = None,
        *,
        fps: float,
        cell_size: float,
        speed_mean: float = 1.0,
        speed_std: float = 0.1,
        density_table: Optional[list] = None,
        provenance: Any = None,
    ) -> "Clip":
        """A clip built from arrays (``dir_variance`` zeros and no obstacles unless given)."""
        density = np.ascontiguousarray(density, dtype=np.float32)
        f, ny, nx = density.shape
        dv = np.zeros_like(density) if dir_variance is None else dir_variance
        ob = np.zeros((ny, nx), np.uint8) if obstacles is None else obstacles
        meta = {
            "schema": "herdfit.clip/1",
            "fps": float(fps),
            "cell_size": float(cell_size),
            "nx": nx,
            "ny": ny,
            "frames": f,
            "speed": {"mean": speed_mean, "std": speed_std, "density_table": density_table or []},
            "provenance": provenance if provenance is not None else {"source": "python"},
        }
        return cls(density, np.asarray(velocity, np.float32), np.asarray(dv, np.float32), np.asarray(ob, np.uint8), meta)

    def save(self, path: Union[str, os.PathLike]) -> None:
        """Writes the clip folder (validated first; atomically)."""
        _herdfit.save_clip(
            os.fspath(path),
            json.dumps(self.meta),
            np.ascontiguousarray(self.density, np.float32),
            np.ascontiguousarray(self.velocity, np.float32),
            np.ascontiguousarray(self.dir_variance, np.float32),
            np.ascontiguousarray(self.obstacles, np.uint8),
        )

    @property
    def frames(self) -> int:
        """Number of frames."""
        return int(self.density.shape[0])
