"""DisplacementFieldWarp: the ITK pull-back map, its GLSL twin, forward map and bounds.

Oracles: SimpleITK's DisplacementFieldTransform (TransformPoint), finite differences,
the CPU reference against the GLSL, and inverse/forward round trips.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy import ndimage

from tests.warp_gpu import gpu_warp
from voxwarp.deform.fields.displacement import DisplacementFieldWarp, sample_chain_field
from voxwarp.deform.warp import WarpError, rotation_matrix, warp_from_dict

sitk = pytest.importorskip("SimpleITK")

SHAPE = (9, 8, 7)
SPACING = np.array([4.0, 5.0, 3.5])
ROTATION = rotation_matrix((1.0, 2.0, 3.0), 25.0)
ORIGIN = np.array([-20.0, 5.0, 3.0])


def grid_affine(rotation: np.ndarray = ROTATION) -> np.ndarray:
    a = np.eye(4)
    a[:3, :3] = rotation * SPACING
    a[:3, 3] = ORIGIN
    return a


def smooth_vectors(shape: tuple[int, int, int], amplitude: float, seed: int) -> np.ndarray:
    """Random vectors smoothed over ~2 nodes, scaled to ``amplitude`` mm at most."""
    rng = np.random.default_rng(seed)
    u = np.stack(
        [ndimage.gaussian_filter(rng.normal(size=shape), 1.5, mode="nearest") for _ in range(3)],
        axis=-1,
    )
    return (u / np.abs(u).max() * amplitude).astype(np.float32)


def tapered(u: np.ndarray) -> np.ndarray:
    """``u`` falling to 0 at the grid's faces, as registration fields usually do: no tear
    at the half-node border where ITK's field stops."""
    w = [np.sin(np.pi * np.linspace(0, 1, n)) for n in u.shape[:3]]
    window = w[0][:, None, None] * w[1][None, :, None] * w[2][None, None, :]
    return (u * window[..., None]).astype(np.float32)


def sitk_transform(u_lps: np.ndarray, affine_lps: np.ndarray) -> Any:
    img = sitk.GetImageFromArray(u_lps.transpose(2, 1, 0, 3).astype(np.float64), isVector=True)
    spacing = np.linalg.norm(affine_lps[:3, :3], axis=0)
    img.SetSpacing(spacing.tolist())
    img.SetDirection((affine_lps[:3, :3] / spacing).ravel().tolist())
    img.SetOrigin(affine_lps[:3, 3].tolist())
    return sitk.DisplacementFieldTransform(img)


