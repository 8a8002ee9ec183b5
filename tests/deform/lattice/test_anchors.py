"""Anchors (deform/lattice/anchors.py): attached geometry follows a deforming base mesh.

Oracles: anchor points are barycentric, so they equal the same combination of the moved
triangle's corners; frames stay orthonormal and right-handed with z the triangle normal;
an attached object's bottom face touches the base mesh exactly at the anchors.
"""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.deform.lattice.anchors import Anchor, AnchorStrip, anchor_frames, anchors_at
from voxwarp.deform.warp import WarpError


def sheet(n: int = 6, size: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n-vertex sheet in the z = 0 plane, two triangles per quad (normal +z)."""
    g = np.linspace(0.0, size, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    f = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
            f += [[a, b, c], [a, c, d]]
    return v, np.array(f)


def bend(v: np.ndarray, radius: float = 8.0) -> np.ndarray:
    """Roll the sheet around the y axis onto a cylinder of ``radius`` (arc length kept)."""
    ang = v[:, 0] / radius
    return np.stack([radius * np.sin(ang), v[:, 1], radius * (1 - np.cos(ang)) + v[:, 2]], axis=1)


def test_anchor_points_follow_the_triangle_exactly() -> None:
    v, f = sheet()
    rng = np.random.default_rng(0)
    anchors = []
    for _ in range(20):
        w = rng.dirichlet([1, 1, 1])
        anchors.append(Anchor(int(rng.integers(len(f))), tuple(w), (0.2, 0.4, 0.4)))
    for verts in (v, bend(v), bend(v) * 1.5 + 3.0):
        p, frames = anchor_frames(anchors, verts, f)
        expected = np.array([np.asarray(a.position) @ verts[f[a.triangle]] for a in anchors])
        np.testing.assert_allclose(p, expected, atol=1e-12)
        # orthonormal, right-handed, z = the triangle's normal
        np.testing.assert_allclose(
            np.einsum("kji,kjl->kil", frames, frames),
            np.broadcast_to(np.eye(3), frames.shape),
            atol=1e-12,
        )
        np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=1e-12)
        for a, fr in zip(anchors, frames, strict=True):
            t = verts[f[a.triangle]]
            n = np.cross(t[1] - t[0], t[2] - t[0])
            np.testing.assert_allclose(fr[:, 2], n / np.linalg.norm(n), atol=1e-12)


def test_strip_nodes_touch_the_surface_at_the_anchors() -> None:
    v, f = sheet(9)
    pts = np.array([[x, 5.0, 0.0] for x in np.linspace(1.0, 9.0, 6)])
    anchors = anchors_at(v, f, pts, np.tile([1.0, 0.0, 0.0], (6, 1)))
    strip = AnchorStrip(anchors, thickness=2.0, width=3.0)
    for verts in (v, bend(v)):
        nodes = strip.nodes(verts, f)
        assert nodes.shape == (6, 2, 2, 3)
        p, fr = anchor_frames(anchors, verts, f)
        # the bottom face's centre line is the anchor line, the top 2 mm above it
        np.testing.assert_allclose(nodes[:, :, 0].mean(axis=1), p, atol=1e-12)
        np.testing.assert_allclose(nodes[:, 0, 1] - nodes[:, 0, 0], 2.0 * fr[:, :, 2], atol=1e-12)
        np.testing.assert_allclose(
            np.linalg.norm(nodes[:, 1, 0] - nodes[:, 0, 0], axis=1), 3.0, atol=1e-12
        )


def test_attached_grid_follows_a_bending_base() -> None:
    pytest.importorskip("voxwarp.deform.lattice.trilinear")
    v, f = sheet(9)
    pts = np.array([[x, y, 0.0] for x in (2.0, 5.0, 8.0) for y in (3.0, 7.0)])
    flat = anchors_at(v, f, pts, np.tile([1.0, 0.0, 0.0], (6, 1)))
    patch = AnchorStrip([flat[0::2], flat[1::2]], thickness=1.5)  # 2 rows x 3
    for verts in (v, bend(v, 6.0)):
        grid = patch.grid(verts, f)
        p, _ = anchor_frames([a for row in patch.anchors for a in row], verts, f)
        m, n = 2, 3
        u = np.array([[i / (m - 1), j / (n - 1), 0.0] for i in range(m) for j in range(n)])
        # the attached object's bottom corners sit on the anchor points
        np.testing.assert_allclose(grid(u), p, atol=1e-9)


@pytest.mark.parametrize(
    ("make", "fragment"),
    [
        (lambda: Anchor(0, (0.5, 0.5, 0.5), (1, 0, 0)), "sum to 1"),
        (lambda: Anchor(0, (1, 0, 0), (1, 0, 0)), "must differ"),
        (lambda: Anchor(-1, (1, 0, 0), (0, 1, 0)), "face index"),
        (lambda: Anchor(0, (np.nan, 0, 1), (0, 1, 0)), "NaN"),
        (lambda: AnchorStrip([Anchor(0, (1, 0, 0), (0, 1, 0))], 1.0, 1.0), ">= 2 anchors"),
        (
            lambda: AnchorStrip([Anchor(0, (1, 0, 0), (0, 1, 0))] * 2, 1.0),
            "needs width",
        ),
        (lambda: AnchorStrip([Anchor(0, (1, 0, 0), (0, 1, 0))] * 2, 0.0, 1.0), "thickness"),
    ],
)
def test_bad_anchors_raise_clear_errors(make: object, fragment: str) -> None:
    with pytest.raises(WarpError) as exc:
        make()  # type: ignore[operator]
    assert fragment in str(exc.value)


def test_bad_base_meshes_raise_clear_errors() -> None:
    v, f = sheet(3)
    a = [Anchor(len(f), (1, 0, 0), (0, 1, 0))]
    with pytest.raises(WarpError, match="does not exist"):
        anchor_frames(a, v, f)
    flat = v.copy()
    flat[:, 1] = 0.0  # every triangle degenerate
    with pytest.raises(WarpError, match="degenerate"):
        anchor_frames([Anchor(0, (1, 0, 0), (0, 1, 0))], flat, f)
    with pytest.raises(WarpError, match="NaN"):
        anchor_frames([Anchor(0, (1, 0, 0), (0, 1, 0))], v * np.nan, f)


def test_anchor_dict_round_trip() -> None:
    a = Anchor(3, (0.2, 0.3, 0.5), (0.1, 0.1, 0.8))
    assert Anchor.from_dict(a.to_dict()) == a
