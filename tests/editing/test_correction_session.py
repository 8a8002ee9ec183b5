"""A registration corrected in the editing session (what the GUI drives, Qt-free): an
imported field, a ChainMail, mass-spring or lattice correction dragged with the camera.

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


@pytest.mark.parametrize("kind", ["chainmail", "massspring", "lattice"])
def test_a_drag_on_top_of_a_field_moves_what_is_seen_and_undoes_exactly(
    volume: Volume, kind: str
) -> None:
    s = EditSession(Scene(volume))
    field = swirl(volume)
    s.add_warps_front([field])
    s.set_deformation(kind, resolution=5)
    u0 = field.displacements.copy()
    export0 = s.scene.displacement_field(spacing=4.0).displacements.copy()
    handles = s.handles()
    ref = int(np.argmin(np.linalg.norm(handles - np.mean(handles, axis=0), axis=1)))
    s.select([ref])
    s.set_reference(ref)
    before = s.snapshot()
    moved = drag(s, camera_for(handles, "+z", "orthographic"), (12.0, -5.0))
    for _ in range(300):  # mass-spring: the springs carry the drag to the neighbours
        s.advance()
    old, new = moved["before"][ref], moved["after"][ref]
    np.testing.assert_allclose(s.handles()[ref], new)  # the held handle stays put
    assert np.linalg.norm(new - old) > 3.0  # mm
    assert s.scene.warps[-1] is field  # the correction first, then the registration
    seen_before = chain_apply([field], old.reshape(1, 3))
    seen_after = chain_apply(s.scene.warps, new.reshape(1, 3))
    # within the error of the models' inverse maps (a few % of the drag)
    print(kind, np.linalg.norm(new - old), np.abs(seen_after - seen_before).max())
    np.testing.assert_allclose(seen_after, seen_before, atol=0.05 * np.linalg.norm(new - old))
    export1 = s.scene.displacement_field(spacing=4.0).displacements
    assert np.abs(export1 - export0).max() > 1.0
    s.restore(before)  # what Edit -> Undo does
    np.testing.assert_array_equal(s.scene.displacement_field(spacing=4.0).displacements, export0)
    assert s.imported_warps == [field]
    np.testing.assert_array_equal(field.displacements, u0)
