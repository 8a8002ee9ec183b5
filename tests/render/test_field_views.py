"""Tests of voxwarp.render.field_views: slice images of wire, offset-field and lattice warps (no
GL).

The oracles are fields built with a known answer: a constant offset (|d| = 5 mm
everywhere), a Gaussian drag whose peak node is known, a wire along z whose attribute u
grows from its first control point to its last, an identity lattice.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.lattice_inverse import bent_grid
from benchmarks.offset_inverse import gaussian_drag_field
from voxwarp.core.volume import Volume
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import AffineWarp
from voxwarp.deform.wires.field import Wire, WireDeformer
from voxwarp.errors import VoxwarpError
from voxwarp.render.field_views import (
    DISPLACEMENT_PIXELS,
    IDENTITY_COLOR,
    NOWHERE_COLOR,
    SWEPT_COLOR,
    VACATED_COLOR,
    VIEWS,
    VIRIDIS,
    FieldSlice,
    FieldViewError,
    colormap,
    field_slice,
    pixel_of,
    views_for,
)

N = 32


def cube(n: int = N, spacing: float = 1.0) -> Volume:
    """An empty n³ volume (bounds -spacing/2 .. (n - 1/2) spacing)."""
    return Volume(np.zeros((n, n, n), dtype=np.float32), spacing=(spacing,) * 3)


def cylinder_volume() -> Volume:
    """32³, 1 mm voxels: a bright (100) cylinder of radius 4 along z through (16, 16)."""
    x, y, _ = np.meshgrid(*(np.arange(N),) * 3, indexing="ij")
    data = (((x - 16) ** 2 + (y - 16) ** 2) <= 16).astype(np.float32) * 100.0
    return Volume(data, spacing=(1.0, 1.0, 1.0))


BASE = np.array([[16, 16, 4], [16, 16, 12], [16, 16, 20], [16, 16, 28]], dtype=float)


def wire_warp(volume: Volume, bent: bool, layout: str = "float") -> Any:
    """A wire along the cylinder's axis; ``bent``: its middle pushed +y by 3-4 mm."""
    modified = BASE.copy()
    if bent:
        modified[1:, 1] += (3.0, 4.0, 2.0)
    # the paper's rigid sweep: its vacated place is what the field views show
    wire = Wire(BASE, modified, radius=6.0, beta=(50.0, 200.0), name="axis", sides="rigid")
    deformer = WireDeformer(volume, [wire], field_scale=1, layout=layout)
    deformer.build()
    return deformer.warp()


@pytest.fixture(scope="module")
def cyl() -> Volume:
    return cylinder_volume()


@pytest.fixture(scope="module")
def bent_wire(cyl: Volume) -> Any:
    return wire_warp(cyl, bent=True)


@pytest.fixture(scope="module")
def straight_wire(cyl: Volume) -> Any:
    return wire_warp(cyl, bent=False)


def legend_max(legend: str) -> float:
    """The top of a scalar view's scale, from its legend (``"... 0 (dark) .. X mm ..."``)."""
    return float(legend.split(".. ")[1].split(" mm")[0])


def colors(image: np.ndarray) -> set[tuple[int, int, int]]:
    return {tuple(int(v) for v in c) for c in np.unique(image.reshape(-1, 3), axis=0)}


def brightness(image: np.ndarray) -> np.ndarray:
    """Position of each pixel's colour on the viridis ramp (0..1), via its nearest key."""
    d = np.sum((image[..., None, :].astype(float) - VIRIDIS[None, None]) ** 2, axis=-1)
    return d.argmin(axis=-1) / (len(VIRIDIS) - 1)


# ---------------------------------------------------------------------------- views
def test_views_per_warp_kind(bent_wire: Any) -> None:
    vol = cube()
    lo, hi = vol.bounds
    offset = OffsetFieldWarp(lo, hi, np.zeros((3, 3, 3, 3)))
    lattice = LatticeWarp(bent_grid(2, lo, hi), (lo, hi))
    assert views_for(None) == ()
    assert views_for(bent_wire) == VIEWS["wires"]
    assert views_for(offset) == ("offset |d|", "displacement")
    assert views_for(lattice) == ("displacement",)
    assert views_for(AffineWarp(np.eye(4))) == ("displacement",)
    assert "attribute t" in VIEWS["wires"]
    assert "swept / vacated" in VIEWS["wires"]


