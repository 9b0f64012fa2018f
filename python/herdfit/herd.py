"""The herd system (*Herds From Video*): simulate, fit, validate, ablate, import tracks, synth,
author. Each function is one library call; settings are the library's config keys, given as
keyword arguments or a ``config`` dict (an unknown key raises :class:`ConfigError` naming it)."""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Iterable, Optional, Sequence, Tuple, Union

import numpy as np

from . import _herdfit
from ._progress import resolve
from .errors import ConfigError
from .params import Params

__all__ = ["simulate", "fit", "validate", "ablate", "import_tracks", "synth", "author", "gradcheck", "defaults"]

PathLike = Union[str, os.PathLike]


def defaults(kind: str) -> Dict[str, Any]:
    """The library's defaults of the job ``kind`` (``fit``, ``validate``, ``ablate``,
    ``import_tracks``, ``synth``, ``author``): every key its settings may hold."""
    return _herdfit.job_defaults(kind)


def _job(kind: str, files: Dict[str, Any], config: Optional[Dict[str, Any]], kwargs: Dict[str, Any]) -> Dict[str, Any]:
    """The job dict: the library's defaults of ``kind``, with ``files`` and the keyword arguments
    that are the job's own keys set at the top and the others in its ``config`` (where the
    library refuses, by name, a key it does not know)."""
    job = defaults(kind)
    top = set(job)
    user = {k: _plain(v) for k, v in files.items() if v is not None}
    cfg = {k: _plain(v) for k, v in (config or {}).items()}
    for k, v in kwargs.items():
        if (k in top and k != "config") or "config" not in top:
            user[k] = _plain(v)
        else:
            cfg[k] = _plain(v)
    if cfg:
        user["config"] = cfg
    return _merge(job, user)


def _merge(base: Any, over: Any) -> Any:
    """``over`` laid on ``base``: dicts key by key (recursively), anything else replaced."""
    if isinstance(base, dict) and isinstance(over, dict):
        out = dict(base)
        for k, v in over.items():
            out[k] = _merge(base[k], v) if k in base else v
        return out
    return over


def _plain(v: Any) -> Any:
    """Paths as strings, ranges/tuples as lists, numpy scalars as numbers, recursively."""
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


def _frames(r: Any) -> Any:
    """``(a, b)`` or ``range(a, b)`` as the library's range ``{start, end}``."""
    if r is None or isinstance(r, dict):
        return r
    if isinstance(r, range):
        return {"start": r.start, "end": r.stop}
    a, b = r
    return {"start": int(a), "end": int(b)}


def simulate(
    params: Optional[Union[Params, PathLike]] = None,
    *,
    agents: Optional[int] = None,
    init: Optional[np.ndarray] = None,
    steps: int = 250,
    seed: int = 0,
    progress: Any = True,
    **config: Any,
) -> Tuple[np.ndarray, np.ndarray]:
    """Runs the herd model (eq. 2–6) from ``agents`` built-in agents or an ``init`` herd
    (``[n, 5]``: id, x, y, vx, vy in BL and BL/s). Returns ``(ids, frames)`` with ``frames`` of
    shape ``[steps + 1, agents, 5]`` (x, y, vx, vy, leader as 1/0); frame 0 is the start. The same
    numbers as ``herdfit simulate`` writes for the same seed. Other settings: ``fps``,
    ``speed_noise``, ``guidance`` (dx, dy), ``precision`` (``f32``/``f64``), ``device``
    (``cpu``/``gpu``: burn's wgpu backend, f32)."""
    if isinstance(params, (str, os.PathLike)):
        params = Params.load(params)
    text = None if params is None else params.to_json()
    cfg = {"steps": steps, "seed": seed, **{k: _plain(v) for k, v in config.items()}}
    arr = None if init is None else np.ascontiguousarray(init, dtype=np.float64)
    if agents is None and arr is None:
        raise ConfigError("herd: give agents=N or init=array", "herd")
    return _herdfit.simulate(text, agents, arr, cfg, resolve(progress))


def fit(
    clips: Union[PathLike, Sequence[PathLike]],
    out: PathLike,
    *,
    start: Optional[Union[Params, PathLike]] = None,
    frames: Any = None,
    config: Optional[Dict[str, Any]] = None,
    progress: Any = True,
    **kwargs: Any,
) -> Params:
    """Fits the 12 parameters to one clip or several (§6), writing the set to ``out`` (with its
    log and loss curve beside it) and returning it (its ``summary`` what the CLI prints; with
    ``zones``, the bundle is written and the summary returned). ``frames=(a, b)`` restricts the frames;
    other keywords are ``FitConfig`` keys (``epochs``, ``window``, ``seed``, ``lr``, …) or the
    job's (``eval_seeds``, ``uncertainty``, ``checkpoint``, …)."""
    if isinstance(clips, (str, os.PathLike)):
        clips = [clips]
    files: Dict[str, Any] = {"clips": [os.fspath(c) for c in clips], "out": os.fspath(out), "frames": _frames(frames)}
    if isinstance(start, Params):
        raise ConfigError("start: give the path of a saved parameter file (Params.save)", "start")
    files["start"] = None if start is None else os.fspath(start)
    summary = _herdfit.run_job("fit", _job("fit", files, config, kwargs), resolve(progress))
    if kwargs.get("zones") is not None:
        return summary  # type: ignore[return-value]
    p = Params.load(out)
    p.summary = summary
    return p


