"""The deformations of "Render deformed view" (no Qt): the push moves the centre where
it says, a scene file lends its warps, bad choices are one-line errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from voxwarp import Scene, load_sample
from voxwarp.deform import chain_apply
from voxwarp.errors import SceneError
from voxwarp.napari_plugin.deformed_view import (
    PUSH_FRACTION,
    deformation_warps,
    deformed_scene,
    push_warps,
)


@pytest.fixture(scope="module")
def head() -> object:
    return load_sample("head", shape=(24, 24, 24))


@pytest.fixture(scope="module")
def pushed(head: object) -> list:
    return push_warps(head, direction=(0.0, 2.0, 0.0))  # normalised: +y


def test_push_moves_the_centre_along_the_direction(head: object, pushed: list) -> None:
    (warp,) = pushed
    grid_centre = head.bounds[0] + 0.5 * head.size_mm  # the centre element
    moved = grid_centre + np.array([0.0, PUSH_FRACTION * head.size_mm[1], 0.0])
    # the warp maps deformed -> original: the moved place samples the element's rest place
    back = chain_apply([warp], moved[None])[0]
    np.testing.assert_allclose(back, grid_centre, atol=0.01 * head.size_mm[1])
    line = np.linspace(head.bounds[0], head.bounds[1], 50)
    line[:, [0, 2]] = grid_centre[[0, 2]]  # along the push through the centre
    assert np.all(np.diff(chain_apply([warp], line)[:, 1]) > 0)  # no fold ahead of the push
    corner = head.bounds[0]  # the grid's corners are fixed
    np.testing.assert_allclose(chain_apply([warp], corner[None])[0], corner, atol=1e-3)


def test_push_goes_up_the_screen(head: object, monkeypatch: pytest.MonkeyPatch) -> None:
    from voxwarp.core.camera import view_rotation
    from voxwarp.napari_plugin import deformed_view

    seen: list[np.ndarray] = []
    monkeypatch.setattr(deformed_view, "push_warps", lambda v, d: seen.append(d) or ["w"])
    scene = deformed_scene(head, {"view": "+z"}, "mass-spring push")
    assert scene.view == "+z"
    np.testing.assert_allclose(seen[0], view_rotation("+z")[:, 1], atol=1e-9)  # screen up
    assert deformed_scene(head, {"view": "+z"}, "none").warps == []


def test_scene_file_lends_its_warps(tmp_path: Path, head: object, pushed: list) -> None:
    path = Scene(head, warps=pushed).save(tmp_path / "pushed.json")
    (warp,) = deformation_warps("scene file", head, path)
    p = np.array([[92.0, 100.0, 92.0], [10.0, 12.0, 14.0]])
    assert not np.allclose(chain_apply(pushed, p), p)  # the points move
    np.testing.assert_allclose(chain_apply([warp], p), chain_apply(pushed, p), atol=1e-5)


@pytest.mark.parametrize(
    ("kind", "path", "message"),
    [
        ("scene file", None, "needs a scene JSON: pick one"),
        ("scene file", "/no/such/scene.json", "no such scene file"),
        ("twirl", None, "deformation must be one of"),
    ],
)
def test_bad_choices_are_one_line(kind: str, path: str | None, message: str, head: object) -> None:
    with pytest.raises(SceneError, match=message) as info:
        deformation_warps(kind, head, path)
    assert "\n" not in str(info.value)


def test_scene_file_without_warps_is_refused(tmp_path: Path, head: object) -> None:
    path = Scene(head).save(tmp_path / "plain.json")
    with pytest.raises(SceneError, match="has no warps"):
        deformation_warps("scene file", head, path)


def test_push_needs_a_direction(head: object) -> None:
    with pytest.raises(SceneError, match="non-zero vector"):
        push_warps(head, direction=(0.0, 0.0, 0.0))
