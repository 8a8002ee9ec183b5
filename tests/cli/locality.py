"""How local an element-model drag is on a head: the push at the face front against the
change at the back of the head, in sagittal slices (``voxwarp slice``).

:func:`thirds_change` pushes the most anterior point of the head (mid-sagittal plane,
middle of its height) 15 mm posteriorly and returns the mean |deformed - rest| grey of
the head's anterior (near) and posterior (far) thirds along y (RAS: +y anterior).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tests.cli.test_cli import run_cli
from voxwarp.io.images import read_image

PUSH_MM = 15.0


def _grey(path: Path) -> np.ndarray:
    return read_image(path)[..., :3].astype(np.float64).mean(axis=-1)


def _slice(sample: str, out: Path, *args: str) -> dict:
    proc = run_cli("slice", sample, "--plane", "sagittal", "--json", "-o", str(out), *args)
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    info["stderr"] = proc.stderr
    return info


def face_point(rest: np.ndarray, info: dict) -> tuple[np.ndarray, float, float]:
    """The world point of the face front (most anterior head pixel, middle half of the
    head's height) and the head's y extent (min, max), from the rest slice."""
    m = np.asarray(info["pixel_to_world"])
    rows, cols = np.nonzero(rest > 0.25 * rest.max())
    pix = np.stack([cols, rows, np.zeros_like(rows), np.ones_like(rows)]).astype(np.float64)
    world = (m @ pix)[:3].T
    z0, z1 = np.percentile(world[:, 2], [25, 75])
    band = world[(world[:, 2] >= z0) & (world[:, 2] <= z1)]
    front = band[np.argmax(band[:, 1])]
    return front, float(world[:, 1].min()), float(world[:, 1].max())


def thirds_change(sample: str, tmp: Path, *model: str) -> tuple[float, float, str]:
    """(near, far, stderr): mean |difference| of the near and far thirds of the head."""
    rest_info = _slice(sample, tmp / "rest.png", "--show", "rest")
    rest = _grey(tmp / "rest.png")
    front, y0, y1 = face_point(rest, rest_info)
    point = ",".join(f"{v:g}" for v in front)
    drag = ("--drag-at", f"{point}:0,-{PUSH_MM:g},0")
    info = _slice(sample, tmp / "def.png", *model, *drag)
    deformed = _grey(tmp / "def.png")
    # the rest state on the same plane and extent (a grid margin grows the deformed box)
    same = _slice(sample, tmp / "rest_same.png", *model, *drag, "--show", "rest")
    assert same["pixel_to_world"] == info["pixel_to_world"]
    rest = _grey(tmp / "rest_same.png")
    assert deformed.shape == rest.shape
    m = np.asarray(info["pixel_to_world"])
    rows, cols = np.indices(rest.shape)
    pix = np.stack([cols.ravel(), rows.ravel(), 0 * rows.ravel(), 1 + 0 * rows.ravel()])
    y = (m @ pix.astype(np.float64))[1].reshape(rest.shape)
    head = (rest > 0.1 * rest.max()) | (deformed > 0.1 * rest.max())
    diff = np.abs(deformed - rest)
    third = (y1 - y0) / 3
    near = float(diff[head & (y > y1 - third)].mean())
    far = float(diff[head & (y < y0 + third)].mean())
    return near, far, info["stderr"]
