"""Hand a napari layer to the voxwarp window in its own process (no Qt here).

:func:`write_handoff` saves the layer's volume as NRRD and a scene JSON beside it
(window, transfer function and mode from the layer's display), both atomically, in a
new temporary folder that outlives napari's session (the voxwarp window reads it).
:func:`launch_voxwarp` starts ``python -m voxwarp gui SCENE`` without a shell.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from voxwarp.core.volume import Volume
from voxwarp.io.volumes import save_volume
from voxwarp.scene import Scene

#: Prefix of the temporary folders handed to voxwarp.
FOLDER_PREFIX = "voxwarp-napari-"


def write_handoff(
    volume: Volume, scene_options: dict[str, Any], folder: str | os.PathLike | None = None
) -> Path:
    """Write ``volume`` (``<name>.nrrd``) and ``scene.json`` into ``folder`` (default a new
    temporary folder); returns the scene path. ``scene_options`` are
    :class:`~voxwarp.scene.Scene` arguments (e.g.
    :func:`voxwarp.napari_plugin.convert.layer_scene_options`)."""
    out = Path(folder) if folder is not None else Path(tempfile.mkdtemp(prefix=FOLDER_PREFIX))
    out.mkdir(parents=True, exist_ok=True)
    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in volume.name) or "volume"
    written = save_volume(volume, out / f"{stem}.nrrd")
    saved = dataclasses.replace(volume, source=str(written))
    return Scene(saved, **scene_options).save(out / "scene.json")


def voxwarp_command(scene_path: str | os.PathLike) -> list[str]:
    """The command line that opens ``scene_path`` in the voxwarp window."""
    return [sys.executable, "-m", "voxwarp", "gui", str(scene_path)]


def launch_voxwarp(scene_path: str | os.PathLike) -> subprocess.Popen:
    """Start the voxwarp window on ``scene_path`` in its own process and session (it
    stays open when napari quits); its output goes to ``voxwarp.log`` beside the scene."""
    log_path = Path(scene_path).with_name("voxwarp.log")
    with open(log_path, "ab") as log:
        return subprocess.Popen(
            voxwarp_command(scene_path),
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
