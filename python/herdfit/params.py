"""Parameter sets (``herdfit.params/1``): the 12 normalised force parameters of the herd model
(paper eq. 3–5: weight, radial and angular of cohesion, avoidance, alignment, obstacle), the fixed
constants, the speed model (eq. 6) and what the fit recorded."""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Mapping, Optional, Union

import numpy as np

from . import _herdfit

__all__ = ["Params", "names"]


def names() -> list:
    """The 12 parameters' names (``cohesion.weight``, …) in vector order."""
    return list(_herdfit.params_names())


class Params:
    """A parameter set. ``Params()`` is the built-in set; :meth:`load` reads a file,
    :meth:`from_json` parses text; the JSON round-trips unchanged."""

    def __init__(self, data: Optional[Mapping[str, Any]] = None) -> None:
        text = _herdfit.params_default() if data is None else json.dumps(dict(data))
        _herdfit.params_vector(text)  # validated by herdfit (unknown keys, ranges) before it is kept
        self._data: Dict[str, Any] = json.loads(text)
        #: What the fit printed, on a set returned by :func:`herdfit.fit`.
        self.summary: Optional[str] = None

    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "Params":
        """Reads and validates a parameter file."""
        _herdfit.params_load(os.fspath(path))
        with open(path, encoding="utf-8") as f:
            return cls(json.load(f))

    @classmethod
    def from_json(cls, text: str) -> "Params":
        """Parses and validates JSON text."""
        return cls(json.loads(text))

    def to_json(self) -> str:
        """The set as JSON text."""
        return json.dumps(self._data, indent=2)

    def to_dict(self) -> Dict[str, Any]:
        """A copy of the set as a dict (the JSON's structure)."""
        return json.loads(json.dumps(self._data))

    def save(self, path: Union[str, os.PathLike]) -> None:
        """Writes the set as herdfit does (validated, with its physical values, atomically)."""
        _herdfit.params_save(json.dumps(self._data), os.fspath(path))

    @property
    def vector(self) -> np.ndarray:
        """The 12 normalised values in [0, 1] (order of :func:`names`)."""
        return np.array(_herdfit.params_vector(json.dumps(self._data)))

    @property
    def values(self) -> Dict[str, float]:
        """The 12 normalised values by name."""
        return dict(zip(names(), self.vector.tolist()))

    def with_values(self, values: Union[Mapping[str, float], np.ndarray, list]) -> "Params":
        """A copy with some (a dict by name) or all 12 values replaced, clamped to their ranges."""
        v = self.vector
        if isinstance(values, Mapping):
            idx = {n: i for i, n in enumerate(names())}
            for k, x in values.items():
                if k not in idx:
                    from .errors import ConfigError

                    raise ConfigError(f"{k}: not a parameter (one of {', '.join(idx)})", k)
                v[idx[k]] = float(x)
        else:
            v = np.asarray(values, dtype=float)
        return Params(json.loads(_herdfit.params_with_vector(json.dumps(self._data), [float(x) for x in v])))

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Params) and self._data == other._data

    def __repr__(self) -> str:
        vals = ", ".join(f"{k}={v:.3g}" for k, v in self.values.items())
        return f"Params({vals})"
