"""voxwarp's deformed view of a volume as an RGB image for napari (no Qt).

:func:`deformation_warps` builds the warps of one of :data:`DEFORMATIONS` through
voxwarp's public models; :func:`render_rgb` draws a scene headless
(:class:`~voxwarp.render.offscreen.OffscreenRenderer` on the pooled EGL context) and
returns ``(height, width, 3)`` uint8 for ``viewer.add_image(image, rgb=True)``.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from voxwarp.core.volume import Volume
from voxwarp.editing.model_settings import Drag, MassSpringSettings, SettleRule
from voxwarp.errors import SceneError
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

#: What "Render deformed view" can apply: nothing, a mass-spring push through the
#: volume's centre, or the warps of a scene JSON the user picks.
DEFORMATIONS: tuple[str, ...] = ("mass-spring push", "none", "scene file")
#: Elements per axis of the push's mass-spring grid (odd: a block at the centre).
PUSH_GRID = 7
#: How far the centre block is pushed, as a fraction of the volume's extent that way.
PUSH_FRACTION = 0.2
#: Most mass-spring steps the push takes to settle (settled: the model builder's rule,
#: :func:`voxwarp.editing.model_settings.is_settled`).
PUSH_MAX_STEPS = 2000
#: The pixel size of the rendered view (square), the widget's default.
DEFAULT_SIZE = 256


def push_warps(
    volume: Volume, direction: Any = (0.0, 0.0, 1.0), fraction: float = PUSH_FRACTION
) -> list[Any]:
    """A mass-spring push: the grid's central 3x3x3 elements moved along world
    ``direction`` by ``fraction`` of the volume's extent that way, the rest settled by
    the springs (the eight corners fixed). Moving a block, not one element, keeps the
    material ahead of it from folding (one element pushed past its neighbour would)."""
    # the mass-spring family loads scipy: only a push needs it
    from voxwarp.editing.families.elements import MassSpringFamily

    unit = np.asarray(direction, dtype=np.float64).reshape(3)
    length = float(np.linalg.norm(unit))
    if not (np.isfinite(length) and length > 0):
        raise SceneError(f"the push direction must be a non-zero vector; got {direction!r}")
    unit = unit / length
    extent = float(np.abs(unit) @ np.asarray(volume.size_mm))
    block = np.zeros((PUSH_GRID,) * 3, dtype=bool)
    middle = slice(PUSH_GRID // 2 - 1, PUSH_GRID // 2 + 2)
    block[middle, middle, middle] = True
    settings = MassSpringSettings(
        shape=(PUSH_GRID,) * 3,
        anchor="corners",  # the demo's set-up, as documented: the block moves freely
        integrator="semi-implicit",
        shear=True,
        drags=(Drag(block, tuple(fraction * extent * unit)),),
        run=SettleRule(settle=True, steps=PUSH_MAX_STEPS),
    )
    return [MassSpringFamily.build(settings, volume).warp]


def scene_file_warps(path: str | os.PathLike, volume: Volume) -> list[Any]:
    """The warp chain of the scene JSON at ``path``, bound to ``volume`` (warps live in
    world mm: they act where they were made, so they fit a volume in the same world
    space). The scene's own volume is loaded too (its warps are read against it)."""
    warps = list(Scene.load(path).warps)
    if not warps:
        raise SceneError(f"{path} has no warps; pick a scene saved with a deformation")
    for w in warps:
        w.bind_volume(volume)
    return warps


def deformation_warps(
    kind: str,
    volume: Volume,
    scene_path: str | os.PathLike | None = None,
    direction: Any = (0.0, 0.0, 1.0),
) -> list[Any]:
    """The warps of deformation ``kind`` (one of :data:`DEFORMATIONS`) for ``volume``;
    ``direction`` (world) is where the mass-spring push goes."""
    check_deformation(kind, scene_path)
    if kind == "none":
        return []
    if kind == "mass-spring push":
        return push_warps(volume, direction)
    return scene_file_warps(scene_path, volume)  # type: ignore[arg-type]


def check_deformation(kind: str, scene_path: str | os.PathLike | None = None) -> None:
    """Raise :class:`SceneError` (one line) unless ``kind`` is one of
    :data:`DEFORMATIONS` with what it needs (a scene JSON for ``"scene file"``)."""
    if kind not in DEFORMATIONS:
        raise SceneError(f"deformation must be one of {', '.join(DEFORMATIONS)}; got {kind!r}")
    if kind == "scene file" and not scene_path:
        raise SceneError("deformation 'scene file' needs a scene JSON: pick one")


def deformed_scene(
    volume: Volume,
    options: dict[str, Any],
    kind: str,
    scene_path: str | os.PathLike | None = None,
) -> Any:
    """A :class:`~voxwarp.scene.Scene` of ``volume`` with ``options`` and deformation
    ``kind``; the push goes up the screen of the scene's camera, so it shows."""
    scene = Scene(volume, **options)
    up = scene.resolved_camera().rotation[:, 1]
    return scene.copy(warps=deformation_warps(kind, volume, scene_path, up))


def render_rgb(scene: Any, size: int = DEFAULT_SIZE) -> np.ndarray:
    """``scene`` rendered headless to a ``(size, size, 3)`` uint8 image (row 0 = top)."""
    with OffscreenRenderer(int(size), int(size)) as renderer:
        image = renderer.render(scene)
    return np.ascontiguousarray(np.asarray(image)[..., :3])
