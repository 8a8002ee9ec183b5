"""Keyframing an editing session: what the GUI's Set Key stores (the wire paper's
tool: deform the object differently at any number of frames, render the series).

:func:`set_key` records, at one frame, the state of the session's deformation and the
view as keys of an :class:`~voxwarp.animation.tracks.Animation`:

* ``camera``: the camera (interpolated by slerp);
* wires: ``wires[i].modified`` (the modified curve's control points) of every wire;
* lattice: ``lattice.nodes``;
* mass-spring / ChainMail: ``elements.drag``, the held elements and their offsets from
  rest (elements held at any key are the track's elements; at a key where one is not
  held its current displacement is keyed, so it stays where it is).

A key at a frame that already has one replaces it. :func:`delete_keys` removes the keys
of a frame. The session keeps its animation (:attr:`voxwarp.editing.session.EditSession.animation`)
and saves it in scene JSON, where ``voxwarp animate`` renders it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from voxwarp.animation.tracks import DEFAULT_FPS, Animation, AnimationError, Track
from voxwarp.core.camera import Camera

#: frames of a new animation
DEFAULT_FRAMES = 48


def json_values(a: Any) -> Any:
    """An array as nested lists of floats rounded to 1e-6 (key values in scene JSON)."""
    return np.asarray(a, dtype=np.float64).round(6).tolist()


def put_key(track: Track, frame: int, value: Any) -> None:
    """Set ``track``'s key at ``frame`` (replacing one there)."""
    keys = [(f, v) for f, v in track.keys if f != frame]
    keys.append((frame, value))
    track.keys = sorted(keys, key=lambda k: k[0])


def track(anim: Animation, target: str, interpolation: str) -> Track:
    """The track of ``target`` in ``anim`` (a new one with ``interpolation`` if none)."""
    for t in anim.tracks:
        if t.target == target:
            return t
    t = Track(target, [], interpolation)
    anim.tracks.append(t)
    return t


def set_key(
    animation: Animation | None,
    session: Any,
    frame: int,
    camera: Camera | None = None,
    *,
    frames: int | None = None,
    fps: float | None = None,
    interpolation: str = "smooth",
) -> Animation:
    """Key the session's deformation (and ``camera``) at ``frame``.

    Parameters
    ----------
    animation
        The animation to add to (copied), or None for a new one.
    session
        An :class:`~voxwarp.editing.session.EditSession`.
    frame
        The frame, 0 .. frames - 1.
    camera
        The view to key (None: the camera is not keyed).
    frames, fps
        Length and rate (None: the animation's, or :data:`DEFAULT_FRAMES` and
        :data:`~voxwarp.animation.tracks.DEFAULT_FPS` for a new one).
    interpolation
        Of new tracks: ``"linear"`` or ``"smooth"``.

    Returns
    -------
    Animation
        A new animation with the keys.
    """
    if interpolation not in ("linear", "smooth"):
        raise AnimationError(f"interpolation must be 'linear' or 'smooth'; got {interpolation!r}")
    base = animation.to_dict() if animation is not None else {"frames": DEFAULT_FRAMES}
    if frames is not None:
        base["frames"] = int(frames)
    base["fps"] = float(fps if fps is not None else base.get("fps", DEFAULT_FPS))
    anim = Animation.from_dict(base)
    if not 0 <= int(frame) < anim.frames:
        raise AnimationError(f"frame must be 0..{anim.frames - 1}; got {frame}")
    frame = int(frame)
    if camera is not None:
        put_key(track(anim, "camera", interpolation), frame, camera.to_dict())
    session.family.set_keys(anim, frame, interpolation)
    return Animation.from_dict(anim.to_dict())  # checked


def delete_keys(animation: Animation, frame: int) -> Animation:
    """The animation without its keys at ``frame`` (tracks left empty are dropped)."""
    d = animation.to_dict()
    tracks = []
    for t in d["tracks"]:
        t["keys"] = [k for k in t["keys"] if k[0] != frame]
        if t["keys"]:
            tracks.append(t)
    d["tracks"] = tracks
    return Animation.from_dict(d)


def key_frames(animation: Animation | None) -> list[int]:
    """The frames that hold a key of any track, sorted."""
    if animation is None:
        return []
    return sorted({int(f) for t in animation.tracks for f, _ in t.keys})
