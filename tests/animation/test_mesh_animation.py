"""Animated attachments (GRAPP 2010, section 5 and Figure 8): ``meshes[NAME].nodes`` tracks
(app/animation/mesh_targets.py) and the bundled ``sample_volumes/lattice_accessories_anim.json``.

Oracles: the smoothstep blend of the two keys, computed here; anchor points and normals
recomputed here from the deformed base triangles (barycentric sums and cross products,
not through :func:`~voxwarp.deform.lattice.anchors.anchor_frames`); the static scenes that
:func:`~voxwarp.teaching.lattice_scenes.accessories` builds at the key poses; a direct
render of the static pose for a frame ``voxwarp animate`` wrote.
"""

from __future__ import annotations

import copy
import json
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import voxwarp.animation.frames
from voxwarp.animation.movie import animate
from voxwarp.animation.tracks import Animation, AnimationError, evaluate
from voxwarp.core.mesh import MeshInstance
from voxwarp.deform.lattice.anchors import AnchorStrip
from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.io.images import read_image
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene
from voxwarp.teaching.lattice_scenes import (
    ACCESSORY_KEYS,
    accessories,
    accessories_anim,
    accessory_attachments,
    accessory_body,
)

ROOT = Path(__file__).resolve().parents[2]
BUNDLED = ROOT / "sample_volumes" / "lattice_accessories_anim.json"
TARGET = "meshes[body].nodes"


@pytest.fixture(autouse=True)
def _quiet() -> Iterator[None]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # HU presets on the empty carrier volume
        yield


@pytest.fixture(scope="module")
def scene() -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return accessories_anim()


