"""Piecewise-linear warped rays (voxwarp.render.skipping.segments, PIECEWISE in the shader).

Oracles: a displacement field that is linear in position (its chord error is zero, so
segments must reproduce the per-sample image), the chord error measured densely along
segments of the lengths the map allows, and the per-sample image of each family.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import IdentityWarp, chain_apply
from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.families.wires import WiresFamily
from voxwarp.editing.session import EditSession
from voxwarp.errors import RenderError
from voxwarp.render.skipping.segments import RaySegments, segment_lengths
from voxwarp.scene import Scene

SIZE = 160


def shells() -> Volume:
    """Two concentric shells and a rod in a 48³ box: thin, sharp-edged content."""
    x, y, z = np.meshgrid(*[np.arange(48.0)] * 3, indexing="ij")
    r = np.sqrt((x - 24) ** 2 + (y - 24) ** 2 + (z - 24) ** 2)
    data = np.where(np.abs(r - 14) < 1.5, 200, 0) + np.where(np.abs(r - 7) < 1.0, 120, 0)
    data += np.where((np.hypot(x - 24, y - 30) < 2) & (r < 18), 160, 0)
    return Volume(data.astype(np.uint8), spacing=(1.0, 1.0, 1.0))


TF = TransferFunction([(0, 0, 0, 0, 0), (60, 1, 0.6, 0.3, 0.0), (255, 1, 1, 0.9, 0.6)])


def field(volume: Volume, vectors: Any, nodes: int = 12, margin: float = 0.6) -> Any:
    """A field on a grid ``margin`` wider than the volume per side; ``vectors(x)`` gives
    u (mm) at world points x (N, 3)."""
    lo, hi = (np.asarray(b, float) for b in volume.bounds)
    size = hi - lo
    glo, ghi = lo - margin * size, hi + margin * size
    axes = [np.linspace(glo[a], ghi[a], nodes) for a in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    u = np.asarray(vectors(pts), np.float32).reshape(nodes, nodes, nodes, 3)
    affine = np.eye(4)
    affine[:3, :3] = np.diag((ghi - glo) / (nodes - 1))
    affine[:3, 3] = glo
    return DisplacementFieldWarp(u, affine)


def render(offscreen: Any, scene: Scene, segment: Any) -> np.ndarray:
    r = offscreen(SIZE, SIZE)
    r.renderer.warped_skip_maps = "always"
    r.renderer.ray_segment = segment
    try:
        img = r.render(scene)
        assert r.renderer.last_skip_kind == "cells"
        assert r.renderer.last_ray_segment == (0 if segment == "auto" else segment)
    finally:
        r.renderer.ray_segment = 1
        r.renderer.warped_skip_maps = "auto"
    return img[..., :3].astype(float)


def shaded_scene(volume: Volume, warps: list) -> Scene:
    return Scene(
        volume, transfer_function=TF, warps=warps, view=(-50, 25), jitter=False, shading=True
    )


def test_a_linear_field_renders_the_same_with_segments_of_8(offscreen: Any) -> None:
    """u = A (x - c) is affine, so its chord error is zero: segments of 8 samples must
    give the per-sample image (shading through the interpolated Jacobian included)."""
    vol = shells()
    a = np.array([[0.08, 0.05, 0.0], [-0.04, 0.06, 0.03], [0.02, 0.0, -0.07]])
    c = np.array([24.0, 24.0, 24.0])
    scene = shaded_scene(vol, [field(vol, lambda x: (x - c) @ a.T)])
    exact = render(offscreen, scene, 1)
    pieces = render(offscreen, scene, 8)
    assert exact.max() > 100  # something is drawn
    assert np.abs(pieces - exact).max() <= 3.0


def test_a_bend_with_segments_of_8_differs_and_auto_stays_close(offscreen: Any) -> None:
    """A sinusoidal bend: fixed segments of 8 samples move thin shells visibly, the
    automatic map keeps the image within a few levels of the per-sample one."""
    vol = shells()
    scene = shaded_scene(
        vol,
        [field(vol, lambda x: np.stack([4 * np.sin(x[:, 2] / 5.0), 0 * x[:, 0], 0 * x[:, 0]], 1))],
    )
    exact = render(offscreen, scene, 1)
    fixed = np.abs(render(offscreen, scene, 8) - exact)
    auto = np.abs(render(offscreen, scene, "auto") - exact)
    assert fixed.max() > 20  # the test can tell a wrong interpolation
    assert auto.mean() <= 0.05
    assert np.percentile(auto, 99.9) <= 8.0
    assert auto.mean() < fixed.mean() / 4


@pytest.mark.parametrize("family", ["lattice", "wires", "massspring"])
def test_auto_segments_keep_each_family_close_to_per_sample(offscreen: Any, family: str) -> None:
    """An edit per family (as ``voxwarp bench interactive`` makes); the image with the
    automatic segment map stays within the stated tolerance of the per-sample one."""
    vol = shells()
    session = EditSession(shaded_scene(vol, []))
    try:
        size = vol.bounds[1][0] - vol.bounds[0][0]
        if family == "lattice":
            session.set_deformation("lattice", resolution=4)
            nodes = session.adapter(LatticeFamily).lattice_nodes.copy()
            nodes[1, 1, 2, 0] += 0.2 * size
            session.adapter(LatticeFamily).set_lattice_nodes(nodes)
        elif family == "wires":
            session.set_deformation("wires")
            pts = session.adapter(WiresFamily).wires[0].modified.control_points.copy()
            pts[2, 0] += 0.2 * size
            session.adapter(WiresFamily).set_wire_points(0, pts)
            job = session.family.build_job()
            job.run()
            session.family.install(job)
        else:
            session.set_deformation("massspring", resolution=6)
            model = session.model
            model.move((3, 3, 3), (0.15 * size, 0.0, 0.0))
            model.settle(max_steps=2000)
            session.model_moved()
        exact = render(offscreen, session.scene, 1)
        auto = np.abs(render(offscreen, session.scene, "auto") - exact)
    finally:
        session.close()
    assert exact.max() > 100
    assert auto.mean() <= 0.1
    assert np.percentile(auto, 99.9) <= 16.0


def chord_deviation(warps: list, p: np.ndarray, d: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Largest distance (mm = texels here) between the chain and its chord along each
    segment p + s h d, s in [0, 1], checked at 17 points."""
    s = np.linspace(0.0, 1.0, 17)
    pts = p[:, None, :] + (s[None, :, None] * h[:, None, None]) * d[:, None, :]
    q = chain_apply(warps, pts.reshape(-1, 3)).reshape(pts.shape)
    chord = q[:, :1] + s[None, :, None] * (q[:, -1:] - q[:, :1])
    return np.linalg.norm(q - chord, axis=-1).max(axis=1)


