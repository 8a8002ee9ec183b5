"""The attribute field's content box (:mod:`voxwarp.deform.wires.field_box`).

Oracle: the same build on the wires' whole reach (``box="reach"``, the box every
field had before). The content box's field must be a block of it with the same
bits, and every voxel of the reach field that the content box leaves out must map
outside the volume (so it rendered nothing): checked at every such voxel centre
with the reach field's own mapping (:meth:`WireFieldWarp.apply`, the shader's).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from tests.deform.wires.test_wire_field_build import smooth_variant, volume, wires
from voxwarp.core.volume import Volume
from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires import field_geometry
from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.sides import _grow_one
from voxwarp.deform.wires.wire import Wire


def built(vol: Volume, ws: list[Wire], scale: int, box: str) -> WireDeformer:
    wd = WireDeformer(vol, ws, field_scale=scale, box=box)
    wd.build()
    return wd


def block_of(small: Any, big: Any) -> tuple[slice, ...]:
    """The small field's voxels within the big field (same grid, wholly inside it)."""
    off = (small.lo - big.lo) / big.spacing
    np.testing.assert_allclose(off, np.rint(off), atol=1e-6)
    np.testing.assert_array_equal(small.spacing, big.spacing)
    first = np.rint(off).astype(int)
    assert np.all(first >= 0)
    assert np.all(first + small.shape <= big.shape)
    return tuple(slice(int(o), int(o) + n) for o, n in zip(first, small.shape, strict=True))


def assert_block_of_reach(vol: Volume, ws: list[Wire], scale: int) -> tuple[int, int]:
    """The content field against the reach field (see the module docstring); returns
    both fields' voxel counts."""
    content, reach = built(vol, ws, scale, "content"), built(vol, ws, scale, "reach")
    assert content.box_used == "content"
    assert reach.box_used == "reach"
    small, big = content.field, reach.field
    block = block_of(small, big)
    for name in ("state", "t"):
        np.testing.assert_array_equal(getattr(small, name), getattr(big, name)[block], name)
    assert (small.weight is None) == (big.weight is None)
    if small.weight is not None:
        # the weights samples read: of the swept voxels and their neighbours (the rest
        # hold 1, unused: WireField.weight)
        known = _grow_one(small.state >= 2)
        np.testing.assert_array_equal(small.weight[known], big.weight[block][known])
    # the voxels left out render nothing: their originals lie outside the volume
    outside = np.ones(big.shape, dtype=bool)
    outside[block] = False
    idx = np.argwhere(outside & (big.state >= 2))
    p = big.lo + (idx + 0.5) * big.spacing
    q = reach.warp().apply(p)
    lo, hi = reach.volume_bounds
    half = 0.5 * float(np.max(vol.spacing))  # an oblique voxel may lie across the axes
    inside = np.all((q > lo - half) & (q < hi + half), axis=1)
    assert not inside.any(), f"{int(inside.sum())} left-out voxels map into the volume"
    return int(np.prod(small.shape)), int(np.prod(big.shape))


@pytest.mark.parametrize("kind", ["rigid", "smoothends", "smoothsides"])
@pytest.mark.parametrize("scale", [1, 2])
def test_content_box_is_a_block_of_the_reach_box(kind: str, scale: int) -> None:
    # bent, twisted (1.2 rad) and scaled (1.3x) wires on two rods
    ws = wires() if kind == "rigid" else smooth_variant(kind)
    small, big = assert_block_of_reach(volume(), ws, scale)
    assert small <= big
    if kind != "rigid":  # the smooth ends' fade reaches far beyond the volume
        assert small < big


def test_content_dragged_out_of_the_volume_stays_in_the_box() -> None:
    # the second rod's end pulled 12 mm beyond the volume's face: its content moves
    # out there, and the box must hold it
    vol = volume()
    w = wires()[1].to_dict()
    w["modified"] = [list(p) for p in w["base"]]
    w["modified"][-1] = [w["base"][-1][0] + 12.0, w["base"][-1][1], w["base"][-1][2]]
    w["twist"] = 0.0
    dragged = Wire.from_dict(w)
    _small, _big = assert_block_of_reach(vol, [dragged], 1)
    wd = built(vol, [dragged], 1, "content")
    q = wd.warp().apply(wd.field.lo + (np.argwhere(wd.field.state >= 2) + 0.5) * wd.field.spacing)
    lo, hi = wd.volume_bounds
    # content really lies beyond the volume's face, inside the field
    assert wd.field.hi[0] > hi[0] + 6.0
    assert np.any(np.all((q > lo) & (q < hi), axis=1))


