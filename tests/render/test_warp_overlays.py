"""The warped grid and glyphs: slice drawing and the 3D meshes.

Oracles:

* 3D grid (CPU): the tubes' rest vertices ring the lattice lines at multiples of N; the
  mesh pass's baked positions (:func:`voxwarp.core.mesh_warp.warped_geometry`) of each
  ring are centred on the chain's forward map of the rest line point (a smooth
  displacement field, solved independently by :func:`chain_forward`);
* 3D glyphs (CPU): built in deformed space and stored pulled back, so the baked arrow
  tips equal ``x + s u(x)`` with ``u = chain(x) - x`` computed here;
* 3D render (GPU): with an invisible volume and a translation, the grid's pixels are
  the camera projections of the translated lattice lines (the lines land where
  :meth:`Camera.project` puts the forward-mapped points, and nowhere else);
* slice drawing: the yellow pixels of a drawn grid are the pixels the analytic
  coverage marks.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.mesh_warp import warped_geometry
from voxwarp.core.volume import Volume
from voxwarp.core.warp_grid import grid_coverage, lattice_lines, pixel_points, pull_back
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import AffineWarp, chain_apply, chain_forward
from voxwarp.render.warp_meshes import TUBE_SIDES, camera_pixel_mm, facing_plane, overlay_meshes
from voxwarp.render.warp_overlays import GRID_RGB, draw_slice_overlays
from voxwarp.scene import Scene

N = 8.0


def _volume() -> Volume:
    return Volume(np.zeros((24, 20, 16), np.uint8), (2.0, 2.0, 2.0), (-20.0, -15.0, -10.0))


def _smooth_field(vol: Volume) -> DisplacementFieldWarp:
    """A smooth pull-back field (|u| up to 3 mm) on a grid wider than the volume."""
    shape = (36, 32, 28)
    affine = np.diag([2.0, 2.0, 2.0, 1.0])
    affine[:3, 3] = np.asarray(vol.bounds[0]) - 12.0
    idx = np.stack(np.meshgrid(*[np.arange(s) for s in shape], indexing="ij"), -1)
    p = idx @ affine[:3, :3].T + affine[:3, 3]
    u = np.zeros((*shape, 3))
    u[..., 0] = 3.0 * np.sin(p[..., 1] / 9.0)
    u[..., 1] = 2.0 * np.cos(p[..., 2] / 11.0)
    u[..., 2] = 1.5 * np.sin(p[..., 0] / 13.0)
    return DisplacementFieldWarp(u, affine)


def test_grid_tubes_follow_the_forward_map() -> None:
    vol = _volume()
    warps = [_smooth_field(vol)]
    scene = Scene(vol, warps=warps)
    (inst,) = overlay_meshes(scene, ["grid"], N, "coronal")
    lo, hi = vol.bounds
    centres = np.concatenate(lattice_lines(lo, hi, N, "coronal"))
    rest = inst.mesh.vertices.reshape(-1, TUBE_SIDES, 3).astype(np.float64)
    np.testing.assert_allclose(rest.mean(axis=1), centres, atol=1e-4)
    baked, _, _ = warped_geometry(inst, warps)
    rings = baked.reshape(-1, TUBE_SIDES, 3).mean(axis=1)
    expect = chain_forward(warps, centres)
    assert np.abs(expect - centres).max() > 1.0  # the grid really moves
    np.testing.assert_allclose(rings, expect, atol=0.02)


def test_glyph_arrows_point_along_u() -> None:
    vol = _volume()
    warps = [_smooth_field(vol)]
    scene = Scene(vol, warps=warps)
    (inst,) = overlay_meshes(scene, ["glyphs"], N, "axial")
    baked, _, _ = warped_geometry(inst, warps)
    per_arrow = 2 * TUBE_SIDES + 7  # shaft rings, cone ring and tip
    arrows = baked.reshape(-1, per_arrow, 3)
    tails = arrows[:, :TUBE_SIDES].mean(axis=1)
    tips = arrows[:, -1]
    u = chain_apply(warps, tails) - tails
    scale = 0.9 * N / np.linalg.norm(u, axis=1).max()
    np.testing.assert_allclose(tips - tails, scale * u, atol=0.02)
    lo, hi = scene.deformed_bounds()
    np.testing.assert_allclose(tails[:, 2], (lo[2] + hi[2]) / 2, atol=0.01)


def test_rendered_grid_lands_on_the_projected_lines(offscreen: Any) -> None:
    vol = _volume()
    shift = np.array([3.0, 0.0, -2.0])
    tf = [(0, 0, 0, 0, 0), (255, 1, 1, 1, 0)]  # an invisible volume
    scene = Scene(vol, "dvr", tf, projection="orthographic", warps=[AffineWarp.translation(shift)])
    cam = scene.resolved_camera()
    plane = facing_plane(cam)
    assert plane == "coronal"  # the default view looks along y
    size = 96
    meshes = overlay_meshes(scene, ["grid"], N, plane, pixel_mm=camera_pixel_mm(cam, (size,) * 2))
    img = offscreen(size, size, "f4").render(scene.copy(meshes=meshes, camera=cam))
    rgb = np.asarray(img)[..., :3]
    lit = rgb.max(axis=-1) > 0.05
    lo, hi = vol.bounds
    pts = np.concatenate([np.linspace(p[0], p[-1], 200) for p in lattice_lines(lo, hi, N, plane)])
    px = cam.project(pts + shift, (size, size))
    cols, rows = np.clip(px.astype(int), 0, size - 1).T
    assert lit[rows, cols].mean() > 0.9  # the lines are where the forward map puts them
    near = np.zeros_like(lit)
    for dr in (-2, -1, 0, 1, 2):
        for dc in (-2, -1, 0, 1, 2):
            near[np.clip(rows + dr, 0, size - 1), np.clip(cols + dc, 0, size - 1)] = True
    assert lit.sum() > 200
    assert not np.any(lit & ~near)  # and nowhere else
    unshifted = cam.project(pts, (size, size)).astype(int)
    assert np.abs(unshifted - px.astype(int)).max() >= 3  # the shift is visible


@pytest.mark.parametrize("overlays", [["grid"], ["grid", "glyphs"]])
def test_slice_grid_pixels_match_the_coverage(overlays: list[str]) -> None:
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 3] = (-1.0, 0, 0), (0, -1.0, 0), (40.0, 30.0, 0.0)
    warps = [AffineWarp.scaling(1.25, (5.0, 5.0, 0.0))]
    rgba = np.full((60, 80, 4), 100, np.uint8)  # grey under the lines
    rgba[..., 3] = 255
    out, notes = draw_slice_overlays(rgba, warps, m, overlays, 10.0)
    rest = pull_back(warps, pixel_points(m, (80, 60)))
    on = (np.abs(rest[..., 0] / 10 - np.round(rest[..., 0] / 10)) * 10 / 0.8 < 0.2) | (
        np.abs(rest[..., 1] / 10 - np.round(rest[..., 1] / 10)) * 10 / 0.8 < 0.2
    )
    yellow = np.asarray(GRID_RGB) * 255 * 0.8 + 100 * 0.2  # "over" at coverage 0.8
    if overlays == ["grid"]:
        np.testing.assert_allclose(out[on, :3], np.broadcast_to(yellow, (on.sum(), 3)), atol=1)
        assert len(notes) == 1
        far = np.isclose(grid_coverage(rest, (m[:3, 0], m[:3, 1]), 10.0), 0.0)
        assert np.all(out[far][:, :3] == 100)  # untouched away from the lines
        assert np.all(out[..., 3] == 255)
    else:
        assert "legend" in notes[1]
        assert out[:20, -60:, 2].max() > 200  # the legend arrow and text (cyan), top right