def validate(clip: PathLike, params: PathLike, out: PathLike, *, baseline: Optional[PathLike] = None,
             video: bool = False, config: Optional[Dict[str, Any]] = None, progress: Any = True, **kwargs: Any) -> Dict[str, Any]:
    """Held-out validation (§7.1) of the set ``params`` on ``clip``; writes the report folder
    ``out`` and returns its ``report.json`` as a dict."""
    files = {"clip": clip, "params": params, "out": out, "baseline": baseline, "video": video}
    _herdfit.run_job("validate", _job("validate", files, config, kwargs), resolve(progress))
    return _report(out, "report.json")


def ablate(clip: PathLike, out: PathLike, *, start: Optional[PathLike] = None, config: Optional[Dict[str, Any]] = None,
           progress: Any = True, **kwargs: Any) -> Dict[str, Any]:
    """The ablation study (each mechanism switched off, refitted and validated); writes ``out``
    and returns ``ablation.json`` as a dict."""
    files = {"clip": clip, "out": out, "start": start}
    _herdfit.run_job("ablate", _job("ablate", files, config, kwargs), resolve(progress))
    return _report(out, "ablation.json")


def import_tracks(tracks: Any, out: PathLike, *, fps: Optional[float] = None, config: Optional[Dict[str, Any]] = None,
                  **kwargs: Any) -> str:
    """Tracked animals → a clip folder ``out`` (fields on a grid). ``tracks`` is a file herdfit
    reads (tracks CSV, idtracker.ai ``.npy``) or a :class:`herdfit.tracks.Tracks`, DataFrame or
    movement dataset (written to a tracks file beside ``out`` first). Returns the summary."""
    from .tracks import Tracks, as_tracks

    if not isinstance(tracks, (str, os.PathLike)):
        t = tracks if isinstance(tracks, Tracks) else as_tracks(tracks, fps=fps)
        path = os.fspath(out).rstrip("/\\") + ".tracks.csv"
        t.save(path)
        tracks = path
    cfg = _merge(defaults("import_tracks"), {k: _plain(v) for k, v in (config or {}).items()})
    if fps is not None:
        kwargs["fps"] = fps
    for k, v in kwargs.items():
        if k not in cfg:
            raise ConfigError(f"import_tracks: unknown field `{k}`, expected one of {', '.join(cfg)}", k)
        cfg[k] = _plain(v)
    job = {"input": os.fspath(tracks), "out": os.fspath(out), "config": cfg}
    return _herdfit.run_job("import_tracks", job, None)


def synth(out: PathLike, *, config: Optional[Dict[str, Any]] = None, progress: Any = True, **kwargs: Any) -> str:
    """A synthetic clip with known parameters (ground truth) written to ``out``."""
    return _herdfit.run_job("synth", _job("synth", {"out": out}, config, kwargs), resolve(progress))


def author(scene: PathLike, out: PathLike, *, config: Optional[Dict[str, Any]] = None, progress: Any = True,
           **kwargs: Any) -> str:
    """Simulates an authored scene (``herdfit.scene/1``) into ``out``; returns the summary."""
    files = {"scene": scene, "out": out}
    return _herdfit.run_job("author", _job("author", files, config, kwargs), resolve(progress))


def _report(folder: PathLike, name: str) -> Dict[str, Any]:
    path = os.path.join(os.fspath(folder), name)
    if not os.path.exists(path):
        return {}
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def gradcheck(json_out: PathLike, *, agents: Optional[int] = None, params: Optional[PathLike] = None,
              record: Optional[PathLike] = None, replay: Optional[PathLike] = None, clip: Optional[PathLike] = None,
              config: Optional[Dict[str, Any]] = None, progress: Any = True, **kwargs: Any) -> Dict[str, Any]:
    """Autodiff against central differences for the 12 parameters (DESIGN §7); writes and
    returns the JSON report. ``agents`` (or the default scenario), ``record``/``replay`` the
    decisions; other keywords are ``GradcheckConfig`` keys (``steps``, ``h``, …)."""
    run = {"params": params, "herd": None if agents is None else {"agents": int(agents)}, "record": record,
           "replay": replay}
    files = {"run": {k: _plain(v) for k, v in run.items() if v is not None}, "json": json_out, "clip": clip}
    _herdfit.run_job("gradcheck", _job("gradcheck", files, config, kwargs), resolve(progress))
    with open(json_out, encoding="utf-8") as f:
        return json.load(f)
