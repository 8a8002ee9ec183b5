"""The minIP hint (voxwarp.core.minip_hint): a thick volume whose rays all meet air says
which slab to take; a thin slab, or a volume without air on the way, says nothing."""

from __future__ import annotations

import numpy as np

from voxwarp.core.minip_hint import THICK_MM, minip_advice, minip_slab_hint
from voxwarp.core.volume import Volume
from voxwarp.scene import Scene


def chest(n: int = 64) -> Volume:
    """A 64³, 2 mm "chest" in HU, patient RAS: a body (40 HU) in air (-1000) with two
    lungs (-850) and a trachea (-1000) inside; 128 mm along every axis."""
    c = (n - 1) / 2
    i, j, k = np.meshgrid(*(np.arange(n) - c,) * 3, indexing="ij")
    data = np.full((n, n, n), -1000.0, np.float32)
    data[(i / 28) ** 2 + (j / 20) ** 2 < 1] = 40.0
    for side in (-1, 1):
        data[((i - side * 13) / 9) ** 2 + (j / 11) ** 2 + (k / 22) ** 2 < 1] = -850.0
    data[(i**2 + (j + 2) ** 2 < 9) & (k > -10)] = -1000.0
    origin = (-2.0 * c,) * 3  # centred on the world origin
    return Volume(data, spacing=(2.0, 2.0, 2.0), origin=origin, space="RAS", name="chest")


def test_a_thick_minip_says_which_slab_shows_the_airways() -> None:
    scene = Scene(chest(), mode="minip", view="anterior")
    note = scene.display_note()
    assert "a slab shows the airways" in note
    assert "--slab A:0:20" in note  # across the anterior view, through the centre
    assert "voxwarp slice INPUT --plane coronal --slab 20 --mode minip" in note
    assert note.count("\n") == 0


def test_a_thin_slab_gets_no_hint() -> None:
    vol = chest()
    lo, hi = vol.bounds
    slab = ((lo[0], -10.0, lo[2]), (hi[0], 10.0, hi[2]))  # 20 mm along y
    assert Scene(vol, mode="minip", view="anterior", clip_box=slab).display_note().find("slab") < 0
    back = (0.0, 1.0, 0.0)
    assert minip_advice(vol, Scene(vol, mode="minip").window, back, slab) is None


def test_no_hint_without_air_on_the_way() -> None:
    """A thick volume of tissue alone: its minIP is not dark, so no hint."""
    rng = np.random.default_rng(0)
    data = (40 + 10 * rng.standard_normal((48, 48, 48))).astype(np.float32)
    scene = Scene(Volume(data, spacing=(2, 2, 2)), mode="minip", view="+y")
    assert 48 * 2 > THICK_MM
    assert minip_slab_hint(scene.volume, scene.window, (0, 1, 0), scene.ray_bounds()) is None
    assert "slab" not in scene.display_note()


def test_the_advice_cuts_the_box_to_a_slab_across_the_view() -> None:
    vol = chest()
    scene = Scene(vol, mode="minip", view="anterior")
    advice = minip_advice(vol, scene.window, (0, 1, 0), scene.ray_bounds())
    assert advice is not None
    assert advice.axis == 1
    assert advice.thickness > THICK_MM
    assert advice.share >= 0.9
    lo, hi = advice.slab_box(scene.ray_bounds())
    assert (lo[1], hi[1]) == (-10.0, 10.0)
    assert (lo[0], hi[0]) == tuple(map(float, (vol.bounds[0][0], vol.bounds[1][0])))
    # from above, the rays through the body meet no air: the minIP is not dark
    assert minip_advice(vol, scene.window, (0, 0, 1), scene.ray_bounds()) is None