def test_the_map_keeps_dense_chord_errors_within_the_tolerance() -> None:
    """Random segments starting anywhere, in any direction, with the length the map
    allows at their start: the chain leaves its chord by at most the tolerance."""
    vol = shells()
    w = field(
        vol,
        lambda x: np.stack([np.sin(x[:, 1] / 10.0), np.cos(x[:, 2] / 12.0), 0 * x[:, 0]], 1),
    )
    lo, hi = np.zeros(3) - 0.5, np.full(3, 47.5)
    tol = 0.1
    m = segment_lengths([w], lo, hi, np.eye(4), tol, 16.0)
    assert np.median(m.lengths) >= 2.0  # segments of several samples where the field is smooth
    assert m.lengths.max() <= 16.0
    rng = np.random.default_rng(3)
    p = lo + rng.random((3000, 3)) * (hi - lo)
    d = rng.normal(size=(3000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cell = np.clip(((p - m.lo) / m.cell).astype(int), 0, np.array(m.lengths.shape) - 1)
    h = m.lengths[tuple(cell.T)].astype(float)
    assert chord_deviation([w], p, d, h).max() <= tol


def test_identity_allows_the_longest_segments_and_a_tear_none() -> None:
    """No bend: every cell allows the longest segment. A field that does not fall to 0
    at its grid's edge tears there (ITK's field stops half a node outside): cells at the
    tear allow no segment, cells far from it the longest."""
    lo, hi = np.zeros(3), np.full(3, 60.0)
    m = segment_lengths([IdentityWarp()], lo, hi, np.eye(4), 0.1, 16.0)
    assert np.all(m.lengths == 16.0)
    u = np.full((4, 4, 4, 3), 5.0, np.float32)  # constant 5 mm on x in [0, 30]³
    affine = np.diag([10.0, 10.0, 10.0, 1.0])
    t = segment_lengths([DisplacementFieldWarp(u, affine)], lo, hi, np.eye(4), 0.1, 16.0)
    tear = t.lo[0] + (np.arange(t.lengths.shape[0]) + 0.5) * t.cell[0]
    near = np.abs(tear - 35.0) < t.cell[0]  # x = 35: half a node past the last node
    assert np.all(t.lengths[near, :5, :5] == 0)
    assert np.all(t.lengths[:2, :2, :2] == 16.0)
    assert np.all(t.lengths[-2:, -2:, -2:] == 16.0)


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"setting": 0}, "ray_segment must be 'auto' or an int >= 1"),
        ({"setting": "fast"}, "ray_segment must be 'auto'"),
        ({"setting": True}, "ray_segment must be 'auto'"),
        ({"tolerance": -1}, "ray_tolerance must be a number >= 0"),
        ({"tolerance": float("nan")}, "ray_tolerance must be a number >= 0"),
    ],
)
def test_bad_settings_name_the_fix(kwargs: dict, pattern: str) -> None:
    with pytest.raises(RenderError, match=pattern):
        RaySegments(**kwargs)