@pytest.fixture(scope="module")
def frames(scene: dict[str, Any]) -> list[dict[str, Any]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return evaluate(scene).scenes


def _nodes(d: dict[str, Any], name: str) -> np.ndarray:
    entry = next(m for m in d["meshes"] if m["name"] == name)
    return np.asarray(entry["transform"]["grid"]["nodes"], dtype=np.float64)


def _key_nodes(angle: float) -> np.ndarray:
    return _nodes(accessories(angle).to_dict(), "body")


def test_in_between_anchors_sit_on_the_interpolated_base_triangles(
    frames: list[dict[str, Any]],
) -> None:
    f = 3  # half way from key 0 (bent 1.2 rad) to key 6 (straight), smooth
    assert ACCESSORY_KEYS[0] == (0, 1.2)
    assert ACCESSORY_KEYS[1] == (6, 0.0)
    t = 0.5
    s = 3 * t * t - 2 * t**3
    a, b = _key_nodes(1.2), _key_nodes(0.0)
    expected = a + s * (b - a)
    got = _nodes(frames[f], "body")
    np.testing.assert_allclose(got, expected, atol=1e-12)
    assert np.abs(got - a).max() > 5.0  # really in between
    assert np.abs(got - b).max() > 5.0
    body, box = accessory_body()
    v = MeshInstance(body, TrilinearGrid(expected), box=box).world_vertices()
    tri = v[np.asarray(body.faces)]  # (M, 3, 3)
    for name, strip, _, _ in accessory_attachments():
        flat = [an for row in strip.anchors for an in row]
        corners = tri[[an.triangle for an in flat]]
        p = np.einsum("kc,kci->ki", [an.position for an in flat], corners)
        n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        n /= np.linalg.norm(n, axis=1)[:, None]
        nodes = _nodes(frames[f], name)
        if strip.two_d:  # plate: (m, n, 2, 3), bottom at the offset along the normal
            bottom, top = nodes[:, :, 0].reshape(-1, 3), nodes[:, :, 1].reshape(-1, 3)
            np.testing.assert_allclose(bottom, p + strip.offset * n, atol=1e-9)
        else:  # band: (n, 2, 2, 3), centred across on the anchors
            bottom, top = nodes[:, :, 0].mean(axis=1), nodes[:, :, 1].mean(axis=1)
            np.testing.assert_allclose(bottom, p, atol=1e-9)
            # across the band: the frame's y = n x (tangent point - P, flattened onto
            # the triangle), the anchor's coordinate system of section 5
            x = np.einsum("kc,kci->ki", [an.tangent for an in flat], corners) - p
            x -= np.einsum("ki,ki->k", x, n)[:, None] * n
            y = np.cross(n, x / np.linalg.norm(x, axis=1)[:, None])
            across = nodes[:, 1, 0] - nodes[:, 0, 0]
            np.testing.assert_allclose(across, strip.width * y, atol=1e-9)
        np.testing.assert_allclose(top - bottom, strip.thickness * n, atol=1e-9)


def test_the_attached_mesh_follows_its_anchors_in_the_frame_scene(
    frames: list[dict[str, Any]],
) -> None:
    sc = Scene.from_dict(frames[9])
    band = next(m for m in sc.meshes if m.name == "band 1")
    body = next(m for m in sc.meshes if m.name == "body")
    strip = next(s for n, s, _, _ in accessory_attachments() if n == "band 1")
    anchors = strip.anchors[0]
    v = body.world_vertices()
    tri = v[np.asarray(body.mesh.faces)][[an.triangle for an in anchors]]
    p = np.einsum("kc,kci->ki", [an.position for an in anchors], tri)
    u = np.stack([np.linspace(0, 1, len(p)), np.full(len(p), 0.5), np.zeros(len(p))], -1)
    lo, hi = band.box
    np.testing.assert_allclose(band.local_to_world(lo + u * (hi - lo)), p, atol=1e-9)
    # and the band did move between frames (it is not the saved pose)
    assert np.abs(_nodes(frames[9], "band 1") - _nodes(frames[0], "band 1")).max() > 5.0


@pytest.mark.parametrize(("index", "angle"), [(0, 1.2), (6, 0.0), (12, -1.2), (24, 1.2)])
def test_key_frames_equal_the_static_scenes_at_those_poses(
    frames: list[dict[str, Any]], index: int, angle: float
) -> None:
    static = accessories(angle).to_dict()
    assert len(frames[index]["meshes"]) == len(static["meshes"]) == 4
    for m in static["meshes"]:
        np.testing.assert_allclose(
            _nodes(frames[index], m["name"]), _nodes(static, m["name"]), atol=1e-9
        )


def test_scene_json_round_trips_and_the_bundled_file_is_current(scene: dict[str, Any]) -> None:
    anim = Animation.from_scene_dict(scene)
    again = Animation.from_dict(json.loads(json.dumps(anim.to_dict())))
    assert again == anim
    assert again.to_dict() == scene["animation"]
    assert "attachments" in again.tracks[0].to_dict()
    # regenerate: .venv/bin/python scripts/make_lattice_demos.py
    assert json.loads(BUNDLED.read_text(encoding="utf-8")) == json.loads(json.dumps(scene))
    for _, strip, _, _ in accessory_attachments():
        back = AnchorStrip.from_dict(json.loads(json.dumps(strip.to_dict())))
        assert back.anchors == strip.anchors
        assert (back.thickness, back.width, back.offset) == (
            strip.thickness,
            strip.width,
            strip.offset,
        )


def _with_track(scene: dict[str, Any], **change: Any) -> dict[str, Any]:
    d = copy.deepcopy(scene)
    d["animation"]["tracks"][0].update(change)
    return d


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"keys": [[0, [[[[0.0, 0.0, 0.0]] * 2] * 2] * 2]]}, "must have its lattice's shape"),
        ({"target": "meshes[torso].nodes"}, "no mesh(es) named 'torso'; use one of"),
        ({"target": "meshes[band 0].nodes", "attachments": []}, "placed by a matrix"),
        ({"attachments": [{"mesh": "body", "anchors": [], "thickness": 1}]}, "'anchors'"),
        ({"attachments": [{"anchors": [], "thickness": 1}]}, "needs 'mesh'"),
        ({"attachments": {"mesh": "plate"}}, "must be a list"),
        ({"keys": [[0, "bent"]]}, "must be numbers"),
    ],
)
def test_bad_mesh_tracks_give_one_line_errors(
    scene: dict[str, Any], change: dict[str, Any], message: str
) -> None:
    d = _with_track(scene, **change)
    if change.get("target") == "meshes[band 0].nodes":  # a mesh placed by a matrix
        d["meshes"][1]["transform"] = {"matrix": np.eye(4).tolist()}
    with pytest.raises(AnimationError) as err:
        evaluate(d)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_anchors_off_the_base_mesh_and_misplaced_attachments_are_refused(
    scene: dict[str, Any],
) -> None:
    d = copy.deepcopy(scene)
    att = d["animation"]["tracks"][0]["attachments"][2]
    att["anchors"][0][0]["triangle"] = 10**6
    with pytest.raises(AnimationError, match="does not exist: the base mesh has"):
        evaluate(d)
    d = copy.deepcopy(scene)
    d["animation"]["tracks"].append({"target": "step", "keys": [[0, 1.0]], "attachments": []})
    with pytest.raises(AnimationError, match=r"belongs to meshes\[NAME\].nodes tracks only"):
        Animation.from_scene_dict(d)
    d = copy.deepcopy(scene)
    d["meshes"][1]["name"] = "body"
    with pytest.raises(AnimationError, match="2 mesh\\(es\\) named 'body'; give each mesh its own"):
        evaluate(d)
    d = copy.deepcopy(scene)  # band 0 follows the body: it cannot be keyed as well
    d["animation"]["tracks"].append({"target": "meshes[band 0].nodes", "keys": [[0, "rest"]]})
    with pytest.raises(AnimationError, match=r"'band 0' is already moved by track meshes\[body\]"):
        evaluate(d)


@pytest.fixture(scope="module", autouse=True)
def _release_the_process_renderer() -> Iterator[None]:
    yield
    voxwarp.animation.frames.release_process_renderer()


def test_voxwarp_animate_renders_the_bundled_scene(tmp_path: Path, gl_ctx: Any) -> None:
    size = (64, 64)
    result = animate(
        BUNDLED, tmp_path / "acc.mp4", frames=3, size=size, movie=False, progress=False
    )
    images = [read_image(p) for p in result.frames]
    assert len(images) == 3
    assert not np.array_equal(images[0], images[1])
    # rendered frame 1 of 3 is animation frame 12: the body bent the other way, exactly
    # the static scene of that pose seen through the held camera
    camera = Scene.from_dict(evaluate(json.loads(BUNDLED.read_text())).scenes[12]).camera
    static = accessories(-1.2).copy(camera=camera)
    with OffscreenRenderer(*size, ctx=gl_ctx) as r:
        direct = r.render(static)
    np.testing.assert_array_equal(images[1], direct)