def test_colormap_ends_are_viridis() -> None:
    out = colormap(np.array([0.0, 1.0, -3.0, 7.0, np.nan]))
    assert out.dtype == np.uint8
    assert out.shape == (5, 3)
    assert tuple(out[0]) == (68, 1, 84)
    assert tuple(out[1]) == (253, 231, 37)
    assert tuple(out[2]) == tuple(out[0])
    assert tuple(out[3]) == tuple(out[1])
    assert tuple(out[4]) == tuple(out[0])


# ---------------------------------------------------------------------------- offset field
def test_constant_offset_is_five_mm_everywhere() -> None:
    vol = cube()
    lo, hi = vol.bounds
    u = np.zeros((5, 6, 7, 3))
    u[...] = (3.0, 0.0, 4.0)
    warp = OffsetFieldWarp(lo, hi, u)
    for axis in range(3):
        fs = field_slice(warp, vol, "offset |d|", axis, 0.3)
        assert isinstance(fs, FieldSlice)
        assert fs.image.dtype == np.uint8
        assert fs.image.ndim == 3
        assert fs.image.shape[2] == 3
        assert max(fs.image.shape[:2]) == 256
        # every pixel lies in the grid box: all at the top of the scale, which is 5 mm
        assert colors(fs.image) == {(253, 231, 37)}
        assert "5 mm" in fs.legend
        assert "offset |d|" in fs.title
        assert f"{'xyz'[axis]} = " in fs.title


def test_offset_slice_geometry_and_title() -> None:
    vol = Volume(np.zeros((20, 40, 10), dtype=np.float32), spacing=(1.0, 1.0, 2.0))
    lo, hi = vol.bounds  # (-0.5, -0.5, -1) .. (19.5, 39.5, 19)
    warp = OffsetFieldWarp(lo, hi, np.zeros((3, 3, 3, 3)))
    fs = field_slice(warp, vol, "offset |d|", 2, 0.25, max_pixels=100)
    assert fs.extent == pytest.approx((lo[0], hi[0], lo[1], hi[1]))
    # 20 x 40 mm: 50 columns (x), 100 rows (y), square pixels
    assert fs.image.shape == (100, 50, 3)
    assert fs.title == f"offset |d|, z = {lo[2] + 0.25 * (hi[2] - lo[2]):.1f} mm"
    # a field of zeros: 0 .. 0 and all dark
    assert colors(fs.image) == {(68, 1, 84)}
    assert "0 mm" in fs.legend


