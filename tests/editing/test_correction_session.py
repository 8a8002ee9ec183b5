"""A registration corrected in the editing session (what the GUI drives, Qt-free): an
imported field, a ChainMail, mass-spring, lattice or wire correction dragged with the
camera (CPU, and the element models' GPU backends). The drag is across the wire (along
y; the session's first wire lies along the fish's x): a control point moved along its
own wire re-parametrises the sweep instead of carrying the point under it.

Oracles: the dragged handle lands where the cursor put it and the corrected chain there
reads the moving volume where the field alone read the handle's old position (the drag
moves what is seen where it is dragged); the exported field changes with the drag and an
undo (snapshot restore) gives back the earlier export exactly, with the imported field
untouched.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.editing.test_editor import camera_for, drag
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import chain_apply
from voxwarp.editing.session import EditSession
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene


@pytest.fixture(scope="module")
def volume() -> Volume:
    return load_sample("fish", shape=(48, 48, 48))


def swirl(volume: Volume) -> DisplacementFieldWarp:
    """A smooth field of up to 4 mm on a coarse grid over the volume's box."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in volume.bounds)
    n = np.array([12, 10, 9])
    affine = np.diag([*((hi - lo) / (n - 1)), 1.0])
    affine[:3, 3] = lo
    t = np.indices(n).transpose(1, 2, 3, 0) / (n - 1)
    u = np.zeros((*n, 3))
    u[..., 0] = 4.0 * np.sin(np.pi * t[..., 1])
    u[..., 2] = 2.0 * np.sin(np.pi * t[..., 0])
    return DisplacementFieldWarp(u, affine)


@pytest.mark.parametrize(
    ("kind", "backend"),
    [
        ("chainmail", "cpu"),
        ("massspring", "cpu"),
        ("lattice", "cpu"),
        ("wires", "cpu"),
        pytest.param("chainmail", "gpu", marks=pytest.mark.gl),
        pytest.param("massspring", "gpu", marks=pytest.mark.gl),
    ],
)
def test_a_drag_on_top_of_a_field_moves_what_is_seen_and_undoes_exactly(
    volume: Volume, kind: str, backend: str, request: pytest.FixtureRequest
) -> None:
    ctx = request.getfixturevalue("gl_ctx") if backend == "gpu" else None
    s = EditSession(Scene(volume), ctx)
    field = swirl(volume)
    s.add_warps_front([field])
    s.set_deformation(kind, resolution=5, backend=backend)
    u0 = field.displacements.copy()
    export0 = s.scene.displacement_field(spacing=4.0).displacements.copy()
    handles = s.handles()
    ref = int(np.argmin(np.linalg.norm(handles - np.mean(handles, axis=0), axis=1)))
    s.select([ref])
    s.set_reference(ref)
    before = s.snapshot()
    moved = drag(s, camera_for(handles, "+z", "orthographic"), (0.0, -12.0))
    for _ in range(300):  # mass-spring: the springs carry the drag to the neighbours
        s.advance()
    s.family.before_save()  # wires: the field of the dragged wire, built now
    old, new = moved["before"][ref], moved["after"][ref]
    np.testing.assert_allclose(s.handles()[ref], new)  # the held handle stays put
    assert np.linalg.norm(new - old) > 3.0  # mm
    assert s.scene.warps[-1] is field  # the correction first, then the registration
    seen_before = chain_apply([field], old.reshape(1, 3))
    seen_after = chain_apply(s.scene.warps, new.reshape(1, 3))
    # within the error of the models' inverse maps (a few % of the drag)
    print(kind, backend, np.linalg.norm(new - old), np.abs(seen_after - seen_before).max())
    np.testing.assert_allclose(seen_after, seen_before, atol=0.05 * np.linalg.norm(new - old))
    export1 = s.scene.displacement_field(spacing=4.0).displacements
    assert np.abs(export1 - export0).max() > 1.0
    s.restore(before)  # what Edit -> Undo does
    np.testing.assert_array_equal(s.scene.displacement_field(spacing=4.0).displacements, export0)
    assert s.imported_warps == [field]
    np.testing.assert_array_equal(field.displacements, u0)
    s.close()
