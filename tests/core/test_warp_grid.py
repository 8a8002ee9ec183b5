"""The warped grid and glyphs on slices, and the 3D lattice lines (numpy, no GL).

Oracles:

* no warp: the grid lines of an axial plane lie at the pixel columns/rows whose world x/y
  is a multiple of N; coverage equals the analytic ``clip(w/2 + 1/2 - d)`` with ``d`` the
  distance in pixels of the pixel centre to the nearest multiple;
* a translation and a scaling (affine) warp: the same with the analytically mapped rest
  point ``q = A x`` (columns predicted from the matrix, not from the chain): the lines
  keep their pixel width where the scaling spreads them;
* glyphs: tail at a pixel centre ``x``, the arrow equals ``u = A x - x`` projected on
  the plane times the scale, and the longest arrow spans 0.9 of the glyph spacing;
* lattice lines sit at multiples of N, inside the box, one plane or all three families.
"""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.warp_grid import (
    grid_coverage,
    lattice_lines,
    nice_ceil,
    nice_number,
    nice_spacing,
    pixel_points,
    pull_back,
    slice_glyphs,
)
from voxwarp.deform.warp import AffineWarp
from voxwarp.errors import InputError

PX = 0.7  # mm per pixel: lines fall between pixel centres too
SIZE = (90, 70)
N = 10.0
WIDTH = 1.5


def _axial(px: float = PX) -> np.ndarray:
    """Pixel -> world of an axial plane at z = 3 (radiological: +col is world -x)."""
    m = np.eye(4)
    m[:3, 0] = (-px, 0, 0)
    m[:3, 1] = (0, -px, 0)
    m[:3, 3] = (31.3, 22.1, 3.0)
    return m


def _expected(values: np.ndarray, step_px: float) -> np.ndarray:
    """Analytic coverage of the lines values = k N, values changing step_px mm per px."""
    d = np.abs(values / N - np.round(values / N)) * N / step_px
    return np.clip(WIDTH / 2 + 0.5 - d, 0.0, 1.0)


def _pulling(a: np.ndarray) -> AffineWarp:
    """The affine warp whose pull-back (``apply``) is ``a``: deformed x -> rest a x."""
    return AffineWarp(np.linalg.inv(a))


def _coverage(warps: list, m: np.ndarray) -> np.ndarray:
    rest = pull_back(warps, pixel_points(m, SIZE))
    return grid_coverage(rest, (m[:3, 0], m[:3, 1]), N, WIDTH)


def test_no_warp_lines_are_straight_at_multiples_of_n() -> None:
    m = _axial()
    cover = _coverage([], m)
    x = m[0, 3] + m[0, 0] * np.arange(SIZE[0])
    y = m[1, 3] + m[1, 1] * np.arange(SIZE[1])
    expect = np.maximum(_expected(x, PX)[None, :], _expected(y, PX)[:, None])
    np.testing.assert_allclose(cover, expect, atol=1e-9)
    # straight: a vertical line is a full column
    cols = np.flatnonzero(np.abs(x / N - np.round(x / N)) * N <= 0.25 * PX)
    assert cols.size > 0
    assert np.all(cover[:, cols] == 1.0)


@pytest.mark.parametrize(
    "matrix",
    [
        AffineWarp.translation((3.3, -4.1, 2.0)).affine_matrix(),
        np.diag([1.6, 0.8, 1.0, 1.0]) @ AffineWarp.translation((2.2, 1.0, 0)).affine_matrix(),
    ],
    ids=["translation", "scaling"],
)
def test_affine_warp_lines_at_the_mapped_columns(matrix: np.ndarray) -> None:
    m = _axial()
    cover = _coverage([_pulling(matrix)], m)
    cols, rows = np.arange(SIZE[0]), np.arange(SIZE[1])
    x = m[0, 3] + m[0, 0] * cols  # deformed world x of each column
    y = m[1, 3] + m[1, 1] * rows
    qx = matrix[0, 0] * x + matrix[0, 3]  # rest point, analytic
    qy = matrix[1, 1] * y + matrix[1, 3]
    expect = np.maximum(
        _expected(qx, PX * matrix[0, 0])[None, :], _expected(qy, PX * matrix[1, 1])[:, None]
    )
    np.testing.assert_allclose(cover, expect, atol=1e-9)
    # the lines moved: they differ from the unwarped grid
    assert np.abs(cover - _coverage([], m)).max() > 0.5


