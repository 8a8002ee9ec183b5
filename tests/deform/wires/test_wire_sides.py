"""Wire sides (deform/wires/wire.py ``Wire.sides``, ``side_falloff``, ``vacated``).

Oracles: on a phantom filled everywhere with a positive value, a wire bent 15 mm with a
35 mm radius leaves no sample of a slice through it empty with the default smooth sides
(the rigid sweep vacates a crescent: > 0, so the count can fail); the displacement is
continuous across the radius and the fade (its difference quotient is bounded by the
smoothstep's slope times the move; the rigid sweep tears there); the CPU Jacobian equals
central finite differences of ``apply`` exactly where the mapping has no t-dependence (a
translated wire) and is far closer to them than ``I + w (A - I)`` on a bent wire; the
default falloff does not fold (det > 0) and a narrow one warns and folds;
``vacated="rest"`` shows the unmoved content; the GLSL warp and its Jacobian agree with
the CPU at points in the fade.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.warp_gpu import gpu_warp
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.constants import FAR
from voxwarp.deform.wires.layouts import _sample_t_float
from voxwarp.deform.wires.warp import WireFieldWarp
from voxwarp.deform.wires.wire import Wire

SIZE = 96  # voxels per axis, 2 mm: a 192 mm cube
SPACING = 2.0
CENTRE = 0.5 * SIZE * SPACING
RADIUS = 35.0
BEND = 15.0


def filled() -> Volume:
    """A cube filled everywhere with 100 (every in-volume sample is non-empty)."""
    data = np.full((SIZE, SIZE, SIZE), 100.0, dtype=np.float32)
    return Volume(np.asfortranarray(data), spacing=(SPACING,) * 3, name="filled")


def spine(**kw: Any) -> Wire:
    """A wire along z through the cube's centre (past both faces), bent along +x by a
    half sine of ``BEND`` mm (a gentle bump, as a bent spine: both ends stay)."""
    s = np.linspace(0.0, 1.0, 9)
    z = -20.0 + s * (SIZE * SPACING + 40.0)
    base = np.stack([np.full(9, CENTRE), np.full(9, CENTRE), z], -1)
    mod = base.copy()
    mod[:, 0] += kw.pop("bend", BEND) * np.sin(np.pi * s)
    kw.setdefault("radius", RADIUS)
    kw.setdefault("ends", "smooth")
    return Wire(base, mod, **kw)


def built(wire: Wire, **kw: Any) -> WireFieldWarp:
    kw.setdefault("field_scale", 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        wd = WireDeformer(filled(), [wire], **kw)
        wd.build()
    return wd.warp()


def coronal(step: float = 1.0) -> np.ndarray:
    """Points of the plane y = centre (through the wire) inside the volume's box."""
    lo, hi = -0.5 * SPACING, (SIZE - 0.5) * SPACING
    ax = np.arange(lo + 0.25, hi, step)
    x, z = np.meshgrid(ax, ax, indexing="ij")
    return np.stack([x.ravel(), np.full(x.size, CENTRE), z.ravel()], -1)


def empty_samples(warp: WireFieldWarp, p: np.ndarray) -> int:
    """How many points show nothing: sent far away, or outside the filled box. Points
    within the largest move of a face are left out (they may show what lies beyond it:
    the deformed volume's own border)."""
    lo, hi = -0.5 * SPACING, (SIZE - 0.5) * SPACING
    margin = warp.wires[0].largest_move() + SPACING
    p = p[np.all((p >= lo + margin) & (p <= hi - margin), axis=1)]
    q = warp.apply(p)
    inside = np.all((q >= lo) & (q <= hi), axis=1)
    return int((~inside).sum())


def test_sides_default_smooth_and_json_keys() -> None:
    w = spine()
    assert (w.sides, w.vacated, w.vacates) == ("smooth", "empty", False)
    d = w.to_dict()
    assert d["sides"] == "smooth"
    assert "side_falloff" not in d
    del d["sides"]
    assert Wire.from_dict(d).sides == "smooth"  # a wire without the key: the default
    back = Wire.from_dict({**d, "sides": "rigid", "vacated": "rest", "side_falloff": 12.0})
    assert (back.sides, back.vacated, back.side_falloff) == ("rigid", "rest", 12.0)
    again = Wire.from_dict(back.to_dict())
    assert (again.sides, again.vacated, again.side_falloff_mm) == ("rigid", "rest", 12.0)
    for bad, fragment in (
        ({"sides": "soft"}, "sides must be one of"),
        ({"vacated": "black"}, "vacated must be one of"),
        ({"side_falloff": -3}, "side_falloff must be"),
    ):
        with pytest.raises(WarpError, match=fragment):
            Wire.from_dict({**d, **bad})


