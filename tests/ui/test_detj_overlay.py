"""View › Jacobian (det J) Overlay in a real window (Xvfb, see conftest).

Oracles: the status line's min/max and folded count are those of
``Scene.jacobian_determinant`` on the same coarse grid (computed here independently of
the window); the field folds by construction (u_x falls with slope -2 over a band of
x), so the count is positive. With the overlay on, the slice views hold det J equal to
``point_determinant`` of the chain at their pixel centres (CPU; the view's is the GPU's,
within 2e-3), the readout shows it, and the 3D frame changes; off again, the 3D frame
is back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.ui.test_main_window import _session, frame
from tests.ui.windows import shown_window
from voxwarp.core.jacobian import point_determinant
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.io.fields import save_displacement_field
from voxwarp.render.jacobian_overlay import pixel_centres
from voxwarp.ui.detj_overlay import status_spacing, status_text


def folding_field(volume: Any) -> DisplacementFieldWarp:
    """u_x = -2 (x - a) over the middle fifth of the box in x (det J = -1 there), and
    a smooth swirl elsewhere (det J varies)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
    n = np.array([21, 12, 10])
    spacing = (hi - lo) / (n - 1)
    affine = np.diag([*spacing, 1.0])
    affine[:3, 3] = lo
    idx = np.stack(np.meshgrid(*(np.arange(k) for k in n), indexing="ij"), -1)
    x = idx * spacing + lo
    a, b = lo[0] + 0.4 * (hi[0] - lo[0]), lo[0] + 0.6 * (hi[0] - lo[0])
    u = np.zeros((*n, 3))
    u[..., 0] = -2.0 * (np.clip(x[..., 0], a, b) - a)
    u[..., 1] = 3.0 * np.sin(x[..., 2] / 10.0)
    return DisplacementFieldWarp(u, affine)


@pytest.fixture
def window(qtbot: Any, monkeypatch: pytest.MonkeyPatch) -> Any:
    w = shown_window(qtbot, monkeypatch, _session(), (1100, 760), layout="2x2")
    yield w
    w.close()


@pytest.mark.slow
def test_status_and_overlay_follow_det_j(window: Any, qtbot: Any, tmp_path: Path) -> None:
    w = window
    assert w.detj.stats is None  # no warps: no status line
    path = save_displacement_field(folding_field(w.session.volume), tmp_path / "fold.nii.gz")
    assert w.add_field(path)
    qtbot.waitUntil(lambda: w.detj.stats is not None, timeout=20000)
    scene = w.session.scene
    ref = scene.jacobian_determinant(spacing=status_spacing(scene.volume)).stats
    assert ref.folded > 0
    assert w.detj.stats == ref
    assert w.detj.label.text() == status_text(ref)
    assert f"{ref.min:.3g}..{ref.max:.3g}" in w.detj.label.text()
    assert f"{ref.folded} folded" in w.detj.label.text()

    before = frame(w)
    w.detj_action.setChecked(True)
    view = w.mpr.views[0]
    qtbot.waitUntil(lambda: view.image is not None and view.image.detj is not None, timeout=20000)
    img = view.image
    pts = pixel_centres(img.pixel_to_world, img.size)
    want = point_determinant(scene.warps, pts).reshape(img.detj.shape)
    ok = np.isfinite(img.detj)
    assert ok.sum() > 100
    # GPU (the warps' GLSL Jacobians) vs CPU: within 2e-3 (8-bit texture filter
    # weights), but for pixels whose centre straddles the fold band's edge
    close = np.abs(img.detj[ok] - want[ok]) <= 2e-3
    assert close.mean() > 0.99
    assert (want <= 0).sum() > 100  # the fold shows in this slice
    assert "det J" in view.readout_text()
    after = frame(w)
    assert np.abs(after - before).max() > 20  # the 3D view is tinted
    assert w.grab().save(str(tmp_path / "detj_window.png"))  # to look at
    w.detj_action.setChecked(False)
    qtbot.waitUntil(lambda: view.image is not None and view.image.detj is None, timeout=20000)
    assert "det J" not in view.readout_text()
    np.testing.assert_allclose(frame(w), before, atol=2)