def test_gaussian_drag_peak_is_brightest_near_it() -> None:
    vol = cube(spacing=2.0)  # 64 mm box
    lo, hi = vol.bounds
    node = (4, 10, 8)
    u = gaussian_drag_field((17, 17, 17), node, (0.0, 0.0, 6.0), sigma=2.0)
    warp = OffsetFieldWarp(lo, hi, u, inverse="baked")
    peak = lo + np.asarray(node) * warp.spacing
    for axis in range(3):
        fraction = (peak[axis] - lo[axis]) / (hi[axis] - lo[axis])
        fs = field_slice(warp, vol, "offset |d|", axis, fraction)
        # the pixel of the slice's maximum is exactly the top of the scale
        to_top = np.sum((fs.image.astype(float) - VIRIDIS[-1]) ** 2, axis=-1)
        r, c = np.unravel_index(to_top.argmin(), to_top.shape)
        er, ec = pixel_of(fs, peak, axis)
        assert abs(r - er) <= 1
        assert abs(c - ec) <= 1
        assert to_top[r, c] == 0.0
        b = brightness(fs.image)
        assert "6 mm" in fs.legend  # the slice passes through the dragged node
        # far from the drag it fades to the bottom of the scale
        assert b[er, (ec + b.shape[1] // 2) % b.shape[1]] < 0.2
    # a slice away from the node shows a smaller maximum
    away = field_slice(warp, vol, "offset |d|", 2, 0.95)
    assert "6 mm" not in away.legend.split(";")[0]


def test_offset_displacement_view_is_coarser_and_agrees() -> None:
    vol = cube()
    lo, hi = vol.bounds
    u = np.zeros((9, 9, 9, 3))
    u[...] = (3.0, 0.0, 4.0)
    warp = OffsetFieldWarp(lo, hi, u, inverse="baked")
    fs = field_slice(warp, vol, "displacement", 2, 0.5)
    assert max(fs.image.shape[:2]) == DISPLACEMENT_PIXELS
    assert "|w(p) - p| 0 (dark) .. 5 mm" in fs.legend
    # deep inside the box the inverse moves every point by the 5 mm offset
    b = brightness(fs.image)
    assert b[40:90, 40:90].min() == 1.0


def test_gpu_owned_offset_field_needs_a_context() -> None:
    vol = cube()
    lo, hi = vol.bounds
    warp = OffsetFieldWarp(lo, hi, shape=(3, 3, 3), texture_source=lambda ctx: None)
    with pytest.raises(FieldViewError, match="OpenGL context"):
        field_slice(warp, vol, "offset |d|", 0, 0.5)


# ---------------------------------------------------------------------------- wires
def test_attribute_t_increases_along_the_wire(bent_wire: Any, cyl: Volume) -> None:
    # x slice through the wire (x = 16 mm): t along z, bottom (z small) to top
    fraction = (16.0 - cyl.bounds[0][0]) / N
    fs = field_slice(bent_wire, cyl, "attribute t", 0, fraction, max_pixels=64)
    assert fs.title == "attribute t, x = 16.0 mm"
    state, _, u = _field_at(bent_wire, fs, 0, 16.0)
    swept = state == 2
    assert swept.sum() > 100
    # the image shows u of the swept pixels through viridis, the rest black / grey
    assert np.array_equal(fs.image[swept], colormap(u[swept]))
    assert np.all(fs.image[state == 0] == 0)
    # per row (bottom to top) the mean t of the swept pixels grows with z
    rows = [r for r in range(swept.shape[0]) if swept[r].sum() >= 2]
    means = np.array([brightness(fs.image)[r][swept[r]].mean() for r in rows])[::-1]
    assert len(means) > 15
    assert np.all(np.diff(means) >= -1e-9)
    assert means[0] < 0.15
    assert means[-1] > 0.85
    assert "t: 0 (dark) .. 1 (yellow)" in fs.legend


def _field_at(warp: Any, fs: FieldSlice, axis: int, position: float) -> tuple[Any, Any, Any]:
    """(state, wire, u) of the field voxel under each pixel centre (the oracle)."""
    fld = warp.field
    state, wire, t = fld.decode()
    h, w = fs.image.shape[:2]
    left, right, bottom, top = fs.extent
    a, b = [(1, 2), (0, 2), (0, 1)][axis]
    pts = np.zeros((h, w, 3))
    pts[..., axis] = position
    pts[..., a] = left + (np.arange(w)[None, :] + 0.5) * (right - left) / w
    pts[..., b] = top - (np.arange(h)[:, None] + 0.5) * (top - bottom) / h
    g = np.floor((pts - fld.lo) / fld.spacing).astype(int)
    g = np.clip(g, 0, np.asarray(fld.shape) - 1)  # every pixel lies in the field box here
    i, j, k = g[..., 0], g[..., 1], g[..., 2]
    return state[i, j, k], wire[i, j, k], t[i, j, k] / 255.0


def test_wire_extent_holds_the_field_box(bent_wire: Any, cyl: Volume) -> None:
    fs = field_slice(bent_wire, cyl, "swept / vacated", 0, 0.5)
    lo, hi = cyl.bounds
    fld = bent_wire.field
    # the field grows beyond the volume along z (the wire's reach beyond its ends)
    assert fs.extent[2] == pytest.approx(min(lo[2], fld.lo[2]))
    assert fs.extent[3] == pytest.approx(max(hi[2], fld.hi[2]))
    assert fs.extent[2] < lo[2]


def test_swept_and_vacated_of_a_bent_wire(bent_wire: Any, cyl: Volume) -> None:
    fs = field_slice(bent_wire, cyl, "swept / vacated", 0, 16.5 / N)
    assert colors(fs.image) == {SWEPT_COLOR, VACATED_COLOR, IDENTITY_COLOR}
    assert "orange: swept" in fs.legend
    # the swept object moved +y: vacated pixels lie on the -y side (left) of the swept ones
    vac = np.nonzero(np.all(fs.image == VACATED_COLOR, axis=-1))[1]
    swept = np.nonzero(np.all(fs.image == SWEPT_COLOR, axis=-1))[1]
    assert vac.mean() < swept.mean()


def test_straight_wire_sweeps_in_place_and_vacates_nothing(straight_wire: Any, cyl: Volume) -> None:
    # modified == base: the object is still swept (by the identity mapping), but nothing
    # is vacated and nothing moves
    fs = field_slice(straight_wire, cyl, "swept / vacated", 0, 16.5 / N)
    assert VACATED_COLOR not in colors(fs.image)
    assert SWEPT_COLOR in colors(fs.image)
    assert straight_wire.deformer.stats.vacated == 0
    disp = field_slice(straight_wire, cyl, "displacement", 0, 16.5 / N)
    assert "0 (dark) .. 0 mm" in disp.legend
    assert colors(disp.image) == {(68, 1, 84)}


def test_wire_id_colours_and_names(bent_wire: Any, cyl: Volume) -> None:
    fs = field_slice(bent_wire, cyl, "wire id", 2, 0.5)
    assert (31, 119, 180) in colors(fs.image)  # wire 0: blue
    assert "blue: axis" in fs.legend


def test_packed_layout_matches_float(cyl: Volume, bent_wire: Any) -> None:
    packed = wire_warp(cyl, bent=True, layout="packed")
    for view in ("swept / vacated", "wire id"):
        a = field_slice(bent_wire, cyl, view, 1, 0.5, max_pixels=64)
        b = field_slice(packed, cyl, view, 1, 0.5, max_pixels=64)
        assert np.array_equal(a.image, b.image)
    a = field_slice(bent_wire, cyl, "attribute t", 1, 0.5, max_pixels=64)
    b = field_slice(packed, cyl, "attribute t", 1, 0.5, max_pixels=64)
    # the packed layout rounds t to 1/255: same pixels, nearly the same colours
    assert np.array_equal(a.image.any(-1), b.image.any(-1))
    assert np.abs(a.image.astype(int) - b.image.astype(int)).max() <= 3


def test_wire_displacement_shows_moved_and_vacated(bent_wire: Any, cyl: Volume) -> None:
    fs = field_slice(bent_wire, cyl, "displacement", 0, 16.5 / N)
    assert NOWHERE_COLOR in colors(fs.image)
    assert "shows nothing" in fs.legend
    top = legend_max(fs.legend)
    assert 2.0 < top < 8.0  # the middle moved by 3-4 mm (plus the turn of the frames)


# ---------------------------------------------------------------------------- lattice
def identity_lattice(vol: Volume, cells: int = 4) -> LatticeWarp:
    lo, hi = vol.bounds
    u = np.stack(np.meshgrid(*(np.linspace(0.0, 1.0, cells + 1),) * 3, indexing="ij"), -1)
    return LatticeWarp(TrilinearGrid(lo + u * (hi - lo)), (lo, hi))


def test_identity_lattice_displaces_nothing() -> None:
    vol = cube(spacing=2.0)
    for axis in range(3):
        fs = field_slice(identity_lattice(vol), vol, "displacement", axis, 0.4)
        assert fs.image.shape == (128, 128, 3)
        assert "0 (dark) .. 0 mm" in fs.legend
        assert colors(fs.image) == {(68, 1, 84)}


def test_bent_lattice_displaces() -> None:
    vol = cube(spacing=2.0)
    lo, hi = vol.bounds
    warp = LatticeWarp(bent_grid(4, lo, hi), (lo, hi))
    fs = field_slice(warp, vol, "displacement", 1, 0.5)
    top = legend_max(fs.legend)
    assert top > 5.0
    # the middle of the box was pushed along +z: the bent lattice's box is taller
    assert fs.extent[3] > hi[2] + 5.0
    assert (253, 231, 37) in colors(fs.image)


# ---------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"view": "attribute t"}, "view must be one of 'offset |d|', 'displacement'"),
        ({"view": 3}, "view must be one of"),
        ({"axis": 3}, "axis must be 0, 1 or 2"),
        ({"axis": -1}, "axis must be 0, 1 or 2"),
        ({"axis": True}, "axis must be 0, 1 or 2"),
        ({"axis": 1.0}, "axis must be 0, 1 or 2"),
        ({"fraction": 1.5}, r"fraction must be in \[0, 1\]"),
        ({"fraction": -0.1}, r"fraction must be in \[0, 1\]"),
        ({"fraction": float("nan")}, r"fraction must be in \[0, 1\]"),
        ({"fraction": "middle"}, r"fraction must be a number in \[0, 1\]"),
        ({"max_pixels": 1}, "max_pixels must be an integer"),
        ({"max_pixels": 10**6}, "max_pixels must be an integer"),
    ],
)
def test_bad_arguments_name_the_allowed_values(kwargs: dict[str, Any], match: str) -> None:
    vol = cube()
    lo, hi = vol.bounds
    warp = OffsetFieldWarp(lo, hi, np.zeros((3, 3, 3, 3)))
    args: dict[str, Any] = {"view": "offset |d|", "axis": 0, "fraction": 0.5}
    args.update(kwargs)
    with pytest.raises(FieldViewError, match=match) as info:
        field_slice(warp, vol, **args)
    assert isinstance(info.value, VoxwarpError)
    assert isinstance(info.value, ValueError)


