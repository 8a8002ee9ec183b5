"""Hand a napari layer to the voxwarp window in its own process (no Qt here).

:func:`write_handoff` saves the layer's volume as NRRD and a scene JSON beside it
(window, transfer function and mode from the layer's display), both atomically, in a
new temporary folder that outlives napari's session (the voxwarp window reads it).
:func:`launch_voxwarp` starts ``python -m voxwarp gui SCENE`` without a shell.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from voxwarp.core.files import output_error
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
    :func:`voxwarp.napari_plugin.convert.layer_scene_options`).

    Each file is written atomically; when either fails (a full or read-only disk: a
    one-line :class:`~voxwarp.errors.OutputError`) nothing of this hand-off is left: the
    new temporary folder is removed, and in a given ``folder`` a volume file this call
    created is removed (files that were there keep their content or this call's)."""
    made = folder is None
    where = Path(tempfile.gettempdir() if folder is None else folder)
    try:
        out = Path(tempfile.mkdtemp(prefix=FOLDER_PREFIX)) if folder is None else where
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise output_error(where, exc) from exc
    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in volume.name) or "volume"
    target = out / f"{stem}.nrrd"
    new_volume = not target.exists()
    try:
        written = save_volume(volume, target)
        saved = dataclasses.replace(volume, source=str(written))
        return Scene(saved, **scene_options).save(out / "scene.json")
    except BaseException:
        if made:
            shutil.rmtree(out, ignore_errors=True)
        elif new_volume:
            target.unlink(missing_ok=True)
        raise


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
