"""Seams of smooth-sides wires (deform/wires/seams.py): where the closest point on the
wires jumps (past a sharp bend's radius of curvature, where two wires' regions meet), the
weight is faded to 0, so the warp stays continuous.

Oracles: the warp's difference quotient on a dense plane through the field is bounded by
the side fade's slope times the move plus the sweep's own stretch after the fade, and far
above that bound with the fade switched off (the same build with ``fade_seams`` replaced
by a no-op: the torn map it fixes); a gentle bend has no seam voxels and bit-identical
weights; the GLSL warp agrees with the CPU next to the faded seam; the bundled MRI's
midline wire's coronal plane is bounded too.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.deform.wires.test_wire_sides import CENTRE, SIZE, SPACING, filled, spine
from tests.warp_gpu import gpu_warp
from voxwarp.deform.wires import sides
from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.layouts import _sample_t_float
from voxwarp.deform.wires.warp import WireFieldWarp
from voxwarp.deform.wires.wire import Wire

H = 0.25  # mm between the plane's sample points


def kinked(**kw: Any) -> Wire:
    """A wire along z through the cube, its middle pushed 25 mm along +x over 40 mm (a
    bend of radius of curvature ~10 mm, far below its 35 + 50 mm reach)."""
    z = np.array([-20.0, 40.0, 76.0, 96.0, 116.0, 152.0, SIZE * SPACING + 20.0])
    base = np.stack([np.full(7, CENTRE), np.full(7, CENTRE), z], -1)
    mod = base.copy()
    mod[3, 0] += 25.0
    return Wire(base, mod, radius=35.0, **kw)


def pair() -> list[Wire]:
    """Two straight wires along z, 60 mm apart along x, moved 10 mm in opposite y: their
    reaches (20 + 20 mm each) overlap at the plane between them, where w = 1/2."""
    z = np.array([-20.0, 60.0, 132.0, SIZE * SPACING + 20.0])
    out = []
    for dx, dy in ((-30.0, 10.0), (30.0, -10.0)):
        base = np.stack([np.full(4, CENTRE + dx), np.full(4, CENTRE), z], -1)
        out.append(Wire(base, base + np.array([0.0, dy, 0.0]), radius=20.0))
    return out


def build(wires: list[Wire], seams: bool = True, **kw: Any) -> tuple[WireFieldWarp, int]:
    """The warp of ``wires`` (field scale 2) and its seam-faded voxel count; with
    ``seams=False`` the fade is switched off (the map before it)."""
    kw.setdefault("field_scale", 2)
    with warnings.catch_warnings(), pytest.MonkeyPatch.context() as mp:
        warnings.simplefilter("ignore")
        if not seams:
            mp.setattr(sides, "fade_seams", lambda *a, **k: 0)
        wd = WireDeformer(filled(), wires, **kw)
        st = wd.build()
    return wd.warp(), st.seam_faded


def quotient(warp: WireFieldWarp, y: float = CENTRE) -> np.ndarray:
    """|warp(p + H e) - warp(p)| / H along x and z on the plane at ``y`` (the cube's
    inner part), as one array."""
    ax = np.arange(10.0, SIZE * SPACING - 10.0, H)
    x, z = np.meshgrid(ax, ax, indexing="ij")
    p = np.stack([x, np.full_like(x, y), z], -1)
    q = warp.apply(p.reshape(-1, 3)).reshape(p.shape)
    qx = np.linalg.norm(np.diff(q, axis=0), axis=-1).ravel() / H
    qz = np.linalg.norm(np.diff(q, axis=1), axis=-1).ravel() / H
    return np.concatenate([qx, qz])


def bound(wires: list[Wire]) -> float:
    """1 + the side fade's steepest slope times the move (1.5 m / F), twice (the seam
    fade multiplies the side fade, each as steep), plus the sweep's own stretch (1)."""
    return 2.0 + max(3.0 * w.largest_move() / w.side_falloff for w in wires)


def test_a_sharp_bend_tears_without_the_seam_fade_and_not_with_it() -> None:
    torn, _ = build([kinked()], seams=False)
    warp, faded = build([kinked()])
    assert faded > 0
    limit = bound([kinked()])
    assert quotient(torn).max() > 5.0 * limit  # the "V" seam past the bend
    assert quotient(warp).max() <= limit, quotient(warp).max()


def test_two_wires_meet_without_a_tear() -> None:
    torn, _ = build(pair(), seams=False)
    warp, faded = build(pair())
    assert faded > 0
    limit = bound(pair())
    # the plane through both wires: each side's displacement is +-10 y times w = 1/2
    assert quotient(torn).max() > 5.0 * limit
    assert quotient(warp).max() <= limit, quotient(warp).max()
    p = np.array([[CENTRE - 30.0, CENTRE, CENTRE], [CENTRE + 30.0, CENTRE, CENTRE]])
    d = warp.apply(p) - p
    assert d[0, 1] < -5.0
    assert d[1, 1] > 5.0


