"""Guided tours of the teaching demos: read a ``NAME_tour.json`` written by
:func:`voxwarp.teaching.sheets.write_tour` (the GUI steps through it; see ``ui/tour_panel.py``).

The file is JSON::

    {"format": "voxwarp-tour", "version": 1, "demo": NAME, "title": TITLE,
     "figure": "NAME.png",
     "steps": [{"title": ..., "text": ..., "scene": "NAME_tour/01.json" | null,
                "panel": "a" | null}, ...]}

Paths are relative to the tour file's folder.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from voxwarp.core.json_input import read_json
from voxwarp.core.scene_paths import scene_file
from voxwarp.errors import VoxwarpError

#: ``"format"`` of a tour file
TOUR_FORMAT = "voxwarp-tour"
#: newest tour version this voxwarp reads
TOUR_VERSION = 1


class TourError(VoxwarpError, ValueError):
    """A tour file that cannot be read (names the problem and the fix)."""


@dataclass(frozen=True)
class TourStep:
    """One step: what to say, and the scene to show (None: keep the current one)."""

    title: str
    text: str
    scene: Path | None
    panel: str | None


@dataclass(frozen=True)
class Tour:
    """A guided tour: its demo, title, figure sheet and steps."""

    path: Path
    demo: str
    title: str
    figure: Path | None
    steps: tuple[TourStep, ...]


def _text(d: dict[str, Any], key: str, where: str) -> str:
    v = d.get(key)
    if not isinstance(v, str) or not v.strip():
        raise TourError(f"{where}: '{key}' must be a non-empty string")
    return v


def read_tour(path: str | os.PathLike) -> Tour:
    """Read and check a tour file; raises :class:`TourError` naming what is wrong."""
    path = Path(path)
    try:
        d = read_json(path)
    except FileNotFoundError as exc:
        raise TourError(
            f"no such tour file: {path} (make one with voxwarp demo NAME --gui)"
        ) from exc
    except (OSError, ValueError) as exc:
        raise TourError(f"cannot read tour file {path}: {exc}") from exc
    if not isinstance(d, dict) or d.get("format") != TOUR_FORMAT:
        raise TourError(f"{path} is not a voxwarp tour (format must be {TOUR_FORMAT!r})")
    version = d.get("version", 1)
    if not isinstance(version, int) or version > TOUR_VERSION:
        raise TourError(
            f"{path}: tour version {version!r} is newer than this voxwarp reads"
            f" ({TOUR_VERSION}); upgrade voxwarp"
        )
    base = path.parent
    steps_raw = d.get("steps")
    if not isinstance(steps_raw, list) or not steps_raw:
        raise TourError(f"{path}: 'steps' must be a non-empty list")
    steps = []
    for i, s in enumerate(steps_raw, start=1):
        where = f"{path}, step {i}"
        if not isinstance(s, dict):
            raise TourError(f"{where}: a step must be an object")
        scene = s.get("scene")
        if scene is not None:
            if not isinstance(scene, str):
                raise TourError(f"{where}: 'scene' must be a path or null")
            scene_path = scene_file(
                scene, base, f"step {i} scene", TourError, noun="scene file", owner="tour"
            )
        panel = s.get("panel")
        steps.append(
            TourStep(
                _text(s, "title", where),
                _text(s, "text", where),
                None if scene is None else scene_path.resolve(),
                panel if isinstance(panel, str) else None,
            )
        )
    figure = d.get("figure")
    figure_path = None
    if isinstance(figure, str):
        figure_path = scene_file(
            figure, base, "figure", TourError, noun="image", must_exist=False, owner="tour"
        )
    return Tour(
        path=path,
        demo=str(d.get("demo", "")),
        title=_text(d, "title", str(path)),
        figure=figure_path if figure_path is not None and figure_path.is_file() else None,
        steps=tuple(steps),
    )
