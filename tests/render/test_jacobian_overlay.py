"""The det J overlay (``voxwarp.render.jacobian_overlay``) in slices and in 3D.

Oracles:

* the colour map's own definition: identity clear, ``det J = 2^±r`` at full opacity in
  the compression/expansion colour, folds solid, NaN clear;
* slices (det J from the warps' GLSL Jacobians, on the GPU): an affine scaling's det J
  is ``1 / (sx sy sz)`` at every pixel (closed form);
  a smooth displacement field's det J at the pixel centres equals the determinant of
  the chain's pull-back map differentiated by central differences of
  ``chain_apply`` (an independent numeric Jacobian) and the CPU ``chain_determinant``
  (what ``Scene.jacobian_determinant`` evaluates) on a grid whose nodes are the pixel
  centres, within 2e-3 (GPU vs CPU);
* folds: a displacement field whose x component falls with slope -2 between two node
  planes and is flat elsewhere has ``det J = -1`` exactly between them and 1 outside
  (trilinear interpolation of the nodes): the fold colour covers exactly the pixels
  between the planes;
* 3D: an affine scaling (the straight-ray path) and a linear displacement field (the
  warped-ray path, trilinear interpolation reproduces it exactly) give one det J
  everywhere: the GLSL-tinted MIP equals the CPU colour map over the same grey.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.jacobian import chain_determinant
from voxwarp.core.slice_plane import SlicePlane
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import AffineWarp, chain_apply
from voxwarp.errors import RenderError
from voxwarp.render.jacobian_overlay import (
    COMPRESSION_RGB,
    EXPANSION_RGB,
    FOLD_RGB,
    JacobianOverlay,
    check_detj_mode,
    detj_rgba,
    draw_legend,
    pixel_centres,
    slice_detj,
)
from voxwarp.render.overlay_options import check_overlays
from voxwarp.scene import Scene

SHAPE = (20, 18, 16)
SPACING = 2.0


def _volume(value: float | None = None) -> Volume:
    rng = np.random.default_rng(5)
    data = rng.integers(40, 220, SHAPE).astype(np.uint8)
    if value is not None:
        data[:] = value
    return Volume(data, (SPACING,) * 3, (-19.0, -17.0, -15.0), space="RAS")


def _field(u_of_x: Any, vol: Volume, pad: int = 3) -> DisplacementFieldWarp:
    """A displacement field on a grid 1 mm apart covering ``vol`` with a margin."""
    lo, hi = (np.asarray(b) for b in vol.bounds)
    lo, hi = np.floor(lo) - pad, np.ceil(hi) + pad
    n = (hi - lo).astype(int) + 1
    a = np.eye(4)
    a[:3, 3] = lo
    idx = np.stack(np.meshgrid(*(np.arange(k) for k in n), indexing="ij"), axis=-1)
    x = idx + lo
    return DisplacementFieldWarp(u_of_x(x).astype(np.float32), a)


def test_colour_map_definition() -> None:
    """Identity clear; 2 and 1/2 full strength in their colours; folds solid; NaN clear."""
    ov = JacobianOverlay(opacity=0.5)
    c = detj_rgba(np.array([1.0, 2.0, 0.5, 4.0, 0.0, -3.0, np.nan, np.sqrt(2)]), ov)
    assert c[0, 3] == 0.0
    np.testing.assert_allclose(c[1], (*COMPRESSION_RGB, 0.5), atol=1e-6)
    np.testing.assert_allclose(c[2], (*EXPANSION_RGB, 0.5), atol=1e-6)
    np.testing.assert_allclose(c[3], (*COMPRESSION_RGB, 0.5), atol=1e-6)  # saturates
    np.testing.assert_allclose(c[4], (*FOLD_RGB, 1.0), atol=1e-6)
    np.testing.assert_allclose(c[5], (*FOLD_RGB, 1.0), atol=1e-6)
    assert c[6, 3] == 0.0
    assert c[7, 3] == pytest.approx(0.25, abs=1e-6)  # half way in log2
    with pytest.raises(RenderError, match="opacity"):
        JacobianOverlay(opacity=1.5)


def test_overlay_names_checked() -> None:
    assert check_overlays("jacobian, jacobian") == ("jacobian",)
    assert check_overlays(None) == ()
    with pytest.raises(RenderError, match="choose from jacobian"):
        check_overlays(["jacobian", "bogus"])


def test_legend_draws_in_the_corner_only() -> None:
    img = np.full((300, 400, 4), 200, np.uint8)
    draw_legend(img, JacobianOverlay())
    changed = np.any(img[..., :3] != 200, axis=2)
    rows, cols = np.nonzero(changed)
    assert rows.min() > 300 // 2
    assert cols.min() > 400 // 2
    fold = np.all(img[..., :3] == [round(v * 255) for v in FOLD_RGB], axis=2)
    assert fold.sum() > 20  # the fold swatch
    tiny = np.zeros((10, 10, 4), np.uint8)
    draw_legend(tiny, JacobianOverlay())  # too small: left alone
    assert not tiny.any()


def _slice(offscreen: Any, scene: Scene, size: tuple[int, int] = (48, 40), **kw: Any) -> Any:
    plane = SlicePlane.named("z", scene.deformed_bounds(), aspect=size[0] / size[1])
    return offscreen(16, 16).render_slice(scene, plane, size=size, overlay="jacobian", **kw)


def test_slice_detj_of_an_affine_scaling_is_the_product(offscreen: Any) -> None:
    """Forward scaling (1.2, 0.8, 1.5): det J = 1 / 1.44 at every pixel; the colours
    are the grey slice blended with the CPU colour map."""
    vol = _volume()
    scene = Scene(vol, warps=[AffineWarp.scaling((1.2, 0.8, 1.5), center=(0, 0, 0))])
    img = _slice(offscreen, scene, overlay_opacity=0.8)
    inside = np.isfinite(img.values)
    assert inside.mean() > 0.5
    np.testing.assert_allclose(img.detj[inside], 1 / 1.44, rtol=1e-5)
    assert np.all(np.isnan(img.detj[~inside]))
    plain = offscreen(16, 16).render_slice(scene, img.plane, size=img.size)
    c = detj_rgba(np.array(1 / 1.44), JacobianOverlay(opacity=0.8))
    expect = plain.rgba[..., :3] * (1 - c[3]) + c[:3] * 255 * c[3]
    h = img.size[1] // 2  # away from the legend (bottom right)
    np.testing.assert_allclose(img.rgba[:h, :, :3][inside[:h]], expect[:h][inside[:h]], atol=1)
    assert img.rgba[:h][inside[:h]][:, 0].mean() > plain.rgba[:h][inside[:h]][:, 0].mean()


def _numeric_det(warps: list, p: np.ndarray, eps: float = 1e-3) -> np.ndarray:
    cols = []
    for k in range(3):
        d = np.zeros(3)
        d[k] = eps
        cols.append((chain_apply(warps, p + d) - chain_apply(warps, p - d)) / (2 * eps))
    return np.linalg.det(np.stack(cols, axis=-1))


def test_slice_detj_equals_the_chain_at_pixel_centres(offscreen: Any) -> None:
    """A smooth field: det J per pixel = numeric det of chain_apply at the pixel centre,
    and = Scene.jacobian_determinant on its grid where pixel centres are nodes."""
    vol = _volume()

    def u(x: np.ndarray) -> np.ndarray:
        return np.stack(
            [3 * np.sin(x[..., 1] / 6.0), 2 * np.cos(x[..., 0] / 5.0), 0 * x[..., 2]], axis=-1
        )

    scene = Scene(vol, warps=[_field(u, vol)])
    img = _slice(offscreen, scene)
    inside = np.isfinite(img.detj)
    pts = pixel_centres(img.pixel_to_world, img.size).reshape(*img.detj.shape, 3)
    num = _numeric_det(scene.warps, pts[inside])
    assert np.ptp(img.detj[inside]) > 0.3  # a det J that varies over the slice
    np.testing.assert_allclose(img.detj[inside], num, atol=2e-3)
    # the grid det J of Scene.jacobian_determinant (chain_determinant) on a grid
    # whose nodes are the pixel centres: index (i, j, 0) = pixel (col i, row j)
    grid = np.array(img.pixel_to_world, dtype=np.float64)
    grid[:3, 2] = (0.0, 0.0, 1.0)
    ref = chain_determinant(scene.warps, grid, (img.size[0], img.size[1], 1))[..., 0].T
    # the slice's det J comes from the warps' GLSL Jacobians (the field's texture read
    # with 8-bit filter weights): GPU and CPU agree to 6e-4 here
    np.testing.assert_allclose(img.detj[inside], ref[inside], atol=2e-3)
    # and the CPU reference of the slice overlay is the grid's det J exactly
    cpu = slice_detj(scene.warps, img.pixel_to_world, img.values)
    np.testing.assert_allclose(cpu[inside], ref[inside], rtol=1e-6)


def test_fold_colour_exactly_where_det_j_is_negative(offscreen: Any) -> None:
    """u_x falls with slope -2 between x = -4 and 6 mm (node planes): det J = -1 there,
    1 elsewhere; the fold colour covers exactly the pixels whose centre is in between."""
    vol = _volume()
    a, b = -4.0, 6.0

    def u(x: np.ndarray) -> np.ndarray:
        out = np.zeros((*x.shape[:3], 3))
        out[..., 0] = -2.0 * (np.clip(x[..., 0], a, b) - a)
        return out

    scene = Scene(vol, warps=[_field(u, vol)])
    img = _slice(offscreen, scene, size=(64, 48))
    fold_rgb = np.array([round(v * 255) for v in FOLD_RGB])
    is_fold = np.all(img.rgba[..., :3] == fold_rgb, axis=2)
    x = pixel_centres(img.pixel_to_world, img.size)[:, 0].reshape(img.detj.shape)
    inside = np.isfinite(img.detj)
    clear = inside & ((x < a - 0.5) | (x > b + 0.5) | ((x > a + 0.5) & (x < b - 0.5)))
    h = img.size[1] // 2  # the legend (bottom right, it holds a fold swatch) left out
    want = (x > a) & (x < b) & inside
    assert want[:h][clear[:h]].sum() > 50
    np.testing.assert_array_equal(is_fold[:h][clear[:h]], want[:h][clear[:h]])
    np.testing.assert_allclose(img.detj[clear & want], -1.0, atol=1e-4)


def _tinted_mip(offscreen: Any, scene: Scene, overlay: JacobianOverlay | None) -> np.ndarray:
    r = offscreen(32, 32, "f4")
    r.renderer.jacobian_overlay = overlay
    try:
        return np.asarray(r.render(scene))
    finally:
        r.renderer.jacobian_overlay = None


@pytest.mark.parametrize("kind", ["affine", "field"])
def test_3d_overlay_glsl_matches_the_cpu_colour_map(offscreen: Any, kind: str) -> None:
    """One det J everywhere: every pixel the volume covers has the grey of the plain MIP
    blended with the CPU colour map of that det J (affine: straight rays; a linear
    field: the warped-ray path evaluating the chain's Jacobian per sample)."""
    vol = _volume(value=150)
    if kind == "affine":
        warps: list = [AffineWarp.scaling((1.3, 1.1, 1.2), center=(0, 0, 0))]
        det = 1 / (1.3 * 1.1 * 1.2)
    else:
        m = np.array([[0.3, 0.1, 0.0], [0.0, -0.2, 0.05], [0.1, 0.0, 0.25]])
        warps = [_field(lambda x: x @ m.T, vol, pad=14)]  # covers the deformed box
        det = float(np.linalg.det(np.eye(3) + m))
    scene = Scene(vol, mode="mip", warps=warps, view="-z", projection="orthographic")
    scene.window = (100.0, 200.0)
    plain = _tinted_mip(offscreen, scene, None)
    ov = JacobianOverlay(opacity=0.7)
    tinted = _tinted_mip(offscreen, scene, ov)
    c = detj_rgba(np.array(det), ov)
    covered = (plain[..., 3] > 0.5) & (plain[..., 0] > 0.1)  # a sample was taken
    covered[16:, 16:] = False  # the legend's corner (too small to draw at 32 px anyway)
    assert covered.sum() > 50
    expect = plain[..., :3] * (1 - c[3]) + c[:3] * c[3]
    # 5e-3: the field's texture is filtered with 8-bit weights, so its Jacobian varies a
    # little between samples (det J within 1%); the affine one is exact
    tol = 2e-3 if kind == "affine" else 5e-3
    np.testing.assert_allclose(tinted[..., :3][covered], expect[covered], atol=tol)
    assert np.abs(tinted - plain)[covered].max() > 0.05


@pytest.mark.parametrize("mode", ["dvr", "iso"])
def test_3d_overlay_in_dvr_and_iso_is_the_fold_colour_times_opacity(
    offscreen: Any, mode: str
) -> None:
    """A mirror warp folds everywhere (det J < 0): unshaded over black, every pixel of
    dvr and iso is the fold colour times the pixel's opacity (a solid tint)."""
    vol = _volume()
    warps = [AffineWarp(np.diag([-1.0, 1.0, 1.0, 1.0]))]
    scene = Scene(vol, mode=mode, warps=warps, view="-z", shading=False, background=(0, 0, 0, 0))
    tinted = _tinted_mip(offscreen, scene, JacobianOverlay(opacity=0.3))
    covered = tinted[..., 3] > 0.2
    covered[16:, 16:] = False
    assert covered.sum() > 50
    want = np.asarray(FOLD_RGB) * tinted[..., 3:4]
    np.testing.assert_allclose(tinted[..., :3][covered], want[covered], atol=2e-3)


def test_3d_overlay_leaves_other_modes_alone(offscreen: Any) -> None:
    """average has no one sample per pixel to colour: drawn as without the overlay."""
    scene = Scene(_volume(), mode="average", warps=[AffineWarp.scaling((0.7,) * 3)])
    plain = _tinted_mip(offscreen, scene, None)
    tinted = _tinted_mip(offscreen, scene, JacobianOverlay())
    np.testing.assert_array_equal(tinted, plain)
    with pytest.raises(RenderError, match="jacobian overlay colours"):
        check_detj_mode("average")


@pytest.mark.parametrize("slab_mm", [0.0, 6.0])
def test_overlay_leaves_the_slice_values_alone(offscreen: Any, slab_mm: float) -> None:
    """The det J output shares the slice's draw: the values (thin slice: from the same
    chain evaluation; slab: the slab loop) equal those drawn without it, and
    ``Renderer.slice_detj`` gives the same det J."""
    vol = _volume()

    def u(x: np.ndarray) -> np.ndarray:
        return np.stack([2 * np.sin(x[..., 1] / 5.0), 0 * x[..., 0], np.cos(x[..., 0] / 7.0)], -1)

    scene = Scene(vol, warps=[_field(u, vol)])
    img = _slice(offscreen, scene, slab_mm=slab_mm)
    plain = offscreen(16, 16).render_slice(scene, img.plane, size=img.size, slab_mm=slab_mm)
    np.testing.assert_array_equal(img.values, plain.values)
    np.testing.assert_array_equal(img.rest, plain.rest)
    r = offscreen(16, 16)
    with r.current():
        det = r.renderer.slice_detj(scene, img.pixel_to_world, img.size)
    ok = np.isfinite(img.detj)
    assert ok.sum() > 100
    np.testing.assert_array_equal(det[ok], img.detj[ok])


def test_legend_stays_on_top_of_the_grid_lines(offscreen: Any) -> None:
    """``render_slice(overlay="jacobian,grid")``: the grid lines are drawn first and the
    det J legend over them, so the legend's pixels are those of the det J-only slice."""
    vol = _volume()
    scene = Scene(vol, warps=[AffineWarp.scaling((1.2, 0.8, 1.5), center=(0, 0, 0))])
    only = _slice(offscreen, scene, size=(240, 200))
    both = offscreen(16, 16).render_slice(
        scene, only.plane, size=only.size, overlay="jacobian,grid", grid_spacing_mm=2.0
    )
    grey, black = np.full_like(only.rgba, 200), np.zeros_like(only.rgba)
    draw_legend(grey, JacobianOverlay())
    draw_legend(black, JacobianOverlay())
    # the legend's opaque pixels (its bar, swatch and text): the same on any background
    legend = np.all(grey[..., :3] == black[..., :3], axis=2) & np.any(grey[..., :3] != 200, axis=2)
    assert legend.sum() > 100
    np.testing.assert_array_equal(both.rgba[legend], only.rgba[legend])
    assert np.any(both.rgba[~legend] != only.rgba[~legend])  # the grid is drawn
