"""Orientation marker: the world axes as a small triad in a corner of an image (no Qt).

About the marker
----------------
A rendered volume does not show which way the patient faces. The marker draws the six
half-axes of world space as seen by the camera: each world axis ``±x``, ``±y``, ``±z``
projected onto the image plane (orthographically, whatever the camera's projection: the
marker shows directions, not positions) and labelled at its end. For a volume with a
patient orientation (``volume.space == "RAS"``) the letters are the patient's: ``R``
(+x), ``L`` (-x), ``A`` (+y), ``P`` (-y), ``S`` (+z), ``I`` (-z); other volumes get
``x``, ``y``, ``z`` at the positive ends. Colours follow the common convention: R/L
(x) red, A/P (y) green, S/I (z) blue; the negative half-axes are dimmer. Half-axes are
drawn back to front, so the one pointing at the viewer is on top. A half-axis that
points (nearly) straight at or away from the viewer gets no letter (it would sit on the
marker's centre).

So in the anterior view of a RAS volume (looking at the face, head up) ``R`` is on the
image's left and ``S`` on top; in the inferior view (from the feet, the radiological
axial view) ``A`` is up and ``R`` left; in the superior view ``A`` is up and ``R`` right.

Python API
----------
Draw it on any rendered image (``(H, W, 3|4)`` uint8, or float in [0, 1])::

    from voxwarp import OffscreenRenderer, Scene, load_volume
    from voxwarp.render.orientation_marker import draw_scene_marker

    scene = Scene(load_volume("ct.nii.gz"), view="-z")
    with OffscreenRenderer(512, 512) as r:
        img = r.render(scene)
    draw_scene_marker(img, scene)  # in place; also returns img

or, with an explicit camera, ``draw_orientation_marker(img, camera, oriented=True)``;
:func:`marker_axes` and :func:`marker_layout` give the geometry (for GUIs that draw the
marker themselves, as voxwarp's viewport does). The command line draws it with
``voxwarp render --marker``.

The letters come from a tiny built-in 5x7 bitmap font (numpy only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.core.orientation import axis_letters
from voxwarp.errors import RenderError
from voxwarp.render.bitmap_font import text_mask

if TYPE_CHECKING:
    from voxwarp.core.camera import Camera
    from voxwarp.scene import Scene

__all__ = [
    "AXIS_COLORS",
    "CORNERS",
    "MarkerAxis",
    "MarkerLayout",
    "draw_orientation_marker",
    "draw_scene_marker",
    "glyph_mask",
    "marker_axes",
    "marker_layout",
]

#: RGB (0..255) of the x (R/L), y (A/P) and z (S/I) world axes.
AXIS_COLORS: tuple[tuple[int, int, int], ...] = ((235, 60, 50), (60, 205, 75), (70, 130, 255))
#: Corners the marker may sit in.
CORNERS: tuple[str, ...] = ("bottom-left", "bottom-right", "top-left", "top-right")
#: Brightness of the negative half-axes relative to the positive ones.
NEGATIVE_DIM = 0.5
#: A half-axis shorter than this on screen (fraction of its length) gets no letter.
MIN_LABEL_LENGTH = 0.25
#: The dark halo around lines and letters (legible on bright volumes too).
HALO_RGB = (15, 15, 15)
HALO_ALPHA = 0.7

GLYPH_SHAPE = (7, 5)


def glyph_mask(letter: str, scale: int = 1) -> np.ndarray:
    """The (7*scale, 5*scale) boolean bitmap of ``letter`` (one of R L A P S I x y z)."""
    if len(letter) != 1:
        raise RenderError(f"a marker label is one letter; got {letter!r}")
    return text_mask(letter, scale)


@dataclass(frozen=True)
class MarkerAxis:
    """One half-axis of the marker.

    Parameters
    ----------
    axis
        World axis 0, 1, 2 (x, y, z).
    sign
        +1 or -1: which half.
    label
        Its letter (``""`` for the negative halves of an unoriented volume).
    direction
        Projected direction on the image, ``(right, up)``; its length is the cosine of
        the angle to the image plane (1: in the plane, 0: along the view).
    depth
        Component towards the viewer (> 0: points at the eye).
    color
        RGB 0..255 (dimmed for negative halves).
    """

    axis: int
    sign: int
    label: str
    direction: tuple[float, float]
    depth: float
    color: tuple[int, int, int]


def _rotation(camera: Any) -> np.ndarray:
    r = getattr(camera, "rotation", camera)
    try:
        m = np.asarray(r, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError) as exc:
        raise RenderError(
            f"the orientation marker needs a Camera (or its 3x3 rotation); got {type(camera)}"
        ) from exc
    if not np.all(np.isfinite(m)):
        raise RenderError("the camera rotation for the orientation marker is not finite")
    return m


def marker_axes(camera: Camera | np.ndarray, oriented: bool) -> list[MarkerAxis]:
    """The six half-axes of the marker for ``camera``, back to front.

    ``camera`` is a :class:`~voxwarp.core.camera.Camera` or its rotation (columns: the
    camera's right, up and back axes in world coordinates); ``oriented``: the world is
    patient RAS (letters R L A P S I) rather than unnamed (x y z).
    """
    rot = _rotation(camera)
    right, up, back = rot[:, 0], rot[:, 1], rot[:, 2]
    out: list[MarkerAxis] = []
    for axis in range(3):
        for sign in (1, -1):
            e = np.zeros(3)
            e[axis] = sign
            if oriented:
                label = axis_letters(axis, sign)
            else:
                label = "xyz"[axis] if sign > 0 else ""
            base = AXIS_COLORS[axis]
            color = base if sign > 0 else tuple(round(c * NEGATIVE_DIM) for c in base)
            out.append(
                MarkerAxis(
                    axis,
                    sign,
                    label,
                    (float(right @ e), float(up @ e)),
                    float(back @ e),
                    color,  # type: ignore[arg-type]
                )
            )
    out.sort(key=lambda a: a.depth)
    return out


@dataclass(frozen=True)
class MarkerLayout:
    """Where the marker's parts go in an image (pixels, x right, y down).

    Parameters
    ----------
    center
        The triad's origin.
    length
        Length of a half-axis lying in the image plane.
    scale
        Pixel size of one font cell (glyphs are 5x7 cells).
    axes
        The half-axes, back to front.
    ends
        Per half-axis, the pixel its line ends at.
    labels
        Per half-axis, the centre of its letter, or None (no letter).
    """

    center: tuple[float, float]
    length: float
    scale: int
    axes: tuple[MarkerAxis, ...]
    ends: tuple[tuple[float, float], ...]
    labels: tuple[tuple[float, float] | None, ...]

    def label_position(self, label: str) -> tuple[float, float] | None:
        """The centre of letter ``label``, or None when it is not drawn."""
        for a, p in zip(self.axes, self.labels, strict=True):
            if a.label == label:
                return p
        return None


def marker_layout(
    camera: Camera | np.ndarray,
    oriented: bool,
    image_size: tuple[int, int],
    size_px: int = 96,
    corner: str = "bottom-left",
    margin_px: int = 6,
) -> MarkerLayout:
    """The marker's geometry in an image of ``image_size`` = (width, height) pixels.

    The marker fills a ``size_px`` square (shrunk to fit a smaller image) ``margin_px``
    from the ``corner`` (one of :data:`CORNERS`).
    """
    if corner not in CORNERS:
        raise RenderError(f"marker corner must be one of {', '.join(CORNERS)}; got {corner!r}")
    w, h = (int(v) for v in image_size)
    if w < 1 or h < 1:
        raise RenderError(f"the image for the orientation marker is empty ({w}x{h})")
    size = float(min(int(size_px), w, h))
    if not size > 0:
        raise RenderError(f"marker size_px must be positive; got {size_px}")
    margin = min(float(margin_px), max(0.0, (min(w, h) - size) / 2))
    scale = max(1, round(size / 64))
    glyph_h = GLYPH_SHAPE[0] * scale
    # room for the letters beyond the ends of the lines, inside the square
    # (a letter's centre lies 0.6 glyph heights + one cell beyond the line's end; its
    # half height and its halo come on top)
    length = max(2.0, 0.5 * size - (1.1 * glyph_h + scale + _halo_radius(scale) + 1))
    cx = margin + size / 2 if "left" in corner else w - margin - size / 2
    cy = margin + size / 2 if "top" in corner else h - margin - size / 2
    # on a pixel centre: lines along the image axes are sharp
    cx, cy = np.floor(cx) + 0.5, np.floor(cy) + 0.5
    axes = tuple(marker_axes(camera, oriented))
    ends, labels = [], []
    for a in axes:
        dx, dy = a.direction
        ends.append((cx + length * dx, cy - length * dy))
        n = float(np.hypot(dx, dy))
        if a.label and n >= MIN_LABEL_LENGTH:
            # the letter just beyond the end of the line, along it
            reach = length * n + 0.6 * glyph_h + scale
            labels.append((cx + reach * dx / n, cy - reach * dy / n))
        else:
            labels.append(None)
    return MarkerLayout((cx, cy), length, scale, axes, tuple(ends), tuple(labels))


# ---------------------------------------------------------------------------- drawing
def _blend(region: np.ndarray, alpha: np.ndarray, rgb: tuple[int, ...], top: float) -> None:
    """``region`` (h, w, C float, channels in 0..top) <- opaque ``rgb`` over it, with
    coverage ``alpha`` (h, w)."""
    a = alpha[..., None]
    col = np.asarray(rgb, dtype=np.float64) * (top / 255.0)
    region[..., :3] = region[..., :3] * (1 - a) + col * a
    if region.shape[-1] == 4:
        region[..., 3:] = region[..., 3:] * (1 - a) + top * a


def _segment_coverage(
    xs: np.ndarray, ys: np.ndarray, p0: tuple[float, float], p1: tuple[float, float], width: float
) -> np.ndarray:
    """Anti-aliased coverage of pixel centres (xs, ys) by a segment ``width`` wide."""
    x0, y0 = p0
    dx, dy = p1[0] - x0, p1[1] - y0
    len2 = dx * dx + dy * dy
    px, py = xs + 0.5 - x0, ys + 0.5 - y0
    t = np.clip((px * dx + py * dy) / len2, 0.0, 1.0) if len2 > 0 else np.zeros_like(px)
    dist = np.hypot(px - t * dx, py - t * dy)
    return np.clip(width / 2 + 0.5 - dist, 0.0, 1.0)


def _glyph_alpha(shape: tuple[int, int], mask: np.ndarray, x0: int, y0: int) -> np.ndarray:
    """A (h, w) array with ``mask`` placed at (x0, y0) (clipped to the array)."""
    out = np.zeros(shape)
    gh, gw = mask.shape
    ys0, xs0 = max(0, y0), max(0, x0)
    ys1, xs1 = min(shape[0], y0 + gh), min(shape[1], x0 + gw)
    if ys1 > ys0 and xs1 > xs0:
        out[ys0:ys1, xs0:xs1] = mask[ys0 - y0 : ys1 - y0, xs0 - x0 : xs1 - x0]
    return out


def _halo_radius(scale: int) -> int:
    """Width in pixels of the dark halo around letters."""
    return max(1, scale // 2 + 1)


def _dilate(mask: np.ndarray, r: int) -> np.ndarray:
    padded = np.pad(mask, r)
    out = np.zeros_like(padded)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            out |= np.roll(np.roll(padded, dy, 0), dx, 1)
    return out


def draw_orientation_marker(
    image: np.ndarray,
    camera: Camera | np.ndarray,
    oriented: bool,
    size_px: int = 96,
    corner: str = "bottom-left",
    negative: bool = True,
    margin_px: int = 6,
) -> np.ndarray:
    """Draw the orientation marker on ``image`` in place (see the module docstring).

    Parameters
    ----------
    image
        (H, W, 3) or (H, W, 4) uint8, or float with channels in [0, 1]; row 0 is the top.
    camera
        The camera the image was rendered with (or its 3x3 rotation).
    oriented
        The volume has a patient orientation (``volume.space == "RAS"``): letters
        R L A P S I; otherwise x y z.
    size_px
        Side of the square the marker fills (shrunk to fit a smaller image).
    corner
        One of :data:`CORNERS`.
    negative
        Also draw the negative half-axes (dimmer, with their letters when oriented).
    margin_px
        Distance from the image's edges.

    Returns
    -------
    numpy.ndarray
        ``image`` itself.
    """
    img = np.asarray(image) if not isinstance(image, np.ndarray) else image
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise RenderError(
            f"the orientation marker draws on an (H, W, 3) or (H, W, 4) image; got shape"
            f" {img.shape}"
        )
    if img.dtype == np.uint8:
        top = 255.0
    elif np.issubdtype(img.dtype, np.floating):
        top = 1.0
    else:
        raise RenderError(f"the orientation marker draws on uint8 or float images; got {img.dtype}")
    h, w = img.shape[:2]
    lay = marker_layout(camera, oriented, (w, h), size_px, corner, margin_px)
    # work on the marker's square (plus room for letters), in float
    half = lay.length + (2 * GLYPH_SHAPE[0] + 4) * lay.scale
    x0 = int(max(0, np.floor(lay.center[0] - half)))
    x1 = int(min(w, np.ceil(lay.center[0] + half)))
    y0 = int(max(0, np.floor(lay.center[1] - half)))
    y1 = int(min(h, np.ceil(lay.center[1] + half)))
    if x1 <= x0 or y1 <= y0:
        return img
    region = img[y0:y1, x0:x1].astype(np.float64)
    ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    width = max(2.0, lay.length / 14)
    for a, end, label_at in zip(lay.axes, lay.ends, lay.labels, strict=True):
        if a.sign < 0 and not negative:
            continue
        cover = _segment_coverage(xs, ys, lay.center, end, width)
        halo = _segment_coverage(xs, ys, lay.center, end, width + 2.0)
        _blend(region, halo * HALO_ALPHA, HALO_RGB, top)
        _blend(region, cover, a.color, top)
        if label_at is not None:
            mask = glyph_mask(a.label, lay.scale)
            gx = round(label_at[0] - mask.shape[1] / 2) - x0
            gy = round(label_at[1] - mask.shape[0] / 2) - y0
            r = _halo_radius(lay.scale)
            halo_mask = _dilate(mask, r)
            shape = region.shape[:2]
            _blend(
                region, _glyph_alpha(shape, halo_mask, gx - r, gy - r) * HALO_ALPHA, HALO_RGB, top
            )
            _blend(region, _glyph_alpha(shape, mask, gx, gy), a.color, top)
    if top == 255.0:
        region = np.clip(np.rint(region), 0, 255)
    img[y0:y1, x0:x1] = region.astype(img.dtype)
    return img


def draw_scene_marker(
    image: np.ndarray, scene: Scene, camera: Camera | None = None, **options: Any
) -> np.ndarray:
    """:func:`draw_orientation_marker` for an image rendered from ``scene`` (with
    ``camera``, default the scene's own); letters R L A P S I when the scene's volume
    has a patient orientation. ``options`` go to :func:`draw_orientation_marker`."""
    cam = camera if camera is not None else scene.resolved_camera()
    oriented = getattr(scene.volume, "space", "") == "RAS"
    return draw_orientation_marker(image, cam, oriented, **options)
