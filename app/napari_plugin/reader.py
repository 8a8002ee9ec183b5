"""The napari reader: voxwarp scene JSON, NRRD, NIfTI and DICOM folders.

:func:`get_reader` is the npe2 ``napari_get_reader`` command. It answers quickly and
never raises for files that are not its own: a JSON that is not a voxwarp scene, a
folder without DICOM files and anything else give ``None``, so napari asks the next
reader. Volumes become Image layers through
:func:`voxwarp.napari_plugin.convert.volume_to_layer_data` (zyx data, spacing as
``scale``, the patient-space affine of oblique scans). A scene with warps adds its
deformed view, rendered headless, as an RGB layer. A 4-D or multi-channel file gives a
layer per channel, its time points on the leading axis (napari's time slider).
"""

from __future__ import annotations

import itertools
import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from voxwarp.core.json_input import read_json
from voxwarp.errors import VoxwarpError
from voxwarp.io.frames import FrameChoiceError
from voxwarp.io.volumes import load_volume
from voxwarp.napari_plugin import deformed_view
from voxwarp.napari_plugin.convert import LayerData, volume_to_layer_data
from voxwarp.napari_plugin.frames import frame_layers
from voxwarp.scene import SCENE_FORMAT, SCENE_KEYS, Scene

ReaderFunction = Callable[[Any], list[LayerData]]
#: Extensions read as volumes (napari's builtins do not read these).
VOLUME_SUFFIXES: tuple[str, ...] = (".nrrd", ".nhdr", ".nii", ".nii.gz")
#: Bytes of a JSON file looked at for the scene marker before parsing it whole.
_HEAD_BYTES = 1 << 16
#: A JSON without the marker in its head is parsed whole only up to this size.
_PARSE_LIMIT = 1 << 20
#: Files of a folder looked at for the DICOM preamble.
_DICOM_PROBES = 8


def get_reader(path: str | list[str]) -> ReaderFunction | None:
    """A reader function for ``path`` if it is a voxwarp scene JSON, a NRRD or NIfTI
    volume or a folder of DICOM files; ``None`` otherwise (never raises)."""
    if isinstance(path, list):
        if len(path) != 1:
            return None
        path = path[0]
    try:
        p = Path(path)
        if p.is_dir():
            return read_volume if is_dicom_folder(p) else None
        name = p.name.lower()
        if name.endswith(".json"):
            return read_scene if is_scene_file(p) else None
        return read_volume if name.endswith(VOLUME_SUFFIXES) else None
    except (OSError, ValueError):
        return None


def is_scene_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` holds a voxwarp scene: ``"format": "voxwarp-scene"`` (what
    :meth:`~voxwarp.scene.Scene.save` writes first), or a small JSON object of scene
    keys only with a ``volume`` entry (scene JSON written by hand)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
        if f'"{SCENE_FORMAT}"'.encode() in head:
            return True
        if os.path.getsize(path) > _PARSE_LIMIT or not head.lstrip().startswith(b"{"):
            return False
        d = read_json(path)
    except (OSError, ValueError):
        return False
    if not isinstance(d, dict) or "volume" not in d:
        return False
    return d.get("format", SCENE_FORMAT) == SCENE_FORMAT and all(k in SCENE_KEYS for k in d)


def is_dicom_folder(path: Path) -> bool:
    """Whether one of the first files of folder ``path`` (in the order the file system
    lists them: no sorting, so a folder of many files answers fast) carries the DICOM
    preamble."""
    with os.scandir(path) as entries:
        files = (e for e in entries if e.is_file())
        for entry in itertools.islice(files, _DICOM_PROBES):
            with open(entry.path, "rb") as fh:
                if fh.read(132)[128:132] == b"DICM":
                    return True
    return False


def read_volume(path: str | list[str]) -> list[LayerData]:
    """One Image layer of the volume at ``path`` (NRRD, NIfTI or a DICOM folder); of a
    4-D/multi-channel file, a layer per channel with its time points stacked
    (:func:`voxwarp.napari_plugin.frames.frame_layers`)."""
    path = path[0] if isinstance(path, list) else path
    try:
        volume = load_volume(path)
    except FrameChoiceError as exc:  # a time series, or channels: every one, as napari does
        return frame_layers(path, exc)
    return [volume_to_layer_data(volume, metadata={"path": str(path)})]


def read_scene(path: str | list[str]) -> list[LayerData]:
    """The scene's volume as an Image layer (its window as contrast limits, the scene's
    transfer function and mode in ``metadata``), and for a scene with warps the
    deformed view as an RGB layer."""
    path = path[0] if isinstance(path, list) else path
    scene = Scene.load(path)
    level, width = scene.window
    info = {
        "path": str(path),
        "mode": scene.mode,
        "transfer_function": scene.transfer_function.to_dict(),
    }
    layers = [volume_to_layer_data(scene.volume, window=(level, width), metadata=info)]
    if scene.warps:
        image = _deformed_view(scene)
        if image is not None:
            meta = {"voxwarp": {"path": str(path), "render": "deformed view"}}
            name = f"{scene.volume.name} (voxwarp deformed view)"
            layers.append((image, {"name": name, "rgb": True, "metadata": meta}, "image"))
    return layers


def _deformed_view(scene: Any) -> Any:
    """The scene rendered headless on a thread of its own (its EGL context never meets
    the Qt GL context of napari's thread), or ``None`` with a warning when rendering
    fails (no OpenGL here): the volume layer still opens."""
    from concurrent.futures import ThreadPoolExecutor

    try:
        with ThreadPoolExecutor(1, thread_name_prefix="voxwarp-render") as pool:
            return pool.submit(deformed_view.render_rgb, scene).result()
    except (VoxwarpError, RuntimeError, OSError) as exc:
        warnings.warn(f"voxwarp: the deformed view was not rendered: {exc}", stacklevel=2)
        return None