def test_dense_lines_and_uncarried_points_are_left_out() -> None:
    m = _axial(px=30.0)  # 3 lines per pixel: no grid there
    assert _coverage([], m).max() == 0.0
    rest = pull_back([], pixel_points(_axial(), SIZE))
    rest[:10] = np.nan
    cover = grid_coverage(rest, (np.array([1.0, 0, 0]), np.array([0, 1.0, 0])), N)
    assert cover[:10].max() == 0.0
    assert cover[12:].max() == 1.0


def test_glyphs_equal_u_at_their_centres() -> None:
    matrix = np.diag([1.1, 0.9, 1.0, 1.0]) @ AffineWarp.translation((2.0, 3.0, 7.0)).affine_matrix()
    m = _axial()
    g = slice_glyphs([_pulling(matrix)], m, SIZE, 12.0)
    assert g.spacing_px == pytest.approx(12.0 / PX)
    x = g.tails[:, :1] * m[:3, 0] + g.tails[:, 1:] * m[:3, 1] + m[:3, 3]
    u = x @ matrix[:3, :3].T + matrix[:3, 3] - x
    # in-plane: right = -world x, up = +world y (radiological axial)
    np.testing.assert_allclose(g.vectors_mm, np.stack([-u[:, 0], u[:, 1]], 1), atol=1e-9)
    arrows = g.heads() - g.tails
    np.testing.assert_allclose(arrows[:, 0], -u[:, 0] * g.px_per_mm, atol=1e-9)
    np.testing.assert_allclose(arrows[:, 1], -u[:, 1] * g.px_per_mm, atol=1e-9)
    longest = np.hypot(*arrows.T).max()
    assert longest == pytest.approx(0.9 * g.spacing_px)
    assert 0 < g.legend_mm <= np.hypot(*g.vectors_mm.T).max()


def test_no_displacement_gives_no_arrows() -> None:
    g = slice_glyphs([], _axial(), SIZE, 10.0)
    assert g.px_per_mm == 0.0


def test_lattice_lines_at_multiples() -> None:
    lo, hi = np.array([-12.0, -3.0, 1.0]), np.array([25.0, 21.0, 38.0])
    lines = lattice_lines(lo, hi, 10.0)
    counts = {0: 0, 1: 0, 2: 0}
    for p in lines:
        along = int(np.argmax(np.ptp(p, axis=0)))
        counts[along] += 1
        others = [a for a in range(3) if a != along]
        assert np.allclose(np.mod(p[:, others], 10.0), 0.0)
        assert p[:, along].min() == lo[along]
        assert p[:, along].max() == hi[along]
    # ticks: x -10..20 (4), y 0..20 (3), z 10..30 (3)
    assert counts == {0: 3 * 3, 1: 4 * 3, 2: 4 * 3}
    axial = lattice_lines(lo, hi, 10.0, "axial")
    assert len(axial) == 3 + 4
    assert all(np.allclose(p[:, 2], (lo[2] + hi[2]) / 2) for p in axial)


def test_spacing_defaults_and_errors() -> None:
    assert nice_number(16.0) == 20.0
    assert nice_number(0.13) == 0.1
    assert nice_number(3.4) == 5.0
    assert nice_spacing((0, 0, 0), (256.0, 200.0, 180.0)) == 20.0
    assert nice_spacing((0, 0, 0), (160.0, 1, 1)) == 10.0
    assert nice_spacing((0, 0, 0), (160.0, 1, 1), at_least_mm=12.0) == 20.0  # rounded up
    assert nice_ceil(2.0) == 2.0
    assert nice_ceil(2.01) == 5.0
    assert nice_ceil(0.7) == 1.0
    with pytest.raises(InputError, match="positive"):
        grid_coverage(np.zeros((2, 2, 3)), (np.array([1.0, 0, 0]),), 0.0)
    with pytest.raises(InputError, match="grid-plane"):
        lattice_lines((0, 0, 0), (1, 1, 1), 0.5, "oblique")
