"""Correct a registration by hand: a drag on top of an imported displacement field.

A registration result (an ITK displacement field or transform read with
:func:`voxwarp.io.fields.load_transform`) maps the fixed space, which the views show, to
the moving image. A correction is a deformation model (ChainMail, mass-spring, wire,
lattice) acting in that displayed space, so it comes *first* in the chain (deformed ->
original): ``[*correction, *registration]``. A drag of ``offset`` at ``point`` then
moves what is seen at ``point`` by ``offset``, whatever the field does there. The
composed chain is one pull-back map, written as one ITK field by
:meth:`voxwarp.scene.Scene.export_field` (``voxwarp export-field SCENE.json``).

Use::

    from voxwarp import load_transform, load_volume
    from voxwarp.editing.correction import corrected_scene, drag_correction

    moving = load_volume("moving.nii.gz")
    field = load_transform("warp.nii.gz")
    model = drag_correction(moving, point=(10, -20, 30), offset=(0, 3, 0))
    scene = corrected_scene(moving, field, [model.warp()])
    scene.save("corrected.json")  # then: voxwarp export-field corrected.json -o fix.h5

The GUI's editing session (:class:`~voxwarp.editing.session.EditSession`) keeps the same
order: its model's warp, then the imported warps.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from voxwarp.core.volume import Volume
from voxwarp.deform.warp import Warp
from voxwarp.editing import model_settings as ms
from voxwarp.errors import VoxwarpError
from voxwarp.scene import Scene

__all__ = ["CorrectionError", "corrected_scene", "correction_chain", "drag_correction"]

#: the element models :func:`drag_correction` builds
MODELS = ("chainmail", "massspring")


class CorrectionError(VoxwarpError, ValueError):
    """A correction that cannot be built (bad model name, point or offset)."""


def correction_chain(correction: Sequence[Warp], registration: Sequence[Warp]) -> list[Warp]:
    """The chain of a corrected registration, deformed -> original: the correction's
    warps (acting in the displayed, fixed space) then the registration's."""
    return [*correction, *registration]


def corrected_scene(
    moving: Volume | Scene, registration: Sequence[Warp], correction: Sequence[Warp]
) -> Scene:
    """A scene of the moving image (or a copy of a scene of it, its look kept) seen
    through ``registration`` corrected by ``correction`` (:func:`correction_chain`)."""
    chain = correction_chain(correction, registration)
    if isinstance(moving, Scene):
        return moving.copy(warps=chain)
    return Scene(moving, warps=chain)


def drag_correction(
    volume: Volume,
    point: Sequence[float],
    offset: Sequence[float],
    *,
    model: str = "chainmail",
    shape: int | Sequence[int] = 8,
    **settings: Any,
) -> Any:
    """A CPU ChainMail (or mass-spring) model over ``volume``'s box whose element
    nearest ``point`` (world mm, displayed space) is held ``offset`` mm from rest.

    The model's boundary conditions are its defaults (:mod:`voxwarp.deform.elements.anchors`:
    ChainMail's corners, mass-spring's anchored shell with its region of influence);
    ``settings`` overrides any field of :class:`~voxwarp.editing.model_settings.ChainMailSettings`
    or :class:`~voxwarp.editing.model_settings.MassSpringSettings` (``margin``,
    ``fix_outside``, ``stiffness``, ...). Returns the model: ``model.warp()`` goes in
    :func:`corrected_scene`. Mass-spring is settled before it is returned.
    """
    # loads scipy: only when used
    from voxwarp.editing.families.elements import ChainMailFamily, MassSpringFamily

    if model not in MODELS:
        raise CorrectionError(f"model must be one of {', '.join(MODELS)}; got {model!r}")
    p, d = (np.asarray(v, dtype=np.float64).reshape(-1) for v in (point, offset))
    if p.shape != (3,) or d.shape != (3,) or not (np.isfinite(p).all() and np.isfinite(d).all()):
        raise CorrectionError("point and offset must be 3 finite numbers each (world mm)")
    dims = (int(shape),) * 3 if np.isscalar(shape) else tuple(int(n) for n in shape)
    family = ChainMailFamily if model == "chainmail" else MassSpringFamily
    kind = ms.ChainMailSettings if model == "chainmail" else ms.MassSpringSettings
    if model == "massspring":
        settings.setdefault("run", ms.SettleRule(settle=True, steps=None))
    try:
        grid = family.grid(kind(shape=dims, **settings), volume)
        index = _nearest_free_element(grid, p)
        built = family.build_on(kind(shape=dims, drags=(ms.Drag(index, d),), **settings), grid)
    except ms.SettingError as exc:
        raise CorrectionError(f"{model} correction: {exc}") from exc
    return built.model


def _nearest_free_element(grid: Any, point: np.ndarray) -> tuple[int, int, int]:
    """Index of the element nearest ``point`` at rest that is not fixed."""
    rest = np.asarray(grid.rest_positions, dtype=np.float64).reshape(-1, 3)
    dist = np.linalg.norm(rest - point, axis=1)
    dist[np.asarray(grid.fixed).reshape(-1)] = np.inf
    if not np.isfinite(dist).any():
        raise CorrectionError("every element of the correction's grid is fixed; drag nothing")
    i, j, k = np.unravel_index(int(np.argmin(dist)), grid.shape)
    return int(i), int(j), int(k)
