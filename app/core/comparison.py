"""Fixed/moving comparison: a registration's fixed image beside the moving one.

The *moving* image is the scene's volume seen through its warp chain; the *fixed*
image is a second volume on its own grid (any size, spacing, orientation), sampled at
the same world point (mm) without warps, so a fixed image on another grid lines up
physically. Three looks (``show``), the same in slices and in 3D:

* ``"checkerboard"``: cells of ``checker_mm`` alternate which image is shown. The cells
  are cubes of the world grid anchored at world (0, 0, 0): cell ``floor(p / size)``
  shows the fixed image where the sum of its three indices is odd, the moving one
  where it is even (:func:`checker_fixed`). A slice shows the plane's cut through them.
* ``"difference"``: moving minus fixed (slices: red where moving is brighter, blue
  where darker; 3D: ``|moving - fixed|`` through the transfer function).
* ``"blend"``: ``(1 - blend) * moving + blend * fixed`` (0 = moving, 1 = fixed).

:class:`Comparison` holds the fixed volume and these settings; ``Scene(fixed=...)``
builds one (:attr:`voxwarp.scene.Scene.comparison`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from voxwarp.core.volume import Volume
from voxwarp.errors import SceneError

#: the comparison looks, in the order of the CLI's choices
COMPARE_SHOWS: tuple[str, ...] = ("checkerboard", "difference", "blend")
#: the default checker cell: this many cells across the fixed image's longest side
CELLS_ACROSS = 8


def checker_fixed(points: np.ndarray, size_mm: float) -> np.ndarray:
    """Whether each world point (``(..., 3)`` mm) lies in a checker cell that shows the
    fixed image (odd sum of ``floor(p / size_mm)``); as the raycaster decides."""
    cells = np.floor(np.asarray(points, np.float64) / float(size_mm)).astype(np.int64)
    return (cells.sum(axis=-1) % 2) == 1


def default_checker_mm(volume: Volume) -> float:
    """A checker cell of about 1/:data:`CELLS_ACROSS` of ``volume``'s longest side,
    rounded to two significant digits (mm)."""
    lo, hi = volume.bounds
    side = float(np.max(np.asarray(hi) - np.asarray(lo))) / CELLS_ACROSS
    if not side > 0:
        return 1.0
    digits = 1 - math.floor(math.log10(side))
    return float(round(side, digits))


@dataclasses.dataclass(frozen=True)
class Comparison:
    """A fixed image and how it is compared with the moving (deformed) volume.

    Attributes
    ----------
    fixed
        The fixed :class:`~voxwarp.core.volume.Volume` (sampled at world points).
    show
        ``"checkerboard"`` (default), ``"difference"`` or ``"blend"``.
    blend
        Weight of the fixed image for ``"blend"``, in [0, 1] (default 0.5).
    checker_mm
        Checker cell size in mm; None: :func:`default_checker_mm` of the fixed image.
    """

    fixed: Volume
    show: str = "checkerboard"
    blend: float = 0.5
    checker_mm: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.fixed, Volume):
            raise SceneError("a comparison's fixed image must be a Volume")
        if self.show not in COMPARE_SHOWS:
            raise SceneError(
                f"compare must be one of {', '.join(COMPARE_SHOWS)}; got {self.show!r}"
            )
        b = float(self.blend)
        if not 0.0 <= b <= 1.0:
            raise SceneError(f"blend must be in [0, 1] (0 = moving, 1 = fixed); got {self.blend}")
        c = self.checker_mm
        if c is not None and not (math.isfinite(float(c)) and float(c) > 0):
            raise SceneError(f"checker size must be a positive number of mm; got {c}")

    @property
    def cell_mm(self) -> float:
        """The checker cell size in mm (given or the default)."""
        if self.checker_mm is not None:
            return float(self.checker_mm)
        return default_checker_mm(self.fixed)

    def weights(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per world point the weights ``(w_moving, w_fixed)`` whose sum of the two
        values is the compared value (before ``abs`` for ``"difference"``)."""
        shape = np.asarray(points).shape[:-1]
        if self.show == "checkerboard":
            f = checker_fixed(points, self.cell_mm).astype(np.float64)
            return 1.0 - f, f
        if self.show == "difference":
            return np.ones(shape), -np.ones(shape)
        return np.full(shape, 1.0 - self.blend), np.full(shape, float(self.blend))

    def combine(self, moving: np.ndarray, fixed: np.ndarray, points: np.ndarray) -> np.ndarray:
        """The compared value as the raycaster computes it per sample (CPU reference):
        checkerboard picks, blend mixes, difference gives ``|moving - fixed|``."""
        wm, wf = self.weights(points)
        v = wm * np.asarray(moving, np.float64) + wf * np.asarray(fixed, np.float64)
        return np.abs(v) if self.show == "difference" else v

    def settings_dict(self) -> dict[str, Any]:
        """The settings of scene JSON's ``compare`` entry (the fixed image apart)."""
        return {"show": self.show, "blend": float(self.blend), "checker_mm": self.checker_mm}
