"""A harness of notebook Viewer events of every kind and size (issue 33): seeded random
batches of pointer, wheel, key and resize events with ordinary, huge, tiny, negative,
non-finite and mistyped values. Oracle: no exception ever leaves ``handle_event`` and
the camera stays usable (finite, positive distance, magnification within the zoom
limits); bad ``size`` arguments are one-line errors."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from voxwarp.core.limits import MAX_ZOOM, MIN_ZOOM
from voxwarp.errors import VoxwarpError

SIZE = (96, 64)
KINDS = ("pointer_down", "pointer_move", "pointer_up", "wheel", "key_down", "resize", "other")
NUMBERS = (0.0, 1.0, -1.0, 37.5, 1e6, -1e6, 1e300, -1e300, 1e-300, math.nan, math.inf, -math.inf)
ODD = (None, "12", "x", [1, 2], {"a": 1}, True)
KEYS = ("ArrowLeft", "ArrowUp", "+", "-", "=", "r", "z", "y", " ", "F13", "", "é")
MODS = ((), ("Shift",), ("Control",), ("Control", "Shift"), ("Meta",))


def _value(rng: np.random.Generator) -> Any:
    if rng.random() < 0.85:
        return float(rng.choice(NUMBERS)) if rng.random() < 0.5 else float(rng.normal(0, 300))
    return ODD[int(rng.integers(len(ODD)))]


def _event(rng: np.random.Generator) -> dict:
    kind = str(rng.choice(KINDS))
    e: dict[str, Any] = {"type": kind, "x": _value(rng), "y": _value(rng)}
    e["button"] = int(rng.integers(0, 4))
    e["modifiers"] = MODS[int(rng.integers(len(MODS)))]
    e["dy"] = _value(rng)
    e["key"] = KEYS[int(rng.integers(len(KEYS)))]
    e["width"], e["height"], e["ratio"] = _value(rng), _value(rng), _value(rng)
    for name in list(e):
        if name != "type" and rng.random() < 0.1:
            del e[name]  # missing fields too
    return e


@pytest.fixture
def viewer(gl_ctx: Any) -> Iterator[Any]:
    from voxwarp import Scene, load_sample
    from voxwarp.notebook import Viewer

    scene = Scene(load_sample("fish", shape=(48, 24, 20)), view="+z", jitter=False)
    v = Viewer(scene, "massspring", size=SIZE, ctx=gl_ctx, resolution=4, anchor="corners")
    yield v
    v.release()


def _camera_ok(v: Any) -> None:
    cam = v.camera
    assert math.isfinite(cam.distance)
    assert cam.distance > 0
    assert math.isfinite(cam.ortho_height)
    assert cam.ortho_height > 0
    assert np.isfinite(cam.rotation).all()
    assert np.isfinite(cam.center).all()
    assert MIN_ZOOM * (1 - 1e-9) <= v.interaction.magnification <= MAX_ZOOM * (1 + 1e-9)
    w, h = v.size
    assert 1 <= w
    assert 1 <= h


@pytest.mark.timeout(60)
def test_random_event_batches_never_raise(viewer: Any) -> None:
    """600 events in seeded batches (a fixed seed: the same cases every run)."""
    rng = np.random.default_rng(20330)
    for _ in range(30):
        for _ in range(20):
            viewer.handle_event(_event(rng))
        _camera_ok(viewer)


@pytest.mark.timeout(30)
@pytest.mark.parametrize("dy", [-1e6, 1e6, -100.0])
def test_a_burst_of_wheel_events_stays_within_the_zoom_limits(viewer: Any, dy: float) -> None:
    """2000 wheel events in one batch used to shrink the distance to 0
    (ZeroDivisionError): the magnification now stops at MIN_ZOOM or MAX_ZOOM."""
    for _ in range(2000):
        viewer.handle_event({"type": "wheel", "x": 5, "y": 5, "dy": dy})
    _camera_ok(viewer)
    expected = MAX_ZOOM if dy < 0 else MIN_ZOOM
    assert viewer.interaction.magnification == pytest.approx(expected)
    viewer.handle_event({"type": "key_down", "key": "r", "modifiers": ()})
    assert viewer.interaction.magnification == 1.0


@pytest.mark.parametrize("size", ["640x480", (1, 2, 3), (10,), (math.nan, 5), (0, 5), None, 5])
def test_bad_sizes_are_one_line_errors(gl_ctx: Any, size: Any) -> None:
    from voxwarp.notebook import Viewer
    from voxwarp.notebook.interaction import view_size

    with pytest.raises(VoxwarpError, match=r"size must be \(width, height\)") as info:
        view_size(size)
    assert "\n" not in str(info.value)
    with pytest.raises(VoxwarpError, match=r"size must be"):
        Viewer(np.zeros((8, 8, 8), np.float32), size=size, ctx=gl_ctx)


def test_huge_sizes_are_capped() -> None:
    from voxwarp.notebook.interaction import MAX_VIEW_SIDE, view_size

    assert view_size((1e12, 10.4)) == (MAX_VIEW_SIDE, 10)
    assert view_size([640, 480]) == (640, 480)