def test_default_side_falloff_is_radius_or_twice_the_move() -> None:
    w = spine()
    # the wire point moves BEND; the radius' circle around it a little more (the
    # cross-sections tilt with the bend)
    assert 0.99 * BEND <= w.largest_move() <= 1.2 * BEND
    assert w.side_falloff == pytest.approx(max(RADIUS, 2 * w.largest_move()))
    big = spine(bend=30.0)
    assert big.side_falloff == pytest.approx(2 * big.largest_move())
    assert big.side_falloff > RADIUS


def test_smooth_sides_leave_no_empty_sample_and_rigid_does() -> None:
    p = coronal()
    assert empty_samples(built(spine()), p) == 0
    rigid = built(spine(sides="rigid"))
    assert np.sum(rigid.apply(p)[:, 0] >= FAR / 2) > 100  # the vacated crescent
    # the rest value fills the vacated place: nothing empty, the content unmoved there
    rest = built(spine(sides="rigid", vacated="rest"))
    assert empty_samples(rest, p) == 0
    gone = rigid.vacated(p)
    np.testing.assert_array_equal(rest.apply(p[gone]), p[gone])


def test_displacement_is_continuous_across_the_radius_and_fade() -> None:
    # a line across the wire's middle along x, through the radius and the whole fade
    h = 0.05
    xs = np.arange(CENTRE - 100.0, CENTRE + 100.0, h)
    p = np.stack([xs, np.full_like(xs, CENTRE), np.full_like(xs, CENTRE)], -1)
    w = spine()
    smooth = built(w).apply(p) - p
    quotient = np.linalg.norm(np.diff(smooth, axis=0), axis=1) / h
    # the smoothstep's steepest slope (1.5 / F) times the move, plus the field's
    # trilinear interpolation of the weight (a voxel's chord of it) and A's own change
    bound = 1.5 * w.largest_move() / w.side_falloff * 1.5 + 0.1
    assert quotient.max() <= bound, quotient.max()
    assert np.abs(smooth).max() == pytest.approx(BEND, rel=0.1)  # it does move
    rigid = built(spine(sides="rigid")).apply(p) - p
    shown = np.all(np.abs(rigid) < FAR / 2, axis=1)
    ok = shown[1:] & shown[:-1]
    tear = np.linalg.norm(np.diff(rigid, axis=0), axis=1)[ok] / h
    assert tear.max() > 10 * bound  # the rigid sweep's edge meets unmoved tissue


