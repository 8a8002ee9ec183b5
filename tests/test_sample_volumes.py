"""Tests of the sample volumes: determinism, shapes, anatomy and the bundled real scans."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage as ndi

import voxwarp.sample_volumes as sv
from voxwarp.sample_volumes import SampleData

GENERATORS: dict[str, Callable[..., SampleData]] = {
    "fish": sv.fish,
    "tubes": sv.tubes,
    "head": sv.head,
}
FOV = {"fish": sv.FISH_FOV_MM, "tubes": sv.TUBES_FOV_MM, "head": sv.HEAD_FOV_MM}
SMALL = (40, 20, 16)
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fish() -> SampleData:
    return sv.fish()


@pytest.fixture(scope="module")
def tubes() -> SampleData:
    return sv.tubes()


@pytest.fixture(scope="module")
def head() -> SampleData:
    return sv.head()


def _exterior(mask: np.ndarray) -> np.ndarray:
    """Voxels of ``mask`` connected to the volume border."""
    lab, _ = ndi.label(mask)
    border = np.unique(
        np.concatenate([lab[[0, -1]].ravel(), lab[:, [0, -1]].ravel(), lab[:, :, [0, -1]].ravel()])
    )
    return np.isin(lab, border[border > 0])


# --------------------------------------------------------------------------- registry
def test_names_lists_phantoms_and_real_scans() -> None:
    assert sv.names() == ["fish", "tubes", "head", "stent", "colin27"]


def test_get_dispatches_with_kwargs() -> None:
    a = sv.get("fish", shape=SMALL, seed=3)
    b = sv.fish(SMALL, seed=3)
    np.testing.assert_array_equal(a.data, b.data)
    assert a.spacing == b.spacing


def test_get_unknown_name_raises() -> None:
    with pytest.raises(KeyError, match="fish"):
        sv.get("trout")


def test_real_scans_take_no_kwargs() -> None:
    with pytest.raises(TypeError):
        sv.get("stent", shape=(10, 10, 10))


def test_package_imports_nothing_from_the_project() -> None:
    code = (
        "import sys, sample_volumes as s; s.get('fish', shape=(8, 6, 5)); s.get('stent');"
        "print(sorted({m.split('.')[0] for m in sys.modules}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    ).stdout
    loaded = set(eval(out))
    assert not loaded & {"app", "deform", "ui", "shaders", "nibabel", "moderngl"}


# --------------------------------------------------------------------------- generators
@pytest.mark.parametrize("name", list(GENERATORS))
def test_same_seed_same_volume_other_seed_other_noise(name: str) -> None:
    gen = GENERATORS[name]
    a, b, c = gen(SMALL, seed=0), gen(SMALL, seed=0), gen(SMALL, seed=1)
    np.testing.assert_array_equal(a.data, b.data)
    diff = a.data.astype(np.float64) - c.data.astype(np.float64)
    assert np.count_nonzero(diff) > 0.5 * diff.size
    # only the noise differs: the difference of two N(0, 10) fields has std ~14 HU
    assert 10.0 < diff.std() < 20.0
    assert abs(diff.mean()) < 2.0


@pytest.mark.parametrize("name", list(GENERATORS))
@pytest.mark.parametrize("shape", [SMALL, (7, 5, 3), (1, 1, 1), (33, 17, 64)])
def test_any_shape_gives_int16_hu(name: str, shape: tuple[int, int, int]) -> None:
    s = GENERATORS[name](shape)
    assert s.data.shape == shape
    assert s.data.dtype == np.int16
    assert s.units == "HU"
    np.testing.assert_allclose(s.spacing, np.array(FOV[name]) / shape)
    assert s.description
    assert s.source
    assert s.license


@pytest.mark.parametrize("name", list(GENERATORS))
def test_bad_shape_raises(name: str) -> None:
    with pytest.raises(ValueError, match="shape"):
        GENERATORS[name]((10, 0, 10))


def test_default_shapes_and_spacing(fish: SampleData, tubes: SampleData, head: SampleData) -> None:
    assert fish.data.shape == (192, 96, 80)
    assert tubes.data.shape == (128, 128, 96)
    assert head.data.shape == (128, 128, 128)
    assert fish.spacing == (0.5, 0.5, 0.5)
    assert tubes.spacing == (0.5, 0.5, 0.5)
    assert head.spacing == (1.5, 1.5, 1.5)


# --------------------------------------------------------------------------- fish
def test_fish_hu_classes(fish: SampleData) -> None:
    d = fish.data
    assert abs(np.median(d[:, :3, :]) + 1000) < 5  # background air
    body = ndi.binary_fill_holes(d > -500)
    assert 0.03 < body.mean() < 0.3  # a slender fish, with room around it to bend
    tissue = d[body & (d > -200) & (d < 200)]
    assert 30 < np.median(tissue) < 70  # muscle
    assert np.count_nonzero((d > -150) & (d < -60)) > 500  # belly fat
    assert 1200 < d.max() < 1800  # vertebrae
    # thin fins (opened away) sticking out of the bulky body, at about 100-200 HU
    solid = d > -500
    fins = solid & ~ndi.binary_dilation(ndi.binary_opening(solid, iterations=2))
    assert np.count_nonzero(fins) > 1000
    assert 50 < np.median(d[fins]) < 200
    assert np.percentile(d[fins], 95) > 120


def test_fish_bone_lies_inside_the_body(fish: SampleData) -> None:
    d = fish.data
    bone = d > 500
    assert np.count_nonzero(bone) > 1000
    body = ndi.binary_fill_holes(d > -500)
    assert not np.any(bone & ~body)
    outside_air = _exterior(d < -500)
    assert not np.any(ndi.binary_dilation(bone) & outside_air)  # bone never touches air


def test_fish_swim_bladder_is_air_enclosed_by_tissue(fish: SampleData) -> None:
    d = fish.data
    air = d < -500
    inner = air & ~_exterior(air)
    _lab, n = ndi.label(inner)
    assert n == 1  # the two lobes are joined by a narrow waist
    assert np.count_nonzero(inner) > 1000
    assert np.median(d[inner]) < -700
    # a shell 2-3 voxels around it is all tissue (no air, no background)
    shell = ndi.binary_dilation(inner, iterations=3) & ~ndi.binary_dilation(inner, iterations=1)
    assert d[shell].min() > -300
    # below the spine, in the front half of the fish
    spine = sv.fish_spine(d.shape, n=200)
    ci, _, ck = ndi.center_of_mass(inner)
    assert ck < np.interp(ci, spine[:, 0], spine[:, 2])
    assert spine[0, 0] < ci < 0.6 * d.shape[0]


def test_fish_vertebrae_are_separate_along_x(fish: SampleData) -> None:
    d = fish.data
    spine = sv.fish_spine(d.shape, n=400)
    # voxels within 2.5 voxels of the spine line
    i, j, k = np.indices(d.shape, sparse=True)
    near = np.zeros(d.shape, bool)
    for p in spine[::2]:
        near |= (i - p[0]) ** 2 + (j - p[1]) ** 2 + (k - p[2]) ** 2 <= 2.5**2
    lab, _n = ndi.label((d > 500) & near)
    sizes = np.bincount(lab.ravel())[1:]
    big = np.flatnonzero(sizes >= 10) + 1
    assert len(big) >= 5
    cx = np.sort([c[0] for c in ndi.center_of_mass(lab > 0, lab, big)])
    assert np.all(np.diff(cx) > 3.0)  # one centrum per ~5.5 voxels, none merged
    assert cx[0] < 0.3 * d.shape[0]
    assert cx[-1] > 0.75 * d.shape[0]
    # discs between the centra: the spine line alternates bone and softer tissue
    along = ndi.map_coordinates(d.astype(np.float32), spine.T, order=1)
    assert np.count_nonzero(along > 1000) > 100
    assert np.count_nonzero(along < 300) > 50


def test_fish_has_ribs_hanging_below_the_spine(fish: SampleData) -> None:
    d = fish.data
    nx, ny, _ = d.shape
    spine = sv.fish_spine(d.shape, n=200)
    x0, x1 = int(0.3 * nx), int(0.5 * nx)
    k_spine = int(np.interp(0.4 * nx, spine[:, 0], spine[:, 2]))
    slab = d[x0:x1, :, : k_spine - 6] > 500  # bone well below the spine
    left, right = slab[:, : ny // 2 - 2].any(axis=(0, 1)), slab[:, ny // 2 + 2 :].any(axis=(0, 1))
    assert left.sum() > 5
    assert right.sum() > 5


def test_fish_spine_follows_the_vertebrae(fish: SampleData) -> None:
    spine = sv.fish_spine(fish.data.shape, n=50)
    assert spine.shape == (50, 3)
    assert np.all(np.diff(spine[:, 0]) > 0)
    vals = ndi.map_coordinates(fish.data.astype(np.float32), spine.T, order=1)
    assert np.all(vals > 60)  # bone or disc all along, never air or fat


# --------------------------------------------------------------------------- tubes
def test_tubes_are_separate_but_nearly_touching(tubes: SampleData) -> None:
    d = tubes.data
    wall = d > 100
    lab, n = ndi.label(wall)
    assert n == 5
    sizes = np.bincount(lab.ravel())[1:]
    assert sizes.min() > 2000
    gaps = []
    for a in range(1, n + 1):
        dist = ndi.distance_transform_edt(lab != a)
        gaps += [dist[lab == b].min() - 1.0 for b in range(a + 1, n + 1)]
    assert min(gaps) <= 3.0  # nearly touching: at most 3 voxels of background between
    assert sum(g <= 3.0 for g in gaps) >= 4  # several close pairs
    # hollow: a lumen (~0 HU) inside walls of 250-400 HU, in fat
    assert np.count_nonzero((d > -40) & (d < 40)) > 10_000
    assert 250 < np.median(d[wall & (d > 200)]) < 400
    assert abs(np.median(d) + 100) < 10


# --------------------------------------------------------------------------- head
def test_head_skull_encloses_the_brain(head: SampleData) -> None:
    d = head.data
    skull = d > 500
    lab, n = ndi.label(~skull)
    assert n == 2  # outside and inside: the shell is closed
    c = tuple(s // 2 for s in d.shape)
    inside = lab == lab[c]
    assert not np.any(inside & _exterior(~skull))
    assert 30 < np.median(d[inside]) < 50  # brain
    ventricles = inside & (d < 20) & (d > 0)
    assert np.count_nonzero(ventricles) > 1000
    assert np.count_nonzero(inside & (d > 60) & (d < 90)) > 20  # lesions
    beyond = ~inside & ~ndi.binary_dilation(skull, iterations=2)
    assert np.all(d[beyond] < 80)  # outside: scalp and air only


# --------------------------------------------------------------------------- real scans
@pytest.mark.parametrize(
    ("name", "shape", "dtype", "spacing"),
    [
        ("stent", (128, 128, 256), np.uint8, (1.0, 1.0, 1.0)),
        ("colin27", (91, 109, 91), np.uint8, (2.0, 2.0, 2.0)),
    ],
)
def test_real_scans_load(
    name: str, shape: tuple[int, int, int], dtype: type, spacing: tuple[float, float, float]
) -> None:
    s = sv.get(name)
    assert s.data.shape == shape
    assert s.data.dtype == dtype
    assert s.spacing == spacing
    assert s.units == ""
    assert "BSD-3-Clause" in s.license
    assert s.data.max() > s.data.min()


def test_stent_is_bright_along_z() -> None:
    d = sv.stent().data
    assert d.max() == 32
    # the stent graft (brightest voxels) spans most of the length along z
    k = np.flatnonzero((d >= 30).any(axis=(0, 1)))
    assert k.max() - k.min() > 0.6 * d.shape[2]


def test_colin27_origin_is_mni() -> None:
    s = sv.colin27()
    assert s.origin == (-89.5, -124.5, -70.5)
    centre = (-np.asarray(s.origin) / np.asarray(s.spacing)).round().astype(int)
    # MNI (0, 0, 0), the anterior commissure, lies deep inside the head, amid brain tissue
    assert ndi.binary_fill_holes(s.data > 20)[tuple(centre)]
    i, j, k = centre
    assert s.data[i - 4 : i + 5, j - 4 : j + 5, k - 4 : k + 5].mean() > 60