def test_a_gentle_bend_has_no_seam_and_the_same_weights() -> None:
    off, _ = build([spine()], seams=False)
    warp, faded = build([spine()])
    assert faded == 0
    assert warp.field.weight is not None
    assert off.field.weight is not None
    np.testing.assert_array_equal(warp.field.weight, off.field.weight)


def test_the_shortfall_says_what_the_seam_fade_takes_from_the_wire() -> None:
    # a whole sweep lands the modified wire's content on the base wire to about a field
    # voxel (the table's linear t); the sharp bend's fade takes some of the move away
    gentle, _ = build([spine()])
    assert gentle.wire_shortfall() < 2.0 * float(gentle.field.spacing.max())
    torn, _ = build([kinked()], seams=False)
    faded, _ = build([kinked()])
    move = kinked().largest_move()
    assert torn.wire_shortfall() < faded.wire_shortfall() <= move
    # the oracle: the faded weight on the modified wire times its move is what is left
    tab = faded.field.tables[0]
    left = np.linalg.norm(faded.apply(tab.modified_points) - tab.modified_points, axis=1)
    whole = np.linalg.norm(tab.base_points - tab.modified_points, axis=1)
    assert faded.wire_shortfall() == pytest.approx(float(np.max(whole - left)), abs=0.5)


def test_rigid_sides_are_unchanged() -> None:
    off, _ = build([kinked(sides="rigid")], seams=False)
    warp, faded = build([kinked(sides="rigid")])
    assert faded == 0
    np.testing.assert_array_equal(warp.field.weight, off.field.weight)


@pytest.mark.parametrize("layout", ["float", "packed", "paper"])
def test_gpu_equals_the_cpu_next_to_the_faded_seam(gl_ctx: Any, layout: str) -> None:
    warp, _ = build([kinked()], layout=layout)
    off, _ = build([kinked()], seams=False, layout=layout)
    try:
        rng = np.random.default_rng(5)
        p = rng.uniform(20.0, SIZE * SPACING - 20.0, (20000, 3))
        p = p[warp.swept(p)]
        fld, old = warp.field, off.field
        assert fld.weight is not None
        assert old.weight is not None
        w = _sample_t_float(fld.weight, (p - fld.lo) / fld.spacing)
        w0 = _sample_t_float(old.weight, (p - old.lo) / old.spacing)
        p = p[(w < 0.9 * w0) & (w > 0.02)]  # where the seam fade acts
        assert len(p) > 300
        q_gpu, j_gpu = gpu_warp(gl_ctx, warp, p)
    finally:
        warp.release()
        off.release()
    np.testing.assert_allclose(q_gpu, warp.apply(p), atol=5e-3)
    np.testing.assert_allclose(j_gpu, warp.jacobian(p), atol=5e-3)


@pytest.mark.slow
def test_colin27_midline_coronal_plane_has_no_tear() -> None:
    from voxwarp.io.samples import load_sample

    path = Path(__file__).parents[3] / "sample_volumes" / "colin27_midline_wires.json"
    wires = [Wire.from_dict(d) for d in json.loads(path.read_text())["wires"]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        wd = WireDeformer(load_sample("colin27"), wires, field_scale=2)
        st = wd.build()
    warp = wd.warp()
    assert st.seam_faded > 0
    x, z = np.meshgrid(np.arange(-95, 95, H), np.arange(-75, 100, H), indexing="ij")
    p = np.stack([x, np.full_like(x, -20.0), z], -1)
    q = warp.apply(p.reshape(-1, 3)).reshape(p.shape)
    qx = np.linalg.norm(np.diff(q, axis=0), axis=-1) / H
    qz = np.linalg.norm(np.diff(q, axis=1), axis=-1) / H
    assert max(qx.max(), qz.max()) <= bound(wires), (qx.max(), qz.max())


def test_the_seam_fade_does_not_fold() -> None:
    for wires in ([kinked()], pair()):
        warp, _ = build(wires)
        off, _ = build(wires, seams=False)
        p = np.random.default_rng(7).uniform(20.0, SIZE * SPACING - 20.0, (6000, 3))
        fld, old = warp.field, off.field
        w = _sample_t_float(fld.weight, (p - fld.lo) / fld.spacing)
        w0 = _sample_t_float(old.weight, (p - old.lo) / old.spacing)
        p = p[warp.swept(p) & (w < 0.95 * w0)]  # where the seam fade acts
        assert len(p) > 100
        eps = 1e-3
        cols = [(warp.apply(p + eps * e) - warp.apply(p - eps * e)) / (2 * eps) for e in np.eye(3)]
        assert np.linalg.det(np.stack(cols, -1)).min() > 0.0