def points_around(w: DisplacementFieldWarp, n: int, seed: int, margin: float = 0.0) -> np.ndarray:
    """Random world points over the field's support (grown by ``margin`` nodes)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-0.5 - margin, np.asarray(w.shape) - 0.5 + margin, (n, 3))
    return c @ w.affine[:3, :3].T + w.affine[:3, 3]


LPS = np.array([-1.0, -1.0, 1.0])


def test_apply_matches_sitk_transform_point_on_an_oblique_lps_grid() -> None:
    # the field as ITK holds it: LPS vectors on an LPS grid, rotated 25 degrees
    u = smooth_vectors(SHAPE, 6.0, 0)
    t = sitk_transform(u, grid_affine())
    w = DisplacementFieldWarp(u, grid_affine(), space="LPS")
    p_ras = points_around(w, 3000, 1, margin=1.0)  # inside, the half-node border, outside
    ref = np.array([t.TransformPoint(tuple(q)) for q in p_ras * LPS]) * LPS
    moved = np.linalg.norm(ref - p_ras, axis=1) > 1e-9
    assert 0.5 < moved.mean() < 0.95  # both regimes sampled
    # float32 vectors vs ITK's float64 image of the same values: measured 6e-8 mm
    np.testing.assert_allclose(w.apply(p_ras), ref, atol=1e-5)


def test_half_node_border_clamps_and_beyond_is_identity() -> None:
    u = np.zeros((3, 3, 3, 3), np.float32)
    u[..., 0] = 2.0
    w = DisplacementFieldWarp(u, np.diag([10.0, 10.0, 10.0, 1.0]))
    p = np.array([[-4.9, 10, 10], [-5.1, 10, 10], [24.9, 10, 10], [25.1, 10, 10]])
    np.testing.assert_allclose(w.apply(p) - p, [[2, 0, 0], [0, 0, 0], [2, 0, 0], [0, 0, 0]])


def test_units_voxel_and_space_lps_are_converted_to_ras_mm() -> None:
    u_vox = smooth_vectors(SHAPE, 1.0, 2)
    a = grid_affine()
    w_vox = DisplacementFieldWarp(u_vox, a, units="voxel")
    np.testing.assert_allclose(w_vox.displacements, u_vox @ a[:3, :3].T, rtol=1e-5, atol=1e-5)
    w_lps = DisplacementFieldWarp(u_vox, a, space="LPS")
    np.testing.assert_allclose(w_lps.affine, np.diag([-1.0, -1, 1, 1]) @ a)
    np.testing.assert_allclose(w_lps.displacements, u_vox * LPS.astype(np.float32))


def test_jacobian_matches_finite_differences() -> None:
    w = DisplacementFieldWarp(smooth_vectors(SHAPE, 5.0, 3), grid_affine())
    # points inside the clamped-free interior, away from cell faces in general
    c = np.random.default_rng(4).uniform(0.2, np.asarray(SHAPE) - 1.2, (200, 3))
    p = c @ w.affine[:3, :3].T + w.affine[:3, 3]
    h = 1e-4
    fd = np.stack([(w.apply(p + e) - w.apply(p - e)) / (2 * h) for e in np.eye(3) * h], axis=-1)
    np.testing.assert_allclose(w.jacobian(p), fd, atol=1e-3)


def test_glsl_matches_the_cpu_reference(gl_ctx: Any) -> None:
    u = smooth_vectors(SHAPE, 6.0, 5)
    w = DisplacementFieldWarp(u, grid_affine())
    half = DisplacementFieldWarp(u.astype(np.float16), grid_affine())  # what the texture holds
    try:
        p = points_around(w, 400, 6, margin=1.0)
        q, jac = gpu_warp(gl_ctx, w, p)
        llvmpipe = "llvmpipe" in gl_ctx.info.get("GL_RENDERER", "")
        # float32 index arithmetic and float filter weights: measured max 4.3e-6 mm on
        # llvmpipe; GPUs with 8-bit filter weights are off by up to |du| / 256 per fetch
        np.testing.assert_allclose(q, half.apply(p), atol=1e-4 if llvmpipe else 5e-2)
        # the GLSL Jacobian is the analytic one of the trilinear interpolant, as the CPU
        # reference, over the whole range (the half-node border and outside included)
        err = np.abs(jac - half.jacobian(p)).max(axis=(1, 2))
        # measured on llvmpipe: max 2.2e-7, median 2.9e-8
        assert np.median(err) < 1e-4
        assert np.quantile(err, 0.99) < (1e-3 if llvmpipe else 5e-2)
    finally:
        w.release()
        w.release()  # idempotent


def test_glsl_shaded_warp_keeps_its_jacobian(gl_ctx: Any) -> None:
    """Compiled for shading, warp(p) reads u from its cell's 8 nodes and keeps the
    Jacobian at p: the same points and the same Jacobian as the plain program, with one
    read of the nodes (the half-node border and the outside included)."""
    u = smooth_vectors(SHAPE, 6.0, 9)
    w = DisplacementFieldWarp(u, grid_affine())
    half = DisplacementFieldWarp(u.astype(np.float16), grid_affine())
    try:
        p = points_around(w, 400, 10, margin=1.0)
        q, jac = gpu_warp(gl_ctx, w, p)
        q_kept, jac_kept = gpu_warp(gl_ctx, w, p, kept=True, shading=True)
        # the 8 nodes' trilinear value against the filtered fetch: float rounding on
        # llvmpipe; GPUs with 8-bit filter weights: up to |du| / 256 per fetch
        llvmpipe = "llvmpipe" in gl_ctx.info.get("GL_RENDERER", "")
        np.testing.assert_allclose(q_kept, q, atol=1e-4 if llvmpipe else 5e-2)
        np.testing.assert_allclose(q_kept, half.apply(p), atol=1e-4)
        np.testing.assert_allclose(jac_kept, jac, atol=1e-6)
        assert np.abs(jac - np.eye(3)).max() > 0.05  # the field's gradient is in it
    finally:
        w.release()


def test_forward_inverts_apply_on_a_smooth_field() -> None:
    w = DisplacementFieldWarp(tapered(smooth_vectors(SHAPE, 6.0, 7)), grid_affine())
    p = points_around(w, 2000, 8, margin=0.5)
    x = w.apply(p)
    back = w.forward(x)
    np.testing.assert_allclose(w.apply(back), x, atol=w.forward_tolerance)
    # no fold: the preimage is unique, so forward returns the point we started from
    np.testing.assert_allclose(back, p, atol=1e-2)


def test_forward_names_a_folded_field() -> None:
    u = np.zeros((5, 5, 5, 3), np.float32)
    u[2, 2, 2, 0] = 25.0  # one node pushed 2.5 cells: the field folds around it
    w = DisplacementFieldWarp(u, np.diag([10.0, 10.0, 10.0, 1.0]))
    x = np.array([[20.0 + s, 20.0, 20.0] for s in np.linspace(-8, 30, 60)])
    with pytest.raises(WarpError, match="folds or tears there") as info:
        w.forward(x)
    assert "\n" not in str(info.value)


def test_displacement_range_holds_sampled_displacements() -> None:
    w = DisplacementFieldWarp(smooth_vectors(SHAPE, 6.0, 9), grid_affine())
    rng = np.random.default_rng(10)
    lo = points_around(w, 300, 11, margin=2.0)
    hi = lo + rng.uniform(0.5, 15.0, (300, 3))
    a, b = w.displacement_range(lo, hi)
    for i in range(0, 300, 3):
        p = rng.uniform(lo[i], hi[i], (200, 3))
        d = w.apply(p) - p
        assert np.all(d >= a[i] - 1e-6)
        assert np.all(d <= b[i] + 1e-6)
    # local: a box far outside the field's support is not moved at all
    far_lo, far_hi = np.full((1, 3), 500.0), np.full((1, 3), 510.0)
    fa, fb = w.displacement_range(far_lo, far_hi)
    np.testing.assert_array_equal(np.r_[fa, fb], 0.0)
    # and tight: inside the grid the interval is much narrower than the global range
    width = (b - a)[np.all(np.isfinite(b - a), axis=1)]
    glob = np.ptp(w.displacements.reshape(-1, 3), axis=0)
    assert np.median(width / glob) < 0.8


def test_deformed_bounds_hold_every_deformed_point() -> None:
    w = DisplacementFieldWarp(tapered(smooth_vectors(SHAPE, 8.0, 12)), grid_affine())
    lo, hi = np.array([-10.0, 0.0, 0.0]), np.array([15.0, 30.0, 25.0])
    x = np.random.default_rng(13).uniform(lo, hi, (3000, 3))
    p = w.forward(x)
    dlo, dhi = w.deformed_bounds(lo, hi)
    assert np.all(p >= dlo - 1e-6)
    assert np.all(p <= dhi + 1e-6)


def test_embedded_scene_entry_round_trip() -> None:
    w = DisplacementFieldWarp(smooth_vectors(SHAPE, 3.0, 14), grid_affine())
    back = warp_from_dict(w.to_dict())
    assert isinstance(back, DisplacementFieldWarp)
    np.testing.assert_array_equal(back.displacements, w.displacements)
    np.testing.assert_array_equal(back.affine, w.affine)


def test_sample_chain_field_reproduces_the_field_at_its_nodes() -> None:
    w = DisplacementFieldWarp(smooth_vectors(SHAPE, 3.0, 15), grid_affine())
    u = sample_chain_field(w.apply, w.affine, w.shape)
    np.testing.assert_allclose(u, w.displacements, atol=1e-5)


@pytest.mark.parametrize(
    ("u", "affine", "pattern"),
    [
        (np.zeros((4, 4, 4, 2)), np.eye(4), "needs 3 components per node"),
        (np.zeros((4, 4, 3)), np.eye(4), "must be 3-D with 3 components"),
        (np.zeros((4, 4, 1, 3)), np.eye(4), "2-D field cannot deform"),
        (np.full((3, 3, 3, 3), np.nan), np.eye(4), "NaN/Inf"),
        (np.full((3, 3, 3, 3), 1e6), np.eye(4), "check the units"),
        (np.zeros((3, 3, 3, 3)), np.diag([1.0, 0.0, 1.0, 1.0]), "singular"),
        (np.zeros((3, 3, 3, 3)), np.eye(3), "must be 4x4"),
        ("abc", np.eye(4), "numeric"),
    ],
)
def test_bad_fields_raise_one_line_errors(u: Any, affine: Any, pattern: str) -> None:
    with pytest.raises(WarpError, match=pattern) as info:
        DisplacementFieldWarp(u, affine)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("entry", "pattern"),
    [
        ({"type": "displacement_field"}, "needs 'path', or 'affine'"),
        (
            {
                "type": "displacement_field",
                "affine": np.eye(4).tolist(),
                "shape": [2, 2, 2],
                "data": "AAAA",
            },
            "does not fit",
        ),
        (
            {"type": "displacement_field", "path": "x.nii.gz", "part": "one"},
            "'part' must be an integer",
        ),
    ],
)
def test_bad_scene_entries_raise_one_line_errors(entry: dict, pattern: str) -> None:
    with pytest.raises(WarpError, match=pattern):
        warp_from_dict(entry)
