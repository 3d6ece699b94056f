"""loopsfm: camera poses and a sparse 3D point cloud from video, with loop closing.

The same program as the ``loopsfm`` command, run in this process::

    import loopsfm
    report = loopsfm.reconstruct("clip.mp4", "out", threads=4)
    model = loopsfm.read_model("out")          # the largest model, out/sparse/0
    model.poses                                 # (n, 4, 4) camera-to-world
    loopsfm.evaluate("out/sparse/0", "groundtruth.txt")["ate_fraction_of_path"]

Options are the command line's flags, with ``_`` for ``-`` (``pairs="sequential"``,
``no_self_calibration=True``, ``export=["ply", "nerfstudio"]``): same names, same defaults,
same checks and messages (``loopsfm.help("reconstruct")`` lists them). A flag is given with
``True`` and left out with ``False`` or ``None``; a list is joined with commas.

Errors raise ``loopsfm.Error`` or one of its kinds (``InvalidArgument``, ``InputError``,
``StorageError``) with the program's message. Ctrl-C (``KeyboardInterrupt``) stops a run at its
next step; what it stored stays, and the same call goes on from there.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Union

import numpy as np

from . import _loopsfm
from ._loopsfm import Cancelled, Error, InputError, InvalidArgument, StorageError

# `map` and `help` stay out of `from loopsfm import *`: they would hide Python's own.
__all__ = [
    "Cancelled", "Error", "InputError", "InvalidArgument", "StorageError", "Model",
    "reconstruct", "extract", "match", "evaluate", "export", "synth", "read_model", "run",
    "version",
]
__version__ = "0.1.0"

PathLike = Union[str, "os.PathLike[str]"]
# progress(stage, done, total): a few times a second while a stage advances (total 0: unknown).
ProgressCallback = Callable[[str, int, int], None]


def _flag_arguments(options: Dict[str, Any]) -> List[str]:
    """Keyword options as command-line flags: threads=2 -> ["--threads", "2"]."""
    args: List[str] = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            args.append(flag)
        elif isinstance(value, (list, tuple)):
            args += [flag, ",".join(os.fspath(v) if isinstance(v, os.PathLike) else str(v)
                                    for v in value)]
        else:
            args += [flag, os.fspath(value) if isinstance(value, os.PathLike) else str(value)]
    return args


def run(*args: Any, progress: Optional[ProgressCallback] = None) -> Any:
    """Runs a loopsfm command line in this process, e.g. ``run("tracks", "-d", "db.db")``.

    Returns the command's report (a dict) for reconstruct, extract, match and eval; None for
    the others.
    """
    report = _loopsfm.run_command([os.fspath(a) if isinstance(a, os.PathLike) else str(a)
                                   for a in args], progress)
    return json.loads(report)


def reconstruct(input: PathLike, output: PathLike, *,
                progress: Optional[ProgressCallback] = None, **options: Any) -> Dict[str, Any]:
    """Video or image folder to camera path and sparse point cloud (``loopsfm reconstruct``).

    Writes what the program writes into ``output`` (database.db, sparse/<k>, points.ply,
    trajectory.txt, transforms.json, report.html, ...) and resumes from what it holds.
    Returns the run's report: frames, each model's summary and cameras, what was written,
    stage times.
    """
    return run("reconstruct", input, "-o", output, *_flag_arguments(options),
               progress=progress)


def extract(input: PathLike, database: PathLike, *,
            progress: Optional[ProgressCallback] = None, **options: Any) -> Dict[str, Any]:
    """Frames, keyframes and SIFT features into a database (``loopsfm extract``)."""
    return run("extract", input, "-d", database, *_flag_arguments(options), progress=progress)


def match(database: PathLike, *, progress: Optional[ProgressCallback] = None,
          **options: Any) -> Dict[str, Any]:
    """Pairs matched and verified in a database made by extract (``loopsfm match``)."""
    return run("match", "-d", database, *_flag_arguments(options), progress=progress)


def map(database: PathLike, output: PathLike, *,  # noqa: A001 (the stage's name)
        progress: Optional[ProgressCallback] = None, **options: Any) -> Dict[str, Any]:
    """Maps a database that extract and match filled, into ``output`` (``loopsfm map``):
    reconstruct's mapping and export alone, with its mapper and output options. Returns the
    report, as reconstruct does."""
    return run("map", "-d", database, "-o", output, *_flag_arguments(options),
               progress=progress)


def evaluate(model: PathLike, groundtruth: PathLike, **options: Any) -> Dict[str, Any]:
    """Scores a model folder or trajectory file against ground truth (``loopsfm eval``).

    Returns the metrics: ``fraction_registered``, ``ate_rmse``, ``ate_fraction_of_path``,
    rotation errors, loop gaps and per-frame errors (``frames``).
    """
    return run("eval", model, groundtruth, *_flag_arguments(options))


def export(output: PathLike, **options: Any) -> None:
    """Writes an earlier run's result again in other formats (``loopsfm export``)."""
    run("export", output, *_flag_arguments(options))


def synth(scene: str, output: PathLike, **options: Any) -> None:
    """Renders a synthetic scene with exact ground truth (``loopsfm synth``)."""
    run("synth", scene, "-o", output, *_flag_arguments(options))


def help(command: str = "") -> str:  # noqa: A001 (the program's --help, by name)
    """The program's ``--help`` text for a command (its options), or for the program."""
    return _loopsfm.help_text(command)


def version() -> str:
    """What ``loopsfm --version`` says, for this module."""
    return _loopsfm.version_text()


@dataclass
class Model:
    """A sparse model: registered frames (in image-id order, which for loopsfm is capture
    order) and 3D points. Poses are camera-to-world in COLMAP's (OpenCV's) camera axes: x right,
    y down, z forward."""

    names: List[str]
    image_ids: np.ndarray     # (n,) int64
    camera_ids: np.ndarray    # (n,) int64
    poses: np.ndarray         # (n, 4, 4) float64, camera-to-world
    intrinsics: np.ndarray    # (n, 3, 3) float64, each frame's calibration matrix K
    cameras: Dict[int, Dict[str, Any]]  # camera id -> model, width, height, params
    point_ids: np.ndarray     # (m,) int64
    xyz: np.ndarray           # (m, 3) float64
    rgb: np.ndarray           # (m, 3) uint8
    error: np.ndarray         # (m,) float64, mean reprojection error in pixels (-1: unknown)
    track_length: np.ndarray  # (m,) int64, frames that see the point
    obs_frame: np.ndarray     # (k,) int64: index into names / poses
    obs_point: np.ndarray     # (k,) int64: index into xyz
    obs_xy: np.ndarray        # (k, 2) float64: pixel (COLMAP's convention: 0.5 is a pixel's centre)

    @property
    def centres(self) -> np.ndarray:
        """(n, 3) camera centres in the world."""
        return self.poses[:, :3, 3]

    def __len__(self) -> int:
        return len(self.names)

    def pose(self, name: str) -> np.ndarray:
        """The camera-to-world pose of the frame of that name."""
        return self.poses[self.names.index(name)]


def read_model(path: PathLike) -> Model:
    """Reads a COLMAP model folder (binary or text; loopsfm's or COLMAP's).

    ``path`` may also be an output folder of reconstruct: its largest model, sparse/0, is
    read.
    """
    path = Path(path)
    if (path / "sparse" / "0").is_dir():
        path = path / "sparse" / "0"
    return Model(**_loopsfm.read_model(os.fspath(path)))
