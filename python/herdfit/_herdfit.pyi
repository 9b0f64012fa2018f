"""Type stubs of the native module (python/src/lib.rs); use the documented wrappers instead."""

from typing import Any, Dict, List, Optional, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

def features() -> List[str]: ...
def load_clip(
    path: str,
) -> Tuple[str, npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.uint8]]: ...
def save_clip(
    path: str,
    meta: str,
    density: npt.NDArray[np.float32],
    velocity: npt.NDArray[np.float32],
    dir_variance: npt.NDArray[np.float32],
    obstacles: npt.NDArray[np.uint8],
) -> None: ...
def params_default() -> str: ...
def params_names() -> List[str]: ...
def params_load(path: str) -> str: ...
def params_save(text: str, path: str) -> None: ...
def params_vector(text: str) -> List[float]: ...
def params_with_vector(text: str, values: List[float]) -> str: ...
def simulate(
    params: Optional[str],
    agents: Optional[int],
    init: Optional[npt.NDArray[np.float64]],
    config: Dict[str, Any],
    progress: Any = None,
) -> Tuple[npt.NDArray[np.uint64], npt.NDArray[np.float64]]: ...
def tracks_load(
    path: str,
) -> Tuple[
    str,
    npt.NDArray[np.uint64],
    npt.NDArray[np.float64],
    npt.NDArray[np.uint64],
    npt.NDArray[np.float64],
    Optional[npt.NDArray[np.float64]],
    Optional[List[str]],
]: ...
def tracks_save(
    path: str,
    meta: str,
    frame: npt.NDArray[np.uint64],
    time: npt.NDArray[np.float64],
    id: npt.NDArray[np.uint64],
    pos: npt.NDArray[np.float64],
    vel: Optional[npt.NDArray[np.float64]] = None,
) -> None: ...
def run_job(kind: str, job: Dict[str, Any], progress: Any = None) -> str: ...
def job_defaults(kind: str) -> Dict[str, Any]: ...
def crowd_defaults(preset: str) -> Dict[str, Any]: ...
def crowd_learn(inputs: List[str], out: str, config: Dict[str, Any], progress: Any = None) -> None: ...
def crowd_simulate(
    model: str,
    entries: Optional[str],
    layout: Optional[str],
    config: Dict[str, Any],
    out: Optional[str] = None,
    progress: Any = None,
) -> Tuple[Any, ...]: ...
def flock_animate(shape: str, out: str, config: Dict[str, Any], progress: Any = None) -> str: ...
def lift_run(
    tracks: str, camera: str, config: Dict[str, Any], out: Optional[str] = None, progress: Any = None
) -> Tuple[Tuple[Any, ...], str]: ...
def export_gltf(tracks: str, out: str, config: Dict[str, Any]) -> str: ...
