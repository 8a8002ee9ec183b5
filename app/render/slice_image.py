"""Slice images: a slice's data and its colours (no GL, no Qt).

A :class:`SliceImage` holds what :class:`voxwarp.render.slices.SliceRenderer` computed
for one plane: the deformed and rest-state values per pixel (NaN where the pixel shows
nothing of the volume) and the pixel -> world mapping. :func:`colorize` turns it into
RGBA, so the GUI re-colours on a window/level drag without drawing again.

Looks (``look``)
----------------
* ``"window"``: grey from the window ``(level, width)``, as radiology viewers show CT and
  MRI: ``level - width / 2`` black, ``level + width / 2`` white.
* ``"tf"``: the transfer function's colour, its opacity scaled so that the most opaque
  value of the function shows at full strength (a slice has no depth to accumulate
  opacity over), over black.

Shown state (``show``)
----------------------
``"deformed"`` (default), ``"rest"`` (the undeformed volume on the same plane),
``"checkerboard"`` (tiles of ``checker_px`` pixels alternating rest and deformed, the
registration check), ``"difference"`` (deformed minus rest over a dim rest image:
red where the deformation raised the value, blue where it lowered it, full strength at
one window width) and ``"blend"`` (``(1 - blend) * deformed + blend * rest``, colours
mixed).

With a fixed image (``image.fixed``, a registration's fixed volume sampled at the same
world points; :mod:`voxwarp.core.comparison`) the comparisons use it instead of the
rest state: ``"rest"`` shows the fixed image, ``"checkerboard"``, ``"difference"`` and
``"blend"`` compare the deformed (moving) image with it. ``checker_mm`` switches the
checkerboard from pixel tiles to the world cells the 3D view uses
(:func:`voxwarp.core.comparison.checker_fixed`: odd cells show the reference).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

import numpy as np

from voxwarp.core.comparison import checker_fixed
from voxwarp.core.slice_plane import SlicePlane
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.errors import RenderError
from voxwarp.render.jacobian_overlay import JacobianOverlay, blend_detj, draw_legend

Look = Literal["window", "tf"]
LOOKS: tuple[str, ...] = ("window", "tf")
Show = Literal["deformed", "rest", "checkerboard", "difference", "blend"]
SHOWS: tuple[str, ...] = ("deformed", "rest", "checkerboard", "difference", "blend")
#: a pixel shows the volume when at least this fraction of its slab samples lie inside
COVERED = 1e-6


@dataclasses.dataclass
class SliceImage:
    """One slice plane's data.

    Attributes
    ----------
    plane
        The plane (None for an image drawn from a bare pixel -> world matrix).
    pixel_to_world
        4x4: ``(col, row, 0, 1)`` -> world centre (mm) of pixel ``[row, col]``.
    values, rest
        (H, W) float32 deformed and rest-state values; NaN where the pixel's point
        (its whole slab) lies outside the volume.
    rgba
        (H, W, 4) uint8 colours (:func:`colorize`), or None before colouring.
    fixed
        (H, W) float32 values of a fixed image at the pixels' world points (NaN
        outside it), or None without one: then the comparisons use ``rest``.
    detj
        (H, W) float32 ``det J`` of the warp chain at the pixel centres (NaN where the
        pixel shows no volume), or None when the ``jacobian`` overlay was not asked for.
    notes
        One line per ``grid``/``glyphs`` overlay drawn (spacing, legend scale).
    """

    plane: SlicePlane | None
    pixel_to_world: np.ndarray
    values: np.ndarray
    rest: np.ndarray
    rgba: np.ndarray | None = None
    detj: np.ndarray | None = None
    notes: list[str] = dataclasses.field(default_factory=list)
    fixed: np.ndarray | None = None

    @property
    def reference(self) -> np.ndarray:
        """What the comparisons compare ``values`` with: ``fixed``, else ``rest``."""
        return self.rest if self.fixed is None else self.fixed

    def pixel_points(self) -> np.ndarray:
        """(H, W, 3) world points (mm) of the pixel centres."""
        h, w = self.values.shape
        cols, rows = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        m = self.pixel_to_world
        return cols[..., None] * m[:3, 0] + rows[..., None] * m[:3, 1] + m[:3, 3]

    @classmethod
    def from_data(
        cls, data: np.ndarray, pixel_to_world: np.ndarray, plane: SlicePlane | None = None
    ) -> SliceImage:
        """From the (H, W, 4) float data of :meth:`SliceRenderer.values`."""
        values = np.where(data[..., 1] > COVERED, data[..., 0], np.nan).astype(np.float32)
        rest = np.where(data[..., 3] > COVERED, data[..., 2], np.nan).astype(np.float32)
        return cls(plane, np.asarray(pixel_to_world, np.float64), values, rest)

    @property
    def size(self) -> tuple[int, int]:
        """(W, H) in pixels."""
        return int(self.values.shape[1]), int(self.values.shape[0])

    def world(self, col: float, row: float) -> np.ndarray:
        """World point (mm) of the (fractional) pixel position ``(col, row)``."""
        return (self.pixel_to_world @ np.array([col, row, 0.0, 1.0]))[:3]

    def value_at(self, col: float, row: float) -> tuple[float, float]:
        """(deformed, rest) values of the pixel holding ``(col, row)`` (the fixed
        image's value instead of rest when there is one: :attr:`reference`); NaN outside."""
        w, h = self.size
        c, r = int(np.floor(col)), int(np.floor(row))
        if not (0 <= c < w and 0 <= r < h):
            return float("nan"), float("nan")
        return float(self.values[r, c]), float(self.reference[r, c])


def _grey(values: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    """(H, W) float32 grey in [0, 1] of ``values`` through ``window``; NaN is black."""
    level, width = (float(v) for v in window)
    if not width > 0:
        raise RenderError(f"window width must be positive; got {width}")
    g = np.asarray(values, dtype=np.float32) - np.float32(level - width / 2)
    g *= np.float32(1.0 / width)
    np.clip(g, 0.0, 1.0, out=g)
    return np.nan_to_num(g, copy=False, nan=0.0)


def colour_values(
    values: np.ndarray,
    look: str = "window",
    window: tuple[float, float] = (0.5, 1.0),
    tf: TransferFunction | None = None,
) -> np.ndarray:
    """(H, W) values -> colours in [0, 1]: (H, W) grey for ``look="window"``, (H, W, 3)
    RGB for ``"tf"``; NaN (nothing) is black."""
    if look == "window":
        return _grey(values, window)
    if look != "tf":
        raise RenderError(f"look must be one of {', '.join(LOOKS)}; got {look!r}")
    if tf is None:
        raise RenderError("look 'tf' needs a transfer function")
    inside = np.isfinite(values)
    v = np.where(inside, values, 0.0)
    table = tf(v.reshape(-1)).reshape(*v.shape, 4)
    top = float(np.max(np.asarray(tf.points)[:, 4])) or 1.0
    rgb = table[..., :3] * np.clip(table[..., 3:4] / top, 0.0, 1.0)
    return np.where(inside[..., None], rgb, 0.0)


def colorize(
    image: SliceImage,
    *,
    look: str = "window",
    window: tuple[float, float] = (0.5, 1.0),
    tf: TransferFunction | None = None,
    show: str = "deformed",
    checker_px: int = 32,
    checker_mm: float | None = None,
    blend: float = 0.5,
    jacobian: JacobianOverlay | None = None,
    legend: str | None = "bottom-right",
) -> np.ndarray:
    """The slice's (H, W, 4) uint8 RGBA (opaque; see the module docstring for
    ``look``, ``show``, ``checker_mm`` and ``blend``); also kept as ``image.rgba``.
    ``jacobian``: draw ``image.detj`` over it with this colour map and its legend in the
    corner ``legend`` (None: no legend; :mod:`voxwarp.render.jacobian_overlay`)."""
    options: dict[str, Any] = {"look": look, "window": window, "tf": tf}
    if show == "deformed":
        colours = colour_values(image.values, **options)
    elif show == "rest":
        colours = colour_values(image.reference, **options)
    elif show == "checkerboard":
        tiles = _checker_tiles(image, checker_px, checker_mm)
        rest = colour_values(image.reference, **options)
        deformed = colour_values(image.values, **options)
        colours = np.where(tiles if rest.ndim == 2 else tiles[..., None], rest, deformed)
    elif show == "difference":
        colours = _difference(image, window)
    elif show == "blend":
        b = float(blend)
        if not 0.0 <= b <= 1.0:
            raise RenderError(f"blend must be in [0, 1] (0 = moving, 1 = fixed); got {blend}")
        rest = colour_values(image.reference, **options)
        colours = (1.0 - b) * colour_values(image.values, **options) + b * rest
    else:
        raise RenderError(f"show must be one of {', '.join(SHOWS)}; got {show!r}")
    out = np.empty((*colours.shape[:2], 4), np.uint8)
    u8 = (np.asarray(colours, dtype=np.float32) * 255 + 0.5).astype(np.uint8)
    out[..., :3] = u8[..., None] if u8.ndim == 2 else u8
    out[..., 3] = 255
    if jacobian is not None and image.detj is not None:
        blend_detj(out, image.detj, jacobian)
        if legend is not None:
            draw_legend(out, jacobian, legend)
    image.rgba = out
    return out


def _checker_tiles(image: SliceImage, checker_px: int, checker_mm: float | None) -> np.ndarray:
    """(H, W) bool: where the checkerboard shows the reference (rest or fixed)."""
    if checker_mm is not None:
        if not (np.isfinite(checker_mm) and checker_mm > 0):
            raise RenderError(f"checker size must be a positive number of mm; got {checker_mm}")
        return checker_fixed(image.pixel_points(), float(checker_mm))
    h, w = image.values.shape
    k = max(int(checker_px), 1)
    return ((np.arange(h)[:, None] // k) + (np.arange(w)[None, :] // k)) % 2 == 1


def _difference(image: SliceImage, window: tuple[float, float]) -> np.ndarray:
    """Deformed - reference (rest or fixed) over a dim grey reference image: red up,
    blue down, full at one width."""
    width = float(window[1])
    ref = image.reference
    under = np.repeat(0.35 * colour_values(ref, "window", window)[..., None], 3, axis=2)
    a = np.where(np.isfinite(image.values), image.values, window[0] - width / 2)
    b = np.where(np.isfinite(ref), ref, window[0] - width / 2)
    t = np.clip((a - b) / width, -1.0, 1.0)
    rgb = under.copy()
    rgb[..., 0] = np.maximum(under[..., 0], np.maximum(t, 0.0))
    rgb[..., 2] = np.maximum(under[..., 2], np.maximum(-t, 0.0))
    rgb[..., 1] = under[..., 1] * (1 - np.abs(t))
    return rgb