def test_no_warp_and_bad_volume() -> None:
    vol = cube()
    with pytest.raises(FieldViewError, match="no deformation"):
        field_slice(None, vol, "displacement", 0, 0.5)
    with pytest.raises(FieldViewError, match="volume must have bounds"):
        field_slice(identity_lattice(vol), object(), "displacement", 0, 0.5)


def test_wire_views_are_not_offered_for_lattices() -> None:
    vol = cube()
    with pytest.raises(FieldViewError, match="for a lattice warp"):
        field_slice(identity_lattice(vol), vol, "wire id", 2, 0.5)


def test_gpu_chainmail_field_is_read_back(gl_ctx: Any) -> None:
    from voxwarp.deform.elements.chainmail import ChainMail
    from voxwarp.deform.elements.grid import ElementGrid

    vol = cube(spacing=2.0)
    lo, hi = vol.bounds
    gpu = ChainMail(ElementGrid((lo, hi), shape=(6, 6, 6)), backend="gpu", ctx=gl_ctx)
    cpu = ChainMail(ElementGrid((lo, hi), shape=(6, 6, 6)))
    try:
        for cm in (gpu, cpu):
            cm.move((2, 3, 3), (0.0, 0.0, 8.0))
        warp = gpu.warp()
        assert warp.gpu_owned
        fraction = 3 / 5  # through the dragged element's plane y = lo + 3 h
        for view in ("offset |d|", "displacement"):
            with pytest.raises(FieldViewError, match="OpenGL context"):
                field_slice(warp, vol, view, 1, fraction)
            a = field_slice(warp, vol, view, 1, fraction, ctx=gl_ctx)
            b = field_slice(cpu.warp(), vol, view, 1, fraction)
            # the half-float texture rounds the field (2^-11 relative)
            assert legend_max(a.legend) == pytest.approx(legend_max(b.legend), rel=5e-3)
            assert legend_max(b.legend) > 4.0
            assert np.abs(a.image.astype(int) - b.image.astype(int)).mean() < 1.0
    finally:
        gpu.close()
        cpu.close()