def fd_jacobian(warp: WireFieldWarp, p: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    cols = [(warp.apply(p + eps * e) - warp.apply(p - eps * e)) / (2 * eps) for e in np.eye(3)]
    return np.stack(cols, -1)


def in_fade(warp: WireFieldWarp, n: int = 4000, seed: int = 3) -> np.ndarray:
    """Random points in the wire's fade (0.05 < w < 0.95, swept)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(20.0, SIZE * SPACING - 20.0, (n, 3))
    p = p[warp.swept(p)]
    fld = warp.field
    assert fld.weight is not None
    wt = _sample_t_float(fld.weight, (p - fld.lo) / fld.spacing)
    return p[(wt > 0.05) & (wt < 0.95)]


def test_jacobian_matches_finite_differences_in_the_fade() -> None:
    # a translated straight wire: A = I and b constant, so J = I + d (x) grad w exactly
    z = np.array([-20.0, 60.0, 132.0, SIZE * SPACING + 20.0])
    base = np.stack([np.full(4, CENTRE), np.full(4, CENTRE), z], -1)
    shifted = Wire(base, base + np.array([12.0, 0.0, 0.0]), radius=20.0)
    warp = built(shifted)
    p = in_fade(warp)
    assert len(p) > 200
    fd = fd_jacobian(warp, p)
    np.testing.assert_allclose(warp.jacobian(p), fd, atol=1e-6)
    assert np.abs(fd - np.eye(3)).max() > 0.3  # the weight's gradient term matters
    # a bent wire: t's own gradient is left out (documented), the weight's is not
    bent = built(spine())
    p = in_fade(bent)
    fd = fd_jacobian(bent, p)
    err = np.linalg.norm(bent.jacobian(p) - fd, ord=2, axis=(1, 2))
    t = bent._lookup(p)[2]
    a = bent.field.tables[0].lookup(t)[0]
    wt = _sample_t_float(bent.field.weight, (p - bent.field.lo) / bent.field.spacing)
    old = np.eye(3) + wt[:, None, None] * (a - np.eye(3))
    err_old = np.linalg.norm(old - fd, ord=2, axis=(1, 2))
    assert np.median(err) < 0.3 * np.median(err_old), (np.median(err), np.median(err_old))


def test_default_falloff_does_not_fold_and_a_narrow_one_warns() -> None:
    warp = built(spine(bend=30.0))
    p = in_fade(warp)
    assert np.linalg.det(fd_jacobian(warp, p)).min() > 0.0
    narrow = spine(bend=30.0, side_falloff=10.0)
    with pytest.warns(UserWarning, match=r"side_falloff 10 mm is below 1.5 x .* folds"):
        WireDeformer(filled(), [narrow], field_scale=2).build()
    folded = built(narrow)
    assert np.linalg.det(fd_jacobian(folded, in_fade(folded))).min() < 0.0


@pytest.mark.parametrize("layout", ["float", "packed", "paper"])
def test_gpu_warp_and_jacobian_equal_the_cpu_in_the_fade(gl_ctx: Any, layout: str) -> None:
    warp = built(spine(), layout=layout)
    try:
        p = in_fade(warp, n=8000)
        assert len(p) > 500
        q_gpu, j_gpu = gpu_warp(gl_ctx, warp, p)
        _, j_kept = gpu_warp(gl_ctx, warp, p, kept=True)  # the raycaster's form
    finally:
        warp.release()
    np.testing.assert_array_equal(j_kept, j_gpu)
    # float32 on the GPU, the lookup table through the texture unit (see
    # test_wire_gpu_sampling.py): a few 1e-3 mm
    np.testing.assert_allclose(q_gpu, warp.apply(p), atol=5e-3)
    np.testing.assert_allclose(j_gpu, warp.jacobian(p), atol=5e-3)


def test_scene_json_keeps_the_sides() -> None:
    warp = built(spine(sides="rigid", vacated="rest"))
    d = json.loads(json.dumps(warp.to_dict()))
    assert d["wires"][0]["sides"] == "rigid"
    assert d["wires"][0]["vacated"] == "rest"
    loaded = WireFieldWarp.from_dict(d)
    loaded.bind_volume(filled())
    assert (loaded.wires[0].sides, loaded.wires[0].vacated) == ("rigid", "rest")
    p = coronal(step=4.0)
    np.testing.assert_allclose(loaded.apply(p), warp.apply(p))


def test_forward_carries_points_through_the_fade() -> None:
    # meshes: forward (original -> deformed) inverts apply in the fade too (Newton steps
    # with the Jacobian that includes the weight's gradient)
    warp = built(spine())
    x = np.random.default_rng(1).uniform(40.0, 150.0, (2000, 3))
    p = warp.forward(x)
    np.testing.assert_allclose(warp.apply(p), x, atol=warp.forward_tolerance * 1.01)
    assert np.linalg.norm(p - x, axis=1).max() > 0.5 * BEND  # it does move them


def _wire_entries(obj: Any) -> list[dict[str, Any]]:
    """Every wire object in a JSON document (wire files, scenes, animations)."""
    if isinstance(obj, dict):
        found = list(obj["wires"]) if isinstance(obj.get("wires"), list) else []
        return found + [
            w for v in obj.values() if v is not obj.get("wires") for w in _wire_entries(v)
        ]
    if isinstance(obj, list):
        return [w for v in obj for w in _wire_entries(v)]
    return []


def test_bundled_wire_files_keep_the_papers_rigid_sweep() -> None:
    # the reproductions, demos and golden images use them: they must not change
    root = Path(__file__).resolve().parents[3] / "sample_volumes"
    files = [p for p in root.glob("*.json") if "wires" in p.read_text(encoding="utf-8")]
    # the Colin27 midline wire shows the default smooth sides (the docs' pictures, which
    # give --sides rigid for the paper's sweep); it is in no reproduction
    files = [p for p in files if p.name != "colin27_midline_wires.json"]
    assert len(files) >= 3
    for path in files:
        wires = _wire_entries(json.loads(path.read_text(encoding="utf-8")))
        assert wires, path.name
        assert {w.get("sides") for w in wires} == {"rigid"}, path.name
