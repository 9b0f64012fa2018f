"""The other systems' entry points: crowds (Lee et al.), line-formation flocks (Klotsman & Tal),
the 3D lift of 2D bird tracks (Lin) and the glTF export. Settings are the library's config keys
(``LearnConfig``, ``SimConfig``, ``AnimateConfig``, ``LiftConfig``, ``GltfConfig``)."""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Optional, Sequence, Tuple, Union

from . import _herdfit
from ._progress import resolve
from .herd import _merge, _plain
from .tracks import Tracks

PathLike = Union[str, os.PathLike]


def _tracks(cols: Tuple[Any, ...]) -> Tracks:
    meta, frame, time, ids, pos, vel, role = cols
    m = json.loads(meta)
    d = int(m["dimension"])
    return Tracks(frame, time, ids, pos[:, :d], m["fps"], m["units"], None if vel is None else vel[:, :d],
                  m.get("provenance"), role)


def _path(x: Optional[PathLike]) -> Optional[str]:
    return None if x is None else os.fspath(x)


class crowd:
    """Crowds from tracks (Lee et al.): :meth:`learn` a model, :meth:`simulate` it."""

    @staticmethod
    def learn(inputs: Union[PathLike, Sequence[PathLike]], out: PathLike, *, preset: str = "paper",
              progress: Any = True, **config: Any) -> Dict[str, Any]:
        """Learns a crowd model (§4–§6.1) from tracks files (ETH/UCY text or herdfit tracks) and
        writes it to ``out``; ``preset`` ``paper`` (Table 1) or ``pedestrians``; returns the model
        as a dict."""
        if isinstance(inputs, (str, os.PathLike)):
            inputs = [inputs]
        cfg = _merge(_herdfit.crowd_defaults(preset), {k: _plain(v) for k, v in config.items()})
        _herdfit.crowd_learn([os.fspath(p) for p in inputs], os.fspath(out), cfg, resolve(progress))
        with open(out, encoding="utf-8") as f:
            return json.load(f)

    @staticmethod
    def simulate(model: PathLike, *, entries: Optional[PathLike] = None, layout: Optional[PathLike] = None,
                 out: Optional[PathLike] = None, progress: Any = True, **config: Any) -> Tracks:
        """Walks the model's agents in where and when the ``entries`` tracks' pedestrians entered,
        or from a layout's spawns; returns the simulated tracks (and writes them to ``out``)."""
        cols = _herdfit.crowd_simulate(os.fspath(model), _path(entries), _path(layout),
                                       {k: _plain(v) for k, v in config.items()}, _path(out), resolve(progress))
        return _tracks(cols)


class flock:
    """Line-formation flocks (Klotsman & Tal)."""

    @staticmethod
    def animate(shape: PathLike, out: PathLike, *, progress: Any = True, **config: Any) -> Dict[str, Any]:
        """Animates a shape (``herdfit.flock-shape/1``) with ``birds``, ``frames``, ``seed``, …
        into the folder ``out`` (3D tracks, savings, report, plots); returns the report."""
        text = _herdfit.flock_animate(os.fspath(shape), os.fspath(out), {k: _plain(v) for k, v in config.items()},
                                      resolve(progress))
        return json.loads(text)


class lift:
    """3D flight from the 2D tracks of one static camera (Lin)."""

    @staticmethod
    def run(tracks: PathLike, camera: PathLike, *, out: Optional[PathLike] = None, progress: Any = True,
            **config: Any) -> Tuple[Tracks, Dict[str, Any]]:
        """Lifts pixel tracks seen by ``camera`` (``herdfit.camera/1``) to 3D (metres); returns
        the 3D tracks and the report (with its "to be trusted" checks). ``v_target``, ``d_near``,
        ``d_far``, ``method``, … are ``LiftConfig`` keys."""
        cols, report = _herdfit.lift_run(os.fspath(tracks), os.fspath(camera),
                                         {k: _plain(v) for k, v in config.items()}, _path(out), resolve(progress))
        return _tracks(cols), json.loads(report)


def export_gltf(tracks: PathLike, out: PathLike, **config: Any) -> Dict[str, Any]:
    """Writes tracks (2D or 3D) as a glTF binary ``.glb``, one node per animal; returns what it
    wrote (nodes, keyframes, duration, bytes)."""
    return json.loads(_herdfit.export_gltf(os.fspath(tracks), os.fspath(out), {k: _plain(v) for k, v in config.items()}))
