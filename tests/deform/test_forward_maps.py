"""Forward maps (original -> deformed) of every warp family: the inverse of ``apply``.

Oracle: ``apply(forward(x)) = x`` on random original points of the deformed region,
and ``forward(apply(p)) = p`` where the warp is invertible, each within a tolerance
stated per family (measured values in the comments):

* affine: closed forms both ways (float64 rounding);
* offset fields (mass-spring, ChainMail, a GPU-owned field read back): ``forward`` is
  exact (``X + u(X)``); ``apply`` solves ``q + u(q) = p`` by its fixed-point steps, so
  the round trip is as good as the inverse's iterations;
* wire field: the sweep's closed-form seed polished by Newton steps down to
  :attr:`Warp.forward_tolerance` (1e-4 mm), checked by ``check_forward``;
* lattice: closed-form forward, Newton inverse;
* a chain of three (affine, offset field, lattice) through ``chain_forward``.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.deform.lattice.test_lattice_warp import BOX, bent
from tests.deform.wires.test_wires import build, cylinder, wire
from voxwarp.deform import ChainMail
from voxwarp.deform.elements.grid import ElementGrid
from voxwarp.deform.elements.massspring import MassSpring
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.warp import (
    AffineWarp,
    Warp,
    WarpError,
    chain_apply,
    chain_forward,
)

RNG_SEED = 18


def points_in(lo: np.ndarray, hi: np.ndarray, n: int, seed: int = RNG_SEED) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, size=(n, 3))


def round_trips(warp: Warp, x: np.ndarray) -> tuple[float, float]:
    """Largest ``|apply(forward(x)) - x|`` and ``|forward(apply(p)) - p|`` (mm), with
    ``p = forward(x)``."""
    p = warp.forward(x)
    there = float(np.linalg.norm(warp.apply(p) - x, axis=1).max())
    back = float(np.linalg.norm(warp.forward(warp.apply(p)) - p, axis=1).max())
    return there, back


def element_box() -> ElementGrid:
    return ElementGrid(((0.0, 0.0, 0.0), (40.0, 40.0, 40.0)), shape=5)


def massspring_warp() -> OffsetFieldWarp:
    ms = MassSpring(element_box())
    ms.move((2, 2, 2), (4.0, -2.0, 1.0))
    ms.step(100)
    return ms.warp(inverse="exact", iterations=24)


def chainmail_warp() -> OffsetFieldWarp:
    cm = ChainMail(element_box())
    cm.move((2, 2, 2), (5.0, 3.0, 0.0))
    cm.relax(4)
    return cm.warp(inverse="exact", iterations=24)


def test_affine_round_trips_to_rounding() -> None:
    w = AffineWarp(
        AffineWarp.rotation((1, 2, 3), 33.0, (5, 5, 5)).forward_matrix
        @ AffineWarp.scaling((1.2, 0.8, 1.1)).forward_matrix
    )
    there, back = round_trips(w, points_in(np.full(3, -50.0), np.full(3, 50.0), 500))
    assert there < 1e-12
    assert back < 1e-12


@pytest.mark.parametrize("make", [massspring_warp, chainmail_warp], ids=["massspring", "chainmail"])
def test_offset_field_forward_inverts_apply(make: object) -> None:
    w = make()  # type: ignore[operator]
    assert np.abs(w.displacements).max() > 3.0  # a real deformation
    x = points_in(w.lo + 1.0, w.hi - 1.0, 2000)
    there, back = round_trips(w, x)
    # 24 fixed-point steps; measured: mass-spring 2.7e-6 / 1.2e-6 mm (det(I + grad u)
    # down to 0.53, so the steps contract slowly), ChainMail 2e-10 mm
    assert there < 1e-4, there
    assert back < 1e-4, back


def test_gpu_owned_field_forward_reads_the_field_back() -> None:
    w = massspring_warp()
    u = w.displacements
    reads: list[int] = []
    gpu = OffsetFieldWarp(
        w.lo,
        w.hi,
        shape=w.shape,
        texture_source=lambda ctx: None,
        field_reader=lambda: (reads.append(1), u)[1],
        revision_source=lambda: 7,
    )
    x = points_in(w.lo, w.hi, 300)
    np.testing.assert_array_equal(gpu.field_forward(x), w.field_forward(x))
    gpu.field_forward(x)
    assert len(reads) == 1  # read back once per revision
    blind = OffsetFieldWarp(w.lo, w.hi, shape=w.shape, texture_source=lambda ctx: None)
    with pytest.raises(WarpError, match="field_reader") as info:
        blind.forward(x)
    assert "\n" not in str(info.value)


def test_wire_forward_follows_the_sweep() -> None:
    vol = cylinder()
    bend = [[4.0, 19.5, 19.5], [20.0, 22.0, 19.5], [36.0, 25.0, 21.0], [60.0, 27.0, 22.0]]
    w = build(vol, [wire(modified=bend, twist=[(0.0, 0.0), (1.0, 1.0)])], field_scale=2)
    inside = np.argwhere(np.asarray(vol.data) > 50).astype(float)
    rng = np.random.default_rng(RNG_SEED)
    x = vol.index_to_world(
        inside[rng.choice(len(inside), 1500)] + rng.uniform(-0.4, 0.4, (1500, 3))
    )
    p = w.forward(x)
    assert np.linalg.norm(p - x, axis=1).max() > 5.0  # the object moved
    assert np.linalg.norm(w.apply(p) - x, axis=1).max() <= w.forward_tolerance
    swept = w.swept(p)
    assert swept.mean() > 0.9
    # measured: residual 1e-4 mm (the Newton stop), all swept, forward(apply(p)) 1e-4 mm
    # where the deformed point is swept, forward undoes apply (the sweep is one to one)
    back = w.forward(w.apply(p[swept]))
    assert np.linalg.norm(back - p[swept], axis=1).max() < 1e-3


def test_wire_forward_leaves_unswept_content_in_place() -> None:
    vol = cylinder()
    w = build(vol, [wire(modified=[[x, 22.5, 19.5] for x in (4.0, 20.0, 36.0, 60.0)])])
    far = np.array([[30.0, 2.0, 2.0], [60.0, 35.0, 3.0]])  # empty corners, no wire near
    np.testing.assert_array_equal(w.forward(far), far)


def test_lattice_forward_matches_the_interface_and_inverts_apply() -> None:
    w = bent()
    x = points_in(BOX[0] + 2.0, BOX[1] - 2.0, 1500)
    p = w.forward(x)
    assert p.shape == x.shape
    assert w.forward(x[0]).shape == (1, 3)
    there, back = round_trips(w, x)
    # Newton inverse (default iterations) of a bent lattice; measured: 5e-8 mm
    assert there < 1e-3, there
    assert back < 1e-3, back


def test_chain_of_three_round_trips() -> None:
    lattice = bent()
    field = massspring_warp()
    rot = AffineWarp.rotation((0, 0, 1), 10.0, (20.0, 20.0, 20.0))
    chain: list[Warp] = [rot, field, lattice]
    # inside the field's box after the lattice (content the field pushes across its
    # box's faces is cut off there, see OffsetFieldWarp)
    x = points_in(np.full(3, 10.0), np.full(3, 30.0), 1000)
    p = chain_forward(chain, x)
    err = np.linalg.norm(chain_apply(chain, p) - x, axis=1).max()
    assert np.linalg.norm(p - x, axis=1).max() > 2.0
    # the members' round-trip errors add up; measured: 6e-8 mm
    assert err < 1e-4, err
