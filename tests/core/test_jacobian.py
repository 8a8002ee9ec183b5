"""``voxwarp.core.jacobian``: det J of a warp chain (analytic) and of a field (central
differences). Oracles: SimpleITK's ``DisplacementFieldJacobianDeterminant`` on the same
nodes, linear fields and affine chains whose determinant is known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from voxwarp.core.jacobian import JacobianStats, chain_determinant, field_determinant
from voxwarp.deform.warp import AffineWarp, chain_apply_carried

sitk = pytest.importorskip("SimpleITK")


def _grid(spacing: tuple[float, float, float], direction: np.ndarray) -> np.ndarray:
    a = np.eye(4)
    a[:3, :3] = direction * np.asarray(spacing)
    a[:3, 3] = (-10.0, 5.0, 3.0)
    return a


def _sitk_det(u: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """SimpleITK's filter on vectors ``u`` (nx, ny, nz, 3) with the grid's spacing and
    origin and an identity direction (the filter differentiates along index axes)."""
    img = sitk.GetImageFromArray(u.transpose(2, 1, 0, 3).astype(np.float64), isVector=True)
    img.SetSpacing(np.linalg.norm(affine[:3, :3], axis=0).tolist())
    img.SetOrigin(affine[:3, 3].tolist())
    return sitk.GetArrayFromImage(sitk.DisplacementFieldJacobianDeterminant(img)).T


def test_field_determinant_equals_simpleitk_on_every_node() -> None:
    """Central differences with ITK's zero-flux border: equal on every node, borders too."""
    spacing = (1.5, 2.0, 3.0)
    a = _grid(spacing, np.eye(3))
    i, j, k = np.meshgrid(np.arange(12), np.arange(10), np.arange(8), indexing="ij")
    u = np.stack(
        [4 * np.sin(i / 3.0) * np.cos(k / 4.0), 3 * np.cos(j / 2.0 + i / 5.0), 2 * np.sin(k)],
        axis=-1,
    )
    ours = field_determinant(u, a)
    theirs = _sitk_det(u, a)
    assert ours.shape == theirs.shape == (12, 10, 8)
    assert np.ptp(theirs) > 1.0  # a field whose det J varies (the check can fail)
    np.testing.assert_allclose(ours, theirs, atol=1e-5)


@pytest.mark.parametrize(
    "direction",
    [np.diag([-1.0, -1.0, 1.0]), AffineWarp.rotation((1, 2, 3), 40.0).forward_matrix[:3, :3]],
    ids=["lps-flip", "oblique"],
)
def test_field_determinant_of_a_linear_field_is_the_matrix_determinant(
    direction: np.ndarray,
) -> None:
    """u(x) = (M - I) x on a grid with a non-identity direction: det J = det M exactly.
    ITK's own filter ignores the direction and gets another value (documented).
    Interior nodes: at the border ITK's zero-flux rule halves the difference."""
    m = np.array([[1.2, 0.1, 0.0], [0.05, 0.9, 0.2], [0.0, -0.1, 1.1]])
    a = _grid((2.0, 1.0, 1.5), direction)
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in (6, 7, 5)), indexing="ij"), axis=-1)
    x = idx @ a[:3, :3].T + a[:3, 3]
    u = x @ (m - np.eye(3)).T
    inner = field_determinant(u, a)[1:-1, 1:-1, 1:-1]  # the border is one-sided halves
    np.testing.assert_allclose(inner, np.linalg.det(m), rtol=1e-5)
    assert abs(float(_sitk_det(u, a)[3, 3, 2]) - np.linalg.det(m)) > 0.05


def test_chain_determinant_of_an_affine_chain() -> None:
    """An affine chain: det J is the determinant of its deformed -> original matrix
    everywhere; a uniform scaling by s (forward) pulls from a region s^3 smaller."""
    a = _grid((3.0, 3.0, 3.0), np.eye(3))
    s = 1.3
    chain = [
        AffineWarp.scaling((s, s, s), center=(0, 0, 0)),
        AffineWarp.rotation((0, 1, 1), 30.0, center=(5, 5, 5)),
        AffineWarp(np.array([[1, 0.3, 0, 2], [0, 0.8, 0, 0], [0.1, 0, 1.5, 1], [0, 0, 0, 1]])),
    ]
    det = chain_determinant(chain[:1], a, (5, 4, 3))
    np.testing.assert_allclose(det, s**-3, rtol=1e-6)
    want = np.prod([np.linalg.det(w.inverse[:3, :3]) for w in chain])
    np.testing.assert_allclose(chain_determinant(chain, a, (5, 4, 3)), want, rtol=1e-6)


def test_chain_determinant_is_nan_where_the_chain_does_not_carry() -> None:
    """Nodes the chain sends away (NaN, beyond FAR_MM) are NaN; the others are finite."""
    far = AffineWarp(np.diag([1e-7, 1.0, 1.0, 1.0]))  # x -> 1e7 x: away from x = 0
    a = _grid((2.0, 2.0, 2.0), np.eye(3))
    a[:3, 3] = (-6.0, 0.0, 0.0)
    det = chain_determinant([far], a, (7, 2, 2))
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in (7, 2, 2)), indexing="ij"), axis=-1)
    p = idx.reshape(-1, 3) @ a[:3, :3].T + a[:3, 3]
    ok = chain_apply_carried([far], p)[1].reshape(7, 2, 2)
    assert ok.any()
    assert not ok.all()
    assert np.array_equal(np.isfinite(det), ok)


def test_stats_count_folded_compressed_and_expanded() -> None:
    det = np.array([-1.0, 0.0, 0.3, 1.0, 2.5, 3.0, np.nan]).reshape(7, 1, 1)
    st = JacobianStats.of(det, np.diag([2.0, 1.0, 0.5, 1.0]))
    assert (st.min, st.max, st.nodes) == (-1.0, 3.0, 6)
    assert (st.folded, st.compressed, st.expanded) == (2, 3, 2)
    assert "2 folded (det J <= 0) (2 mm^3)" in st.line()
