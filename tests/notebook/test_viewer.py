"""The notebook Viewer driven without a browser: jupyter_rfb event dicts in, frames out."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from voxwarp.editing.common import DisplayOptions
from voxwarp.errors import VolumeError

SIZE = (160, 120)
NO_OVERLAY = DisplayOptions(
    elements=False, links=False, fixed=False, grid_box=False, selection=False,
    wires_base=False, wires_modified=False, lattice_cells=False,
)  # fmt: skip


def _ev(kind: str, x: float = 0.0, y: float = 0.0, **more: Any) -> dict:
    """An event as jupyter_rfb sends it (new and old style keys, as compat mode 3)."""
    e = {"type": kind, "event_type": kind, "x": x, "y": y, "button": 1, "buttons": (1,)}
    e.update(modifiers=(), timestamp=0.0, time_stamp=0.0, **more)
    return e


def _scene() -> Any:
    from voxwarp import Scene, load_sample

    vol = load_sample("fish", shape=(96, 48, 40))
    return Scene(vol, view="+z", projection="orthographic", transfer_function="ct-soft",
        jitter=False, zoom=1.6)  # fmt: skip


@pytest.fixture
def viewer(gl_ctx: Any) -> Iterator[Any]:
    from voxwarp.notebook import Viewer

    v = Viewer(_scene(), "massspring", size=SIZE, ctx=gl_ctx, resolution=6, anchor="corners")
    v.handle_event({"type": "resize", "width": SIZE[0], "height": SIZE[1], "ratio": 1.0})
    yield v
    v.release()


def _volume_only(v: Any) -> np.ndarray:
    options, v.display_options = v.display_options, NO_OVERLAY
    try:
        return np.asarray(v.snapshot()).astype(np.int16)
    finally:
        v.display_options = options


def test_frame_is_the_scene_with_handles(viewer: Any) -> None:
    frame = viewer.get_frame()
    assert frame.dtype == np.uint8
    assert frame.ndim == 3
    assert frame.shape[2] == 4
    full = viewer.snapshot()
    assert full.shape == (SIZE[1], SIZE[0], 4)
    plain = _volume_only(viewer)
    # the handles are drawn where they project: the pixel under a handle differs
    x, y = viewer.handle_pixels()[_movable_handle(viewer)]  # in view (grid margin "auto")
    assert 0 <= x < SIZE[0]
    assert 0 <= y < SIZE[1]
    assert np.any(full[int(y), int(x), :3] != plain[int(y), int(x), :3])


def test_orbit_by_pointer_changes_camera_and_image(viewer: Any) -> None:
    before_rot = viewer.camera.rotation.copy()
    before = _volume_only(viewer)
    corner = (3.0, 3.0)  # no handle here: the press orbits
    assert viewer.handle_event(_ev("pointer_down", *corner))
    assert viewer.handle_event(_ev("pointer_move", 43.0, 13.0))
    assert viewer.handle_event(_ev("pointer_up", 43.0, 13.0, buttons=()))
    assert not np.allclose(viewer.camera.rotation, before_rot)
    after = _volume_only(viewer)
    assert _changed_pixels(after, before) > 300
    assert viewer.session.selection == []  # orbiting selects nothing


def _changed_pixels(a: np.ndarray, b: np.ndarray, by: int = 10) -> int:
    return int((np.abs(a - b)[..., :3].max(axis=-1) > by).sum())


def test_wheel_zooms_in(viewer: Any) -> None:
    before = _volume_only(viewer)
    d0 = viewer.camera.ortho_height
    assert viewer.handle_event(_ev("wheel", 80, 60, dx=0.0, dy=-200.0))
    assert viewer.camera.ortho_height == pytest.approx(d0 / 1.15**2)
    after = _volume_only(viewer)
    lit = lambda img: int((img[..., :3].max(axis=-1) > 20).sum())  # noqa: E731
    assert lit(after) > 1.2 * lit(before)  # the fish covers more of the view


def _movable_handle(v: Any) -> int:
    """A free element near the middle of the grid (front layer, so pick finds it; the
    viewers here fix the corners only, the thesis's set-up)."""
    grid = v.session.model.grid
    i, j = grid.shape[0] // 2, grid.shape[1] // 2
    k = grid.shape[2] - 1  # +z view: the top layer is nearest the eye
    return int(np.ravel_multi_index((i, j, k), grid.shape))


def test_pick_and_drag_moves_element_and_undo_restores(viewer: Any) -> None:
    s = viewer.session
    h = _movable_handle(viewer)
    start = viewer.handle_pixels()[h]
    end = start + np.array([0.0, -25.0])  # 25 px up the screen
    rest = s.handles()[h].copy()
    before_img = _volume_only(viewer)
    before_state = s.snapshot()
    cam, size = viewer.camera, viewer.size
    expected = cam.point_on_view_plane(end, size, rest) - cam.point_on_view_plane(start, size, rest)

    assert viewer.handle_event(_ev("pointer_down", *start))
    assert s.dragging
    assert s.reference == h
    for t in (0.3, 0.6, 1.0):
        viewer.handle_event(_ev("pointer_move", *(start + (end - start) * t)))
        viewer.get_frame()  # the model advances a frame per frame drawn while dragging
    assert viewer.handle_event(_ev("pointer_up", *end, buttons=()))
    viewer.step(30)
    moved = s.handles()[h] - rest
    assert np.allclose(moved, expected, atol=1e-4)  # held where it was dragged
    assert np.linalg.norm(expected) > 5.0
    grid = s.model.grid
    ijk = np.add(np.unravel_index(h, grid.shape), (1, 0, 0))
    neighbour = np.ravel_multi_index(tuple(ijk), grid.shape)
    pulled = s.handles()[neighbour] - grid.rest_positions.reshape(-1, 3)[neighbour]
    assert pulled @ expected > 0.1 * expected @ expected  # springs pull it along

    after_img = _volume_only(viewer)
    y0, y1 = int(min(start[1], end[1])) - 8, int(max(start[1], end[1])) + 8
    x0, x1 = int(start[0]) - 12, int(start[0]) + 12
    window = (slice(max(0, y0), y1), slice(max(0, x0), x1))
    assert _changed_pixels(after_img[window], before_img[window]) > 40

    assert viewer.interaction.undo_texts == ["Drag"]
    assert viewer.undo()
    assert s.snapshot().same_as(before_state)
    assert np.array_equal(_volume_only(viewer), before_img)
    assert viewer.redo()
    assert np.allclose(s.handles()[h] - rest, expected, atol=1e-4)


def test_scripted_drag_and_pick(viewer: Any) -> None:
    h = _movable_handle(viewer)
    x, y = viewer.handle_pixels()[h]
    assert viewer.pick(x, y) == h
    assert viewer.session.selection == [h]
    assert viewer.pick(2.0, 2.0) is None  # nothing there
    assert viewer.drag((2.0, 2.0), (30.0, 30.0)) is None  # no handle: no drag, no edit
    assert viewer.interaction.undo_texts == []
    assert viewer.drag((x, y), (x + 20, y)) == h
    assert viewer.interaction.undo_texts == ["Drag"]


@pytest.mark.parametrize(
    "event",
    [
        None,
        "pointer_down",
        {},
        {"type": 3},
        {"type": "no_such_event", "x": 1, "y": 2},
        {"type": "pointer_down"},  # no position
        {"type": "pointer_down", "x": "left", "y": 2},
        {"type": "pointer_down", "x": float("nan"), "y": 2},
        {"type": "wheel", "x": 1, "y": 1},  # no dy
        {"type": "resize", "width": -5, "height": 10},
        {"type": "key_down", "key": "F13", "modifiers": ()},
        {"type": "pointer_move", "x": 5, "y": 5},  # no button down
    ],
)
def test_invalid_event_is_ignored(viewer: Any, event: Any) -> None:
    cam = viewer.camera.rotation.copy(), viewer.camera.ortho_height
    state = viewer.session.snapshot()
    assert viewer.handle_event(event) is False
    assert np.array_equal(viewer.camera.rotation, cam[0])
    assert viewer.camera.ortho_height == cam[1]
    assert viewer.session.snapshot().same_as(state)
    assert viewer.size == SIZE


def test_keys_and_resize(viewer: Any) -> None:
    rot = viewer.camera.rotation.copy()
    assert viewer.handle_event({"type": "key_down", "key": "ArrowLeft", "modifiers": ()})
    assert not np.allclose(viewer.camera.rotation, rot)
    assert viewer.handle_event({"type": "key_down", "key": "r", "modifiers": ()})
    assert np.allclose(viewer.camera.rotation, rot)
    assert viewer.handle_event({"type": "key_down", "key": " ", "modifiers": ()})
    assert viewer.running is False
    assert viewer.handle_event({"type": "resize", "width": 100, "height": 80, "ratio": 2.0})
    assert viewer.snapshot().shape == (160, 200, 4)  # device pixels


def test_chainmail_from_sample_input(gl_ctx: Any) -> None:
    from voxwarp.notebook import Viewer

    v = Viewer(
        "sample:fish",
        "chainmail",
        size=(96, 72),
        ctx=gl_ctx,
        resolution=4,
        stiffness=0.8,
        anchor="corners",
    )
    try:
        assert v.session.kind == "chainmail"
        grid = v.session.model.grid
        h = int(np.ravel_multi_index((2, 1, 2), grid.shape))
        rest = v.session.handles()[h].copy()
        x, y = v.handle_pixels()[h]
        assert v.drag((x, y), (x + 10, y)) == h
        moved = v.session.handles() - grid.rest_positions.reshape(-1, 3)
        assert moved[h, 0] > 5.0  # +x on screen is +x in the world here (view from -y)
        assert np.linalg.norm(moved, axis=1).astype(bool).sum() > 1  # links pull others
        assert v.undo()
        assert np.allclose(v.session.handles()[h], rest)
    finally:
        v.release()


def test_gpu_backend_drag_and_undo(gl_ctx: Any) -> None:
    from voxwarp.notebook import Viewer

    v = Viewer(
        _scene(), "massspring", size=SIZE, ctx=gl_ctx, resolution=5, backend="gpu", anchor="corners"
    )
    try:
        assert v.session.model.backend == "gpu"
        grid = v.session.model.grid
        h = int(np.ravel_multi_index((3, 2, grid.shape[2] - 1), grid.shape))
        rest = v.session.handles()[h].copy()
        x, y = v.handle_pixels()[h]
        assert v.drag((x, y), (x, y - 20)) == h
        v.step(10)
        assert np.linalg.norm(v.session.handles()[h] - rest) > 5.0
        assert v.undo()
        assert np.allclose(v.session.handles()[h], rest)
    finally:
        v.close()
        v.close()  # idempotent


def test_bad_sources_are_refused_in_one_line(gl_ctx: Any) -> None:
    from voxwarp.editing.session import EditorError
    from voxwarp.notebook import Viewer

    with pytest.raises(EditorError, match="Viewer takes a Scene"):
        Viewer(42, ctx=gl_ctx)
    with pytest.raises(EditorError, match="need a deformation"):
        Viewer(_scene(), ctx=gl_ctx, resolution=4)
    with pytest.raises(EditorError, match="deformation"):
        Viewer(_scene(), "origami", ctx=gl_ctx)
    with pytest.raises(VolumeError):  # a 2D array: load_volume's one line
        Viewer(np.zeros((8, 8), np.float32), ctx=gl_ctx)


def test_a_3d_array_is_a_volume_of_1_mm_voxels() -> None:
    from voxwarp.notebook import session_for

    session = session_for(np.arange(6 * 5 * 4, dtype=np.float32).reshape(6, 5, 4))
    assert session.scene.volume.shape == (6, 5, 4)
    assert tuple(session.scene.volume.spacing) == (1.0, 1.0, 1.0)


def test_a_nibabel_image_keeps_its_geometry() -> None:
    nib = pytest.importorskip("nibabel")
    from voxwarp.notebook import session_for

    affine = np.diag([-2.0, 1.5, 1.0, 1.0])  # LAS: stored flipped to RAS
    img = nib.Nifti1Image(np.arange(120, dtype=np.float32).reshape(6, 5, 4), affine)
    volume = session_for(img).scene.volume
    assert volume.source == "nibabel image"
    assert tuple(volume.spacing) == (2.0, 1.5, 1.0)
    assert volume.file_axes == "LAS"


def test_scene_is_copied_and_a_saved_session_resumes(gl_ctx: Any, tmp_path: Any) -> None:
    from voxwarp.notebook import Viewer

    scene = _scene()
    v = Viewer(scene, "massspring", size=SIZE, ctx=gl_ctx, resolution=4)
    try:
        assert scene.warps == []  # the caller's scene is not edited
        assert len(v.session.scene.warps) == 1
        g = v.session.model.grid
        h = int(np.ravel_multi_index((2, 1, g.shape[2] - 1), g.shape))
        x, y = v.handle_pixels()[h]
        assert v.drag((x, y), (x + 15, y)) == h
        path = v.session.save(tmp_path / "edited.json")
        positions = v.session.model.positions()
    finally:
        v.release()
    v = Viewer(str(path), size=SIZE, ctx=gl_ctx)  # a scene JSON, as `voxwarp gui` opens it
    try:
        assert v.session.kind == "massspring"  # its model resumes, drags and all
        assert np.allclose(v.session.model.positions(), positions)
    finally:
        v.release()


def test_own_context_serves_calls_from_any_thread(gl_ctx: Any) -> None:
    """JupyterLab (ipykernel 7) sends widget messages on a subshell thread while cells run
    on the main thread: a viewer with its own context renders on a thread of its own, so
    both work (an EGL context is current in one thread only)."""
    import threading

    from voxwarp.notebook import Viewer

    # its own context; margin 0: no grid corner lies under the pressed pixel (2, 2)
    v = Viewer(_scene(), "massspring", size=(96, 64), resolution=4, margin=0.0)
    try:
        out: dict[str, Any] = {}

        def browser() -> None:  # what a subshell thread does with the widget
            try:
                v.handle_event({"type": "resize", "width": 96, "height": 64, "ratio": 1.0})
                v.handle_event(_ev("pointer_down", 2.0, 2.0))
                v.handle_event(_ev("pointer_move", 30.0, 2.0))
                v.handle_event(_ev("pointer_up", 30.0, 2.0, buttons=()))
                out["frame"] = v.get_frame()
            except Exception as exc:  # reported below, in the test's thread
                out["error"] = exc

        before = v.snapshot()  # the main thread
        t = threading.Thread(target=browser, name="subshell")
        t.start()
        t.join(60)
        assert "error" not in out, out.get("error")
        assert out["frame"].shape[2] == 4
        after = np.asarray(v.snapshot(), np.int16)
        assert _changed_pixels(after, np.asarray(before, np.int16)) > 50  # the orbit took
    finally:
        v.close()


def test_fixed_image_compares_in_the_view(gl_ctx: Any) -> None:
    """Viewer(fixed=): the frame is the comparison; the image against itself as
    difference is the bare background (a transfer function transparent up to 100),
    set_fixed(None) brings the moving image back."""
    from voxwarp.core.transfer_function import TransferFunction
    from voxwarp.notebook import Viewer

    tf = TransferFunction([(0, 0, 0, 0, 0), (100, 1, 1, 1, 0), (400, 1, 1, 1, 1)])
    scene = _scene().copy(transfer_function=tf)
    v = Viewer(scene, size=SIZE, ctx=gl_ctx, fixed=scene.volume)
    try:
        assert v.session.scene.comparison is not None
        assert v.session.scene.comparison.show == "checkerboard"
        v.set_fixed(scene.volume, "difference")
        diff = np.asarray(v.snapshot(1.0))[..., :3].astype(int)
        v.set_fixed(None)
        assert v.session.scene.comparison is None
        moving = np.asarray(v.snapshot(1.0))[..., :3].astype(int)
        assert moving.max() > 60  # the fish shows
        assert diff.max() <= 2
    finally:
        v.release()


def test_jacobian_overlay_switch(viewer: Any) -> None:
    """``viewer.overlays = "jacobian"``: the model at rest has det J = 1, so the frame is
    unchanged but for the legend (bottom right); off again, the frame is back."""
    from voxwarp.errors import RenderError

    plain = _volume_only(viewer)
    viewer.overlays = "jacobian"
    assert viewer.overlays == ("jacobian",)
    tinted = _volume_only(viewer)
    legend = np.zeros(plain.shape[:2], bool)
    legend[-32:, -143:] = True
    np.testing.assert_array_equal(tinted[~legend], plain[~legend])
    assert np.any(tinted[legend] != plain[legend])
    viewer.overlays = ()
    assert viewer.overlays == ()
    np.testing.assert_array_equal(_volume_only(viewer), plain)
    viewer.overlays = "grid,jacobian"  # one switch for every overlay name
    assert viewer.overlays == ("jacobian", "grid")
    assert viewer.warp_lines.grid
    assert not viewer.warp_lines.glyphs
    viewer.overlays = ()
    assert not viewer.warp_lines.grid
    with pytest.raises(RenderError, match="choose from jacobian"):
        viewer.overlays = "bogus"


def test_interactive_frames_use_the_scenes_interaction_resolution(viewer: Any) -> None:
    """``interactive_downsample``: frames drawn while interacting sample the reduced
    volume (another picture), frames at rest the full one (the same as at level 1)."""
    from voxwarp.render.adaptive_quality import FULL

    viewer.display_options = NO_OVERLAY
    rest = np.asarray(viewer._draw(FULL, 1.0)).astype(np.int16)
    assert np.array_equal(np.asarray(viewer._draw(FULL, 1.0, interacting=True)), rest)
    viewer.session.scene.interactive_downsample = 4
    coarse = np.asarray(viewer._draw(FULL, 1.0, interacting=True)).astype(np.int16)
    assert _changed_pixels(coarse, rest) > 50
    assert np.array_equal(np.asarray(viewer._draw(FULL, 1.0)), rest)
