"""herdfit: learn how animal groups move from video and tracked data, from Python.

The Rust library's entry points with numpy arrays in and out::

    import herdfit
    ids, frames = herdfit.simulate(agents=200, steps=100, seed=1)   # [101, 200, 5]
    clip = herdfit.Clip.load("sheep/")                               # fields as arrays
    p = herdfit.fit("sheep/", "sheep-params.json", frames=(0, 100))  # a Params
    tracks = herdfit.tracks.read_idtracker("trajectories.npy")       # or TRex, movement

Errors raise :class:`HerdfitError` (:class:`ConfigError` a ``ValueError`` naming the key,
:class:`FileError` an ``OSError``); long calls show tqdm bars (``progress=``) and stop on Ctrl-C.
"""

from __future__ import annotations

from . import _herdfit, tracks
from ._herdfit import __version__
from .clip import Clip
from .errors import ConfigError, FileError, HerdfitError
from .herd import ablate, author, defaults, fit, gradcheck, import_tracks, simulate, synth, validate
from .params import Params
from .systems import crowd, export_gltf, flock, lift
from .tracks import Tracks, from_movement, read_tracks, to_movement

__all__ = [
    "__version__", "features", "missing_features", "Clip", "Params", "Tracks", "simulate", "fit", "validate",
    "ablate", "import_tracks", "synth", "author", "gradcheck", "defaults", "read_tracks", "to_movement", "from_movement",
    "tracks", "crowd", "flock", "lift", "export_gltf", "HerdfitError", "ConfigError", "FileError",
]


def features() -> list:
    """The Cargo features this build has (``video``: OpenCV video extraction and rendering;
    ``gpu``: burn's wgpu backend, ``device="gpu"``)."""
    return list(_herdfit.features())


def missing_features() -> dict:
    """What this build lacks and how to get it (empty when nothing is missing)."""
    missing = {}
    if "video" not in features():
        missing["video"] = (
            "built without OpenCV: install libopencv-dev clang libclang-dev (scripts/setup-debian.sh) "
            "and reinstall with `pip install ./python`"
        )
    return missing
