"""How VTK draws between transfer-function points, as piecewise-linear points.

ParaView and 3D Slicer interpolate colours in other spaces (CIE L*a*b*, Moreland's
diverging Msh, HSV, steps) and bend opacity segments with a midpoint and a sharpness;
voxwarp's transfer functions are linear in RGB and opacity between points. These
functions add points along VTK's path until the straight pieces are within half a grey
level of it (checked against VTK 9.7.2's vtkColorTransferFunction / vtkPiecewiseFunction,
tests/core/test_tf_formats.py). Pure numpy (and colorsys); used by
:mod:`voxwarp.core.tf_formats`.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable

import numpy as np

# VTK's sRGB <-> CIE L*a*b* (vtkMath::RGBToLab / LabToRGB: sRGB gamma, D65 white
# 0.9505, 1, 1.089, and out-of-gamut colours scaled down by their largest component)
_RGB_TO_XYZ = np.array(
    [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]
)
_XYZ_TO_RGB = np.array(
    [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]]
)
_WHITE = np.array([0.9505, 1.0, 1.089])


def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB in [0, 1] (..., 3) -> L*a*b* (..., 3), as VTK computes it."""
    c = np.asarray(rgb, dtype=np.float64)
    lin = np.where(c > 0.04045, ((c + 0.055) / 1.055) ** 2.4, c / 12.92)
    v = (lin @ _RGB_TO_XYZ.T) / _WHITE
    f = np.where(v > 0.008856, np.cbrt(v), 7.787 * v + 16.0 / 116.0)
    return np.stack(
        [116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1
    )


def lab_to_rgb(lab: np.ndarray) -> np.ndarray:
    """L*a*b* (..., 3) -> sRGB in [0, 1], as VTK computes it (gamut clipped by scaling)."""
    lab = np.asarray(lab, dtype=np.float64)
    fy = (lab[..., 0] + 16) / 116
    f = np.stack([lab[..., 1] / 500 + fy, fy, fy - lab[..., 2] / 200], -1)
    v = np.where(f**3 > 0.008856, f**3, (f - 16.0 / 116.0) / 7.787) * _WHITE
    lin = v @ _XYZ_TO_RGB.T
    c = np.where(lin > 0.0031308, 1.055 * np.abs(lin) ** (1 / 2.4) - 0.055, 12.92 * lin)
    top = np.max(c, axis=-1, keepdims=True)
    c = np.where(top > 1.0, c / np.where(top > 1.0, top, 1.0), c)
    return np.clip(c, 0.0, 1.0)


def _lab_path(t: np.ndarray, c0: np.ndarray, c1: np.ndarray) -> np.ndarray:
    """Colours at fractions ``t`` (n, 1) of the straight L*a*b* path from c0 to c1."""
    return lab_to_rgb((1 - t) * rgb_to_lab(c0) + t * rgb_to_lab(c1))


def _msh(lab: np.ndarray) -> np.ndarray:
    m = float(np.sqrt(np.sum(lab**2)))
    s = float(np.arccos(np.clip(lab[0] / m, -1, 1))) if m > 0.001 else 0.0
    h = float(np.arctan2(lab[2], lab[1])) if s > 0.001 else 0.0
    return np.array([m, s, h])


def _adjust_hue(msh: np.ndarray, unsat_m: float) -> float:
    """Moreland's hue for the unsaturated end of a segment from saturated ``msh``."""
    m, s, h = msh
    if m >= unsat_m - 0.1:
        return float(h)
    spin = s * np.sqrt(unsat_m**2 - m**2) / (m * np.sin(s))
    return float(h + spin if h > -0.3 * np.pi else h - spin)


def _diverging_path(t: np.ndarray, c0: np.ndarray, c1: np.ndarray) -> np.ndarray:
    """ParaView's Diverging space (Moreland 2009, as vtkColorTransferFunction does it):
    straight lines in polar L*a*b* (Msh), through white between two distinct saturated
    colours, with the hue of an unsaturated end chosen to follow the saturated one."""
    out = np.empty((len(t), 3))
    for i, s in enumerate(t[:, 0]):
        a, b = _msh(rgb_to_lab(c0)), _msh(rgb_to_lab(c1))
        diff = abs(a[2] - b[2]) % (2 * np.pi)
        diff = 2 * np.pi - diff if diff > np.pi else diff
        if a[1] > 0.05 and b[1] > 0.05 and diff > 0.33 * np.pi:
            white = np.array([max(a[0], b[0], 88.0), 0.0, 0.0])
            a, b, s = (a, white, 2 * s) if s < 0.5 else (white, b, 2 * s - 1)
        if a[1] < 0.05 < b[1]:
            a[2] = _adjust_hue(b, a[0])
        elif b[1] < 0.05 < a[1]:
            b[2] = _adjust_hue(a, b[0])
        m, sat, h = (1 - s) * a + s * b
        out[i] = lab_to_rgb(np.array([m * np.cos(sat), m * np.sin(sat) * np.cos(h),
                                      m * np.sin(sat) * np.sin(h)]))  # fmt: skip
    return out


def _hsv_path(t: np.ndarray, c0: np.ndarray, c1: np.ndarray, wrap: bool = False) -> np.ndarray:
    """VTK's HSV space: hue, saturation, value linear; with HSVWrap the hue takes the
    shorter way round the circle."""
    import colorsys

    h0, s0, v0 = colorsys.rgb_to_hsv(*c0)
    h1, s1, v1 = colorsys.rgb_to_hsv(*c1)
    if wrap and abs(h0 - h1) > 0.5:
        h0, h1 = (h0 - 1.0, h1) if h0 > h1 else (h0, h1 - 1.0)
    out = np.empty((len(t), 3))
    for i, s in enumerate(t[:, 0]):
        h = (1 - s) * h0 + s * h1
        out[i] = colorsys.hsv_to_rgb(h + 1.0 if h < 0 else h, (1 - s) * s0 + s * s1,
                                     (1 - s) * v0 + s * v1)  # fmt: skip
    return out


#: ParaView colour spaces reproduced by extra RGB points: name -> path between two colours
COLOUR_PATHS: dict[str, Callable[..., np.ndarray]] = {
    "Lab": _lab_path,
    "CIELAB": _lab_path,
    "Diverging": _diverging_path,
    "HSV": _hsv_path,
}


def subdivided(
    colour: np.ndarray, space: str, tol: float = 0.5 / 255, depth: int = 8, hsv_wrap: bool = False
) -> np.ndarray:
    """Colour points (x, r, g, b) interpolated in ``space`` (:data:`COLOUR_PATHS`) as VTK
    does, as RGB points: each segment is halved (up to ``depth`` times) while the path
    leaves the RGB line by more than ``tol`` at a quarter, half or three quarters."""
    path = COLOUR_PATHS[space]
    if space == "HSV" and hsv_wrap:
        path = functools.partial(_hsv_path, wrap=True)
    rows = [colour[0]]
    for k in range(1, len(colour)):
        (x0, *c0), (x1, *c1) = colour[k - 1], colour[k]
        if x1 > x0:
            a, b = np.array(c0), np.array(c1)
            for t, rgb in _bisect(lambda t, a=a, b=b: path(t, a, b), 0.0, 1.0, a, b, tol, depth):
                rows.append(np.concatenate([[x0 + t * (x1 - x0)], rgb]))
        rows.append(colour[k])
    return np.asarray(rows)


def _bisect(
    path: Callable[[np.ndarray], np.ndarray],
    t0: float,
    t1: float,
    p0: np.ndarray,
    p1: np.ndarray,
    tol: float,
    depth: int,
) -> list[tuple[float, np.ndarray]]:
    """Interior (t, rgb) points making the RGB polyline follow ``path`` within ``tol``."""
    ts = t0 + (t1 - t0) * np.array([[0.25], [0.5], [0.75]])
    got = path(ts)
    lin = p0 + (ts - t0) / (t1 - t0) * (p1 - p0)
    if depth == 0 or np.max(np.abs(got - lin)) <= tol:
        return []
    tm, pm = float(ts[1, 0]), got[1]
    left = _bisect(path, t0, tm, p0, pm, tol, depth - 1)
    return [*left, (tm, pm), *_bisect(path, tm, t1, pm, p1, tol, depth - 1)]


def _vtk_segment(s: np.ndarray, y1: float, y2: float, mid: float, sharp: float) -> np.ndarray:
    """vtkPiecewiseFunction's value at fractions ``s`` (n, 1) of a segment from ``y1`` to
    ``y2`` with the first node's midpoint and sharpness: the midpoint remaps ``s`` so the
    mean value falls there; sharpness 0 is linear, above that a Hermite curve flattened at
    the ends, steeper in the middle as the sharpness grows (checked against VTK 9.7.2)."""
    s = np.where(s < mid, 0.5 * s / mid, 0.5 + 0.5 * (s - mid) / (1.0 - mid))
    if sharp < 0.01:
        return (1 - s) * y1 + s * y2
    k = 1.0 + 10.0 * sharp
    s = np.where(s < 0.5, 0.5 * (2 * s) ** k, np.where(s > 0.5, 1 - 0.5 * (2 * (1 - s)) ** k, s))
    ss, sss = s * s, s * s * s
    t = (1.0 - sharp) * (y2 - y1)
    y = (2 * sss - 3 * ss + 1) * y1 + (-2 * sss + 3 * ss) * y2 + (sss - 2 * ss + s) * t
    return np.clip(y + (sss - ss) * t, 0.0, 1.0)


def expand_opacity(rows: np.ndarray) -> np.ndarray:
    """Opacity rows ``(x, a, midpoint, sharpness)`` as piecewise-linear ``(x, a)`` that
    follows VTK's curve (:func:`_vtk_segment`): a midpoint alone becomes one extra point
    (exact), a sharpness points on the curve (within half a grey level)."""
    out: list[np.ndarray] = [rows[0, :2]]
    for (x0, y0, mid, sharp), (x1, y1, _m, _s) in itertools.pairwise(rows):
        mid = min(max(mid, 1e-6), 1 - 1e-6)
        if x1 > x0 and sharp >= 0.01:
            curve = functools.partial(_vtk_segment, y1=y0, y2=y1, mid=mid, sharp=sharp)
            pts = _bisect(curve, 0.0, 1.0, np.array([y0]), np.array([y1]), 0.5 / 255, 8)
            out += [np.array([x0 + t * (x1 - x0), v[0]]) for t, v in pts]
        elif x1 > x0 and abs(mid - 0.5) > 1e-6:
            out.append(np.array([x0 + mid * (x1 - x0), 0.5 * (y0 + y1)]))
        out.append(np.array([x1, y1]))
    return np.asarray(out)


def expand_midpoints(rows: np.ndarray) -> tuple[np.ndarray, bool]:
    """Rows ``(x, values..., midpoint, sharpness)`` -> ``(x, values...)`` with each
    segment's midpoint as an extra point, and whether any sharpness was dropped.

    VTK's midpoint ``m`` puts the value halfway between two points at ``m`` of the way
    (0.5: linear); sharpness 0 is linear. Here a segment with ``m != 0.5`` gets a point at
    ``x0 + m (x1 - x0)`` with the mean value, so it stays piecewise linear; sharpness
    (a smooth S-curve in VTK) is ignored (reported).
    """
    out: list[np.ndarray] = []
    sharp = False
    for k, row in enumerate(rows):
        out.append(row[:-2])
        if k == len(rows) - 1:
            break
        mid, s = row[-2], row[-1]
        sharp = sharp or s > 1e-6
        if abs(mid - 0.5) > 1e-6 and 0.0 < mid < 1.0:
            nxt = rows[k + 1, :-2]
            x = row[0] + mid * (nxt[0] - row[0])
            out.append(np.concatenate([[x], 0.5 * (row[1:-2] + nxt[1:])]))
    return np.asarray(out), sharp


def step(colour: np.ndarray) -> np.ndarray:
    """ParaView's Step colour space as VTK draws it: between two points, the colour of
    the upper one (so each point's colour fills the interval up to it)."""
    rows = [colour[0]]
    for k in range(1, len(colour)):
        rows.append(np.concatenate([[colour[k - 1, 0]], colour[k, 1:]]))
        rows.append(colour[k])
    return np.asarray(rows)


def simplify(t: np.ndarray, values: np.ndarray, tol: float) -> np.ndarray:
    """Indices of the fewest samples (Ramer-Douglas-Peucker) whose linear interpolation
    keeps every sample of ``values`` (n, k) at ``t`` (n,) within ``tol`` per channel;
    the first and last are always kept."""
    keep = {0, len(t) - 1}
    stack = [(0, len(t) - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        w = (t[i + 1 : j] - t[i]) / (t[j] - t[i])
        dev = np.abs(values[i + 1 : j] - (values[i] + w[:, None] * (values[j] - values[i])))
        k = int(np.argmax(dev.max(axis=1)))
        if dev[k].max() > tol:
            keep.add(i + 1 + k)
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return np.array(sorted(keep))
