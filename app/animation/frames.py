"""Rendering animation frames in any process: one renderer, volume and warps kept per
process and reused from frame to frame (a Dask worker renders many frames with one EGL
context). Used by :mod:`voxwarp.animation.movie` (serial runs) and
:mod:`voxwarp.animation.distributed` (workers).

A frame's image must not depend on the frames drawn before it, so the renderer never
builds deformed-space skip maps (they are built on a second draw of a warp state, which
a worker may or may not have seen): serial and distributed runs give identical pixels.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp.core.files import output_error
from voxwarp.deform.warp import WarpError, warp_from_dict
from voxwarp.errors import SceneError, VoxwarpError
from voxwarp.io import images  # images.write_image: tests stand in for it
from voxwarp.render.offscreen import OffscreenRenderer
from voxwarp.scene import Scene

_STUB_VOLUME = {"embedded": {"dtype": "uint8", "shape": [1, 1, 1], "order": "F", "data": "AA=="}}


def canonical_json(obj: Any) -> str:
    """Compact JSON with sorted keys (the input of digests and cache keys)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


class _ProcessRenderer:
    """This process's renderer, volume and warps, reused from frame to frame."""

    def __init__(self) -> None:
        self.renderer: Any = None
        self.key: Any = None
        self.volume: Any = None
        self.volume_key: str | None = None
        self.warps: dict[str, Any] = {}

    def render(self, header: Mapping[str, Any], scene: Mapping[str, Any]) -> np.ndarray:
        w, h = (int(v) for v in header["size"])
        dtype = str(header.get("dtype", "u1"))
        if self.key != (w, h, dtype):
            self.release()
            self.renderer = OffscreenRenderer(w, h, dtype=dtype)
            # a frame's image must not depend on the frames drawn before (module doc)
            self.renderer.renderer.warped_skip_maps = "never"
            self.key = (w, h, dtype)
        base_dir = header.get("base_dir")
        volume_key = canonical_json({"volume": header["volume"], "base_dir": base_dir})
        if volume_key != self.volume_key:
            self._release_warps(list(self.warps.values()))
            self.warps = {}
            self.volume = None
            probe = {"volume": header["volume"], "transfer_function": {"points": [[0, 0, 0, 0, 0]]}}
            self.volume = Scene.from_dict(probe, base_dir=base_dir).volume
            self.volume_key = volume_key
        entries = scene.get("warps") or []
        if not isinstance(entries, list):
            raise SceneError("scene 'warps' must be a list of warp objects")
        keys = [canonical_json(e) for e in entries]
        warps: dict[str, Any] = {}
        try:
            for k, e in zip(keys, entries, strict=True):
                warp = self.warps.get(k) or warps.get(k)
                if warp is None:
                    warp = warp_from_dict(e)
                    warp.bind_volume(self.volume)
                warps[k] = warp
        except (WarpError, TypeError) as exc:
            raise SceneError(f"invalid warp in scene: {exc}") from exc
        self._release_warps([v for k, v in self.warps.items() if k not in warps])
        self.warps = warps
        stub = {k: v for k, v in scene.items() if k != "warps"}
        stub["volume"] = _STUB_VOLUME
        parsed = Scene.from_dict(stub, base_dir=base_dir)
        frame = parsed.copy(volume=self.volume, warps=[warps[k] for k in keys])
        return self.renderer.render(frame)

    def _release_warps(self, warps: Sequence[Any]) -> None:
        if not warps or self.renderer is None:
            return
        with self.renderer.current():  # their textures live in the renderer's context
            for w in warps:
                w.release()

    def release(self) -> None:
        self._release_warps(list(self.warps.values()))
        self.warps = {}
        self.volume = None
        self.volume_key = None
        if self.renderer is not None:
            self.renderer.release()
        self.renderer = None
        self.key = None


_PROCESS = _ProcessRenderer()
_PROCESS_LOCK = threading.Lock()


def render_frame(header: Mapping[str, Any], scene: Mapping[str, Any]) -> np.ndarray:
    """Render one frame with this process's renderer (made on first use and kept).

    Parameters
    ----------
    header
        :func:`render_header`: volume entry, base folder, size, dtype.
    scene
        The frame's scene dict (without ``"volume"``).

    Returns
    -------
    numpy.ndarray
        (H, W, 4) uint8 or float32 image, row 0 at the top.

    Notes
    -----
    Thread-safe: frames of one process are drawn one at a time (one GL context).
    """
    with _PROCESS_LOCK:
        return _PROCESS.render(header, scene)


def file_record(path: str | os.PathLike) -> tuple[int, str] | None:
    """``(size, SHA-256 hex)`` of a file's bytes, or None when it cannot be read."""
    h = hashlib.sha256()
    size = 0
    try:
        with open(path, "rb") as fh:
            while chunk := fh.read(1 << 20):
                h.update(chunk)
                size += len(chunk)
    except OSError:
        return None
    return size, h.hexdigest()


def render_frame_to_file(
    header: Mapping[str, Any], scene: Mapping[str, Any], path: str | os.PathLike
) -> dict[str, Any]:
    """Render one frame (:func:`render_frame`), write it atomically and check it.

    The written file is read back and compared with the rendered pixels, so a short
    write a library did not report never passes as a finished frame.

    Returns
    -------
    dict
        ``{"path", "size", "sha256"}`` of the file as written (what the manifest records).

    Raises
    ------
    OutputError
        When the frame cannot be written or does not read back as written (the file is
        removed).
    """
    image = render_frame(header, scene)
    images.write_image(path, image)
    record = file_record(path)
    try:
        back = images.read_image(path) if record is not None else None
    except VoxwarpError:
        back = None
    if back is None or back.dtype != image.dtype or not np.array_equal(back, image):
        try:
            os.unlink(path)
        except OSError:
            pass
        raise output_error(
            path, "the frame file does not read back as written (a short write: disk full?)"
        )
    assert record is not None
    return {"path": str(path), "size": record[0], "sha256": record[1]}


def release_process_renderer() -> None:
    """Free this process's renderer, volume and warps (the next frame makes new ones)."""
    with _PROCESS_LOCK:
        _PROCESS.release()