def test_head_wire_field_is_smaller_and_the_same() -> None:
    # the cost table's MRI head wire (smooth ends, twisted and bent top), at 64³
    from benchmarks.wires import HEAD_WIRE, head_volume

    small, big = assert_block_of_reach(head_volume(64), [Wire(**HEAD_WIRE)], 2)
    assert small < 0.7 * big


def test_a_box_that_cuts_content_falls_back_to_the_whole_reach(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # a content box forced down to the volume's box cuts the rod moved 10 mm sideways,
    # out through the volume's face: the swept voxels on the cut face map into the
    # volume, so the build runs again
    vol = volume()
    w = wires()[1].to_dict()
    w["modified"] = [[p[0], p[1] + 10.0, p[2]] for p in w["base"]]
    dragged = [Wire.from_dict(w)]
    reach = built(vol, dragged, 1, "reach")
    monkeypatch.setattr(
        field_geometry, "content_box", lambda probes, volume_box, loose, cells: loose
    )
    whole = built(vol, dragged, 1, "content")
    assert whole.box_used == "content"  # the loose box cuts nothing
    monkeypatch.setattr(
        field_geometry, "content_box", lambda probes, volume_box, loose, cells: volume_box
    )
    cut = built(vol, dragged, 1, "content")
    assert cut.box_used == "reach"
    for name in ("state", "t"):
        np.testing.assert_array_equal(getattr(cut.field, name), getattr(reach.field, name))


def test_unknown_box_is_a_one_line_error() -> None:
    with pytest.raises(WarpError, match="box must be one of"):
        WireDeformer(volume(), wires(), box="tight")


@pytest.mark.parametrize(
    "options", [{"layout": "packed"}, {"layout": "paper"}, {"propagate": "flagged"}]
)
def test_other_layouts_and_the_flagged_propagation_keep_the_block(options: dict) -> None:
    for ws in (wires(), smooth_variant("smoothends")):
        fields = {}
        for box in ("content", "reach"):
            wd = WireDeformer(volume(), ws, field_scale=1, box=box, **options)
            wd.build()
            assert wd.box_used == box
            fields[box] = wd.field
        small, big = fields["content"], fields["reach"]
        block = block_of(small, big)
        names = ("code",) if "layout" in options else ("state", "t")
        for name in names:
            np.testing.assert_array_equal(getattr(small, name), getattr(big, name)[block], name)


def test_an_oblique_anisotropic_volume_keeps_the_block() -> None:
    # the rods turned 35 degrees about z and 20 about x, 2.5 mm slices: the volume's
    # world box is its axis-aligned bound, and its voxels lie across the world axes; the
    # smooth ends fade over 60 mm, far past that box
    vol = volume()
    cz, sz = np.cos(np.radians(35)), np.sin(np.radians(35))
    cx, sx = np.cos(np.radians(20)), np.sin(np.radians(20))
    rot = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array(
        [[1, 0, 0], [0, cx, -sx], [0, sx, cx]]
    )
    oblique = Volume(vol.data, (0.8, 0.8, 2.5), (-3.0, 2.0, 1.5), direction=rot)
    index = np.array(
        [[4.0, 12.0, 13.0], [14.0, 12.0, 13.0], [26.0, 12.0, 13.0], [35.0, 12.0, 13.0]]
    )
    base = oblique.index_to_world(index)
    moved = base + np.array([[0.0, 0, 0], [0, 2, 0], [3, 4, 0], [6, 6, 2]])
    w = Wire(
        base,
        moved,
        kind="bezier",
        radius=7.0,
        beta=(50, 2000),
        twist=[(0, 0), (1, 0.8)],
        falloff=60.0,
    )
    small, big = assert_block_of_reach(oblique, [w], 1)
    assert small < big
