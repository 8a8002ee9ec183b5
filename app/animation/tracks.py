"""Keyframe animation of scenes: tracks on scene parameters, evaluated into per-frame scenes.

The wire paper's tool let the user deform a wire differently over any number of frames
and render the series into a movie; here every deformation family (wires, lattice,
mass-spring, ChainMail) and the look of the scene (camera, transfer function, sample
distance, window, clipping box, ...) can be keyed the same way. ``voxwarp animate``
(:mod:`voxwarp.animation.movie`) renders the frames and encodes the movie.

Scene JSON
----------
An animated scene is ordinary scene JSON (:meth:`voxwarp.scene.Scene.to_dict`, also
:meth:`voxwarp.editing.session.EditSession.save` with its ``"editor"`` entry) plus an
``"animation"`` entry, which :meth:`Scene.from_dict <voxwarp.scene.Scene.from_dict>` ignores::

    "animation": {
      "frames": 24,                  # frames of the animation (>= 1)
      "fps": 24,                     # frames per second of the movie (default 24)
      "steps_per_frame": 10,         # optional: mass-spring steps per frame
      "relax_steps": 1,              # optional: ChainMail relaxation steps per frame
      "tracks": [
        {"target": "wires[0].modified", "interpolation": "linear",
         "keys": [[0, [[x, y, z], ...]], [12, [[x, y, z], ...]]]},
        {"target": "elements.drag", "elements": [[4, 2, 3]], "interpolation": "smooth",
         "keys": [[0, [0, 0, 0]], [8, [0, 0, -6]], [9, null]]},
        {"target": "camera", "keys": [[0, {"view": "-y"}], [23, {"view": [-60, 20]}]]}
      ]
    }

``steps_per_frame`` and ``relax_steps`` default to the ``"editor"`` entry's values (what
the GUI runs per frame), else 10 and 1. Each track keys one *target*; its ``keys`` are
``[frame, value]`` pairs with frames in ``[0, frames - 1]`` (numbers, strictly
increasing). Before the first key a track holds the first value, after the last key
the last value.

Targets and their values (the deformation families' targets, ``wires[i]...``,
``lattice.nodes``, ``elements.drag`` and ``meshes[NAME].nodes``, are handled by one
module per family in :mod:`voxwarp.animation.targets`):

``camera``
    A camera object (:meth:`voxwarp.core.camera.Camera.to_dict`; missing fields come from the
    scene's camera), or ``{"view": "-y" | [azimuth, elevation], "zoom": z, "fov": f,
    "projection": p}`` (optional zoom/fov/projection): a camera fitted, like the scene's
    own, to the scene's deformed box as saved. Centre, distance, field of view,
    orthographic height and radius are interpolated component-wise, the rotation by
    slerp (scipy's ``Slerp``, the shorter way round); all keys need the same projection.
``transfer_function``
    Control points ``[[value, r, g, b, a], ...]``, ``{"points": [...]}`` or a preset name
    (resolved on the scene's volume); every key must have the same number of points,
    which are paired in value order.
``step``, ``zoom``, ``fov``, ``iso_value``, ``flm_threshold``
    A number. ``zoom`` and ``fov`` refit the camera of a scene without an explicit
    camera (they cannot be combined with a ``camera`` track or a scene camera).
``window``, ``clip_box``, ``background``
    ``[level, width]``; ``[[x0, y0, z0], [x1, y1, z1]]`` (mm); ``[r, g, b(, a)]``.
``wires[i].modified``
    The (N, 3) control points (mm) of wire ``i``'s modified curve (N the same in every
    key; a Bézier wire needs 3k + 1). The scene needs exactly one ``"wires"`` warp.
``wires[i].twist``, ``wires[i].scale``
    Wire ``i``'s twist (radians) or scale keys along the wire: a number (constant along
    the wire) or ``[[u, value], ...]`` (u the fraction of the wire's length; the same
    number of pairs in every key), see :class:`voxwarp.deform.wires.field.Wire`.
``lattice.nodes``
    The (nx + 1, ny + 1, nz + 1, 3) nodes (mm) of the scene's one ``"lattice"`` warp
    (the shape of the scene's lattice), or ``"rest"``: the undeformed lattice over the
    warp's box.
``meshes[NAME].nodes``
    The node grid (mm, the shape of its lattice) of the scene's mesh instance named
    ``NAME``, or ``"rest"`` (its box, undeformed). The track's optional
    ``"attachments"`` lists meshes anchored to its triangles (GRAPP 2010, section 5):
    their lattices are rebuilt from the anchors on the moved mesh every frame, see
    :mod:`voxwarp.animation.mesh_targets`.
``elements.drag``
    Which elements of the scene's mass-spring or ChainMail model (an ``offset_field``
    warp saved with its model) are held, and where: the track's ``"elements"`` lists
    ``[i, j, k]`` indices; a value is one offset ``[dx, dy, dz]`` (mm from rest, in the
    model's frame: world mm unless the editor placed the grid) for all of them, an
    (m, 3) list (one per element), or ``null``: let them go. Between a held key and a
    ``null`` key the earlier key holds until the later key's frame. Several drag
    tracks may hold different elements. The model is simulated only in animations with
    a drag track (a scene's saved model state is otherwise rendered as saved); it starts
    from the saved state at rest (velocities are not saved), with the saved held
    elements still held.

Interpolation
-------------
``"linear"`` blends the two keys around a frame by ``t`` in [0, 1] (the fraction of the
way from one key frame to the next). ``"smooth"`` eases each key interval with
smoothstep, ``t' = 3 t² - 2 t³``: it passes through every key with zero slope there
(ease-in/ease-out, also at the first and last key), and, unlike a Catmull-Rom spline,
never leaves the range of the two keys around a frame — so blended transfer functions
stay sorted with components in [0, 1], scales stay positive, and a poke eases in and
out. Dense keys (e.g. every second frame of a swimming motion) with ``"linear"`` give
steady motion through the keys. Rotations use slerp with the same (eased) ``t``.

Evaluation
----------
Physics models depend on their history, so the animation is evaluated *serially* on the
CPU, frame after frame (:func:`iter_frames`; :func:`evaluate` collects them all): for
each frame ``f`` (in order) the tracks are evaluated at ``f``, the element drags
applied, then ``steps_per_frame`` mass-spring steps or ``relax_steps`` ChainMail
relaxation steps run, and the frame's state is written as a complete scene dict
(:meth:`Scene.to_dict` form: the warps' ``to_dict()`` carry the deformed fields, wires
and lattice nodes). Frames are then rendered from those dicts in any order and on any
machine (:mod:`voxwarp.animation.movie`, :mod:`voxwarp.animation.distributed`),
identically. ``voxwarp animate`` streams them (:func:`stream_animated_scene`): a frame's
dict is made when the renderer is ready for it and dropped once it is drawn, so memory
stays bounded and the first frame appears at once however long the animation (each dict
holds the deformed fields, so evaluating all :data:`MAX_FRAMES` frames up front would
take gigabytes). A scene without an explicit camera and without a ``camera`` track gets
the camera fitted to its deformed box *as saved*, held for every frame, so the view does
not jump as the object deforms.

Rendering ``N`` frames of an animation of ``frames`` frames (``voxwarp animate
--frames N``) evaluates the tracks at ``f = i (frames - 1) / (N - 1)`` for frame ``i``,
i.e. the key frames are scaled to the new length; the physics still runs
``steps_per_frame`` steps per rendered frame.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.animation.targets import (
    EXTRA_KEYS,
    FAMILY_TARGET_NAMES,
    TARGET_FAMILIES,
    Binding,
    TargetFamily,
    family_of,
    repeatable,
    track_elements,
    track_extras,
)
from voxwarp.animation.values import AnimationError, array, interpolate, key_weights, number
from voxwarp.core.camera import Camera
from voxwarp.core.files import atomic_write_text
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.errors import SceneError
from voxwarp.scene import Scene, read_scene_dict

#: key of the animation entry in scene JSON
ANIMATION_KEY = "animation"
#: interpolation modes of a track
INTERPOLATIONS: tuple[str, ...] = ("linear", "smooth")
#: default frames per second
DEFAULT_FPS = 24.0
#: physics per frame when neither the animation nor the editor entry says
DEFAULT_STEPS_PER_FRAME = 10
DEFAULT_RELAX_STEPS = 1
#: most frames of one animation
MAX_FRAMES = 100_000
#: most frames per second
MAX_FPS = 1000.0
#: most physics steps per frame (``steps_per_frame``, ``relax_steps``)
MAX_PHYSICS_STEPS = 10000
#: keys of the animation entry
ANIMATION_KEYS: tuple[str, ...] = ("frames", "fps", "tracks", "steps_per_frame", "relax_steps")
#: keys of a track entry (besides the families' :data:`EXTRA_KEYS`)
TRACK_KEYS: tuple[str, ...] = ("target", "keys", "interpolation", "elements")
#: scene attributes a track can key, with the shape of their values (() = a number)
SCALAR_TARGETS: dict[str, tuple[int, ...]] = {
    "step": (),
    "zoom": (),
    "fov": (),
    "iso_value": (),
    "flm_threshold": (),
    "window": (2,),
    "clip_box": (2, 3),
    "background": (4,),
}
#: every target a track can key (``i``: a wire's index)
TARGETS: tuple[str, ...] = (
    "camera",
    "transfer_function",
    *SCALAR_TARGETS,
    *FAMILY_TARGET_NAMES,
)


# ---------------------------------------------------------------------------- interpolation
def slerp_rotation(r0: np.ndarray, r1: np.ndarray, t: float) -> np.ndarray:
    """The rotation a fraction ``t`` of the way from ``r0`` to ``r1``, the shorter way round.

    Spherical linear interpolation by :class:`scipy.spatial.transform.Slerp`.

    Parameters
    ----------
    r0, r1
        (3, 3) proper rotation matrices.
    t
        Fraction in [0, 1] (0 gives ``r0``, 1 gives ``r1``).

    Returns
    -------
    numpy.ndarray
        (3, 3) proper rotation matrix.
    """
    from scipy.spatial.transform import Rotation, Slerp  # scipy loads when used

    keys = Rotation.from_matrix(np.stack([np.asarray(r0, float), np.asarray(r1, float)]))
    return Slerp([0.0, 1.0], keys)(float(t)).as_matrix()


_CAMERA_LINEAR = ("distance", "fov", "ortho_height", "radius")


def interpolate_camera(
    keys: Sequence[tuple[float, Camera]], frame: float, interpolation: str = "linear"
) -> Camera:
    """The camera at ``frame`` between camera keys (see the module doc).

    Parameters
    ----------
    keys
        ``(frame, Camera)`` pairs, frames strictly increasing, one projection.
    frame
        Frame to evaluate.
    interpolation
        ``"linear"`` or ``"smooth"``.

    Returns
    -------
    Camera
        A new camera (a copy of the key's camera on a key).
    """
    i, j, t = key_weights([k[0] for k in keys], frame, interpolation)
    a = keys[i][1]
    if t == 0.0:
        return Camera.from_dict(a.to_dict())
    b = keys[j][1]
    rot = slerp_rotation(a.rotation, b.rotation, t)
    values = {n: (1.0 - t) * getattr(a, n) + t * getattr(b, n) for n in _CAMERA_LINEAR}
    return Camera(
        center=(1.0 - t) * a.center + t * b.center,
        rotation=rot,
        projection=a.projection,
        **values,
    )


# ---------------------------------------------------------------------------- parsing
def _count(x: Any, what: str, lo: int, hi: int) -> int:
    if isinstance(x, bool) or not isinstance(x, int | float) or float(x) != int(x):
        raise AnimationError(f"{what} must be an integer {lo}..{hi}; got {x!r:.60}")
    if not lo <= int(x) <= hi:
        raise AnimationError(f"{what} must be an integer {lo}..{hi}; got {x!r}")
    return int(x)


def _target_name(target: Any) -> str:
    if isinstance(target, str) and (
        target in ("camera", "transfer_function")
        or target in SCALAR_TARGETS
        or family_of(target) is not None
    ):
        return target
    raise AnimationError(f"unknown animation target {target!r}; targets: {', '.join(TARGETS)}")


@dataclass
class Track:
    """Keys of one target (see the module doc for targets and values).

    Parameters
    ----------
    target
        One of :data:`TARGETS` (``wires[i]...`` with a wire index).
    keys
        ``(frame, value)`` pairs (JSON values), frames strictly increasing.
    interpolation
        ``"linear"`` or ``"smooth"``.
    elements
        For ``elements.drag``: the (m, 3) element indices the track holds.
    extras
        The family's further entries (JSON values by name), e.g. the ``"attachments"``
        of a ``meshes[NAME].nodes`` track.
    """

    target: str
    keys: list[tuple[float, Any]]
    interpolation: str = "linear"
    elements: list[list[int]] | None = None
    extras: dict[str, Any] = field(default_factory=dict)

    @property
    def key_frames(self) -> list[float]:
        """The key frames."""
        return [k[0] for k in self.keys]

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        d: dict[str, Any] = {
            "target": self.target,
            "interpolation": self.interpolation,
            "keys": [[_json_number(f), _jsonable(v)] for f, v in self.keys],
        }
        if self.elements is not None:
            d["elements"] = [list(e) for e in self.elements]
        d.update({k: _jsonable(v) for k, v in self.extras.items()})
        return d

    @classmethod
    def from_dict(cls, d: Any, frames: int, where: str = "track") -> Track:
        """Parse and check one track entry (the checks that need no scene).

        Parameters
        ----------
        d
            ``{"target", "keys", "interpolation"?, "elements"?}``.
        frames
            The animation's frame count (key frames must lie in ``[0, frames - 1]``).
        where
            Name of the entry in error messages.

        Returns
        -------
        Track

        Raises
        ------
        AnimationError
            Naming the entry and the problem.
        """
        if not isinstance(d, Mapping):
            raise AnimationError(f"{where} must be an object with 'target' and 'keys'")
        allowed = (*TRACK_KEYS, *EXTRA_KEYS)
        unknown = set(d) - set(allowed)
        if unknown:
            raise AnimationError(
                f"{where}: unknown keys {sorted(unknown)}; allowed: {', '.join(allowed)}"
            )
        if "target" not in d:
            raise AnimationError(f"{where} needs a 'target'; targets: {', '.join(TARGETS)}")
        target = _target_name(d["target"])
        where = f"{where} ({target})"
        interpolation = d.get("interpolation", "linear")
        if interpolation not in INTERPOLATIONS:
            raise AnimationError(
                f"{where}: interpolation must be one of {', '.join(INTERPOLATIONS)};"
                f" got {interpolation!r}"
            )
        raw = d.get("keys")
        if not isinstance(raw, list) or not raw:
            raise AnimationError(f"{where} needs 'keys': a non-empty list of [frame, value]")
        keys: list[tuple[float, Any]] = []
        for n, k in enumerate(raw):
            if not isinstance(k, list | tuple) or len(k) != 2:
                raise AnimationError(f"{where}: key {n} must be [frame, value]; got {k!r:.60}")
            f = number(k[0], f"{where}: key {n}'s frame")
            if not 0 <= f <= frames - 1:
                raise AnimationError(
                    f"{where}: key {n}'s frame {f:g} is outside the animation's frames"
                    f" 0..{frames - 1}"
                )
            if keys and f <= keys[-1][0]:
                raise AnimationError(
                    f"{where}: key frames must increase strictly; key {n} ({f:g}) follows"
                    f" {keys[-1][0]:g}"
                )
            keys.append((f, _check_value(target, k[1], f"{where}: key {n}")))
        elements = track_elements(target, d, keys, where)
        return cls(target, keys, interpolation, elements, track_extras(target, d, where))


def _json_number(f: float) -> int | float:
    return int(f) if float(f).is_integer() else float(f)


def _jsonable(v: Any) -> Any:
    """Key values as JSON values (numpy arrays and numbers become lists and floats)."""
    if isinstance(v, np.ndarray | np.generic):
        return v.tolist()
    if isinstance(v, list | tuple):
        return [_jsonable(x) for x in v]
    if isinstance(v, Mapping):
        return {k: _jsonable(x) for k, x in v.items()}
    return v


def _check_value(target: str, v: Any, what: str) -> Any:
    """Checks of a key value that need no scene; returns the JSON value."""
    family = family_of(target)
    if family is not None:
        family.check_value(target, v, what)
    elif target in SCALAR_TARGETS:
        shape = SCALAR_TARGETS[target]
        if target == "background" and isinstance(v, list) and len(v) == 3:
            shape = (3,)
        if shape == ():
            number(v, what)
        else:
            array(v, what, shape)
    elif target == "camera":
        if not isinstance(v, Mapping):
            raise AnimationError(
                f"{what} must be a camera object (Camera.to_dict form) or"
                ' {"view": ..., "zoom": ...}'
            )
    elif target == "transfer_function":
        if not isinstance(v, str | list | Mapping):
            raise AnimationError(f"{what} must be control points, {{'points': ...}} or a preset")
    return v


@dataclass
class Animation:
    """The ``"animation"`` entry of scene JSON (see the module doc).

    Parameters
    ----------
    frames
        Number of frames (1..:data:`MAX_FRAMES`).
    fps
        Frames per second of the movie.
    tracks
        The :class:`Track` objects.
    steps_per_frame, relax_steps
        Physics per frame (``None``: the editor entry's values or the defaults).
    """

    frames: int
    fps: float = DEFAULT_FPS
    tracks: list[Track] = field(default_factory=list)
    steps_per_frame: int | None = None
    relax_steps: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON form (the value of the scene's ``"animation"`` key)."""
        d: dict[str, Any] = {
            "frames": self.frames,
            "fps": _json_number(self.fps),
            "tracks": [t.to_dict() for t in self.tracks],
        }
        if self.steps_per_frame is not None:
            d["steps_per_frame"] = self.steps_per_frame
        if self.relax_steps is not None:
            d["relax_steps"] = self.relax_steps
        return d

    @classmethod
    def from_dict(cls, d: Any) -> Animation:
        """Parse and check an animation entry.

        Parameters
        ----------
        d
            The ``"animation"`` object.

        Returns
        -------
        Animation

        Raises
        ------
        AnimationError
            On a missing or malformed key (the message names it and the fix).
        """
        if not isinstance(d, Mapping):
            raise AnimationError("'animation' must be an object with 'frames' and 'tracks'")
        allowed = set(ANIMATION_KEYS)
        unknown = set(d) - allowed
        if unknown:
            raise AnimationError(
                f"animation: unknown keys {sorted(unknown)}; allowed: {', '.join(sorted(allowed))}"
            )
        if "frames" not in d:
            raise AnimationError("animation needs 'frames': the number of frames (>= 1)")
        frames = _count(d["frames"], "animation 'frames'", 1, MAX_FRAMES)
        fps = number(d.get("fps", DEFAULT_FPS), "animation 'fps'")
        if not 0 < fps <= MAX_FPS:
            raise AnimationError(f"animation 'fps' must be in (0, {MAX_FPS:g}]; got {fps:g}")
        steps = d.get("steps_per_frame")
        relax = d.get("relax_steps")
        if steps is not None:
            steps = _count(steps, "animation 'steps_per_frame'", 0, MAX_PHYSICS_STEPS)
        if relax is not None:
            relax = _count(relax, "animation 'relax_steps'", 0, MAX_PHYSICS_STEPS)
        tracks = d.get("tracks", [])
        if not isinstance(tracks, list):
            raise AnimationError("animation 'tracks' must be a list of track objects")
        parsed = [Track.from_dict(t, frames, f"track {n}") for n, t in enumerate(tracks)]
        singles = [t.target for t in parsed if not repeatable(t.target)]
        twice = sorted({t for t in singles if singles.count(t) > 1})
        if twice:
            raise AnimationError(f"animation: more than one track keys {', '.join(twice)}")
        return cls(frames, fps, parsed, steps, relax)

    @classmethod
    def from_scene_dict(cls, d: Mapping[str, Any]) -> Animation:
        """The animation of a scene JSON object (:class:`AnimationError` without one)."""
        if not isinstance(d, Mapping) or ANIMATION_KEY not in d:
            raise AnimationError(
                "the scene has no 'animation' entry; add one (see app/animation/tracks.py or"
                " sample_volumes/fish_swim_anim.json)"
            )
        return cls.from_dict(d[ANIMATION_KEY])

    @classmethod
    def from_scene_file(cls, path: str | os.PathLike) -> Animation:
        """The animation of a scene JSON file."""
        return cls.from_scene_dict(read_scene_dict(path))

    def time_of(self, index: int, count: int | None = None) -> float:
        """Animation frame (key time) of rendered frame ``index`` of ``count`` frames.

        Parameters
        ----------
        index
            Rendered frame, 0..count - 1.
        count
            Frames rendered (default :attr:`frames`); key frames scale to it.

        Returns
        -------
        float
        """
        n = self.frames if count is None else int(count)
        if n <= 1 or n == self.frames:
            return float(index)
        return index * (self.frames - 1) / (n - 1)


def save_animated_scene(path: str | os.PathLike, source: Any, animation: Animation) -> Path:
    """Write scene JSON with an ``"animation"`` entry, atomically.

    Parameters
    ----------
    path
        Output file.
    source
        A :class:`~voxwarp.scene.Scene`, an :class:`~voxwarp.editing.session.EditSession` (anything
        with
        ``to_dict(base_dir=...)``) or a scene JSON dict (written as given).
    animation
        The animation to attach (validated against the frames first).

    Returns
    -------
    Path
    """
    path = Path(path)
    if isinstance(source, Mapping):
        d = dict(source)
    else:
        d = source.to_dict(base_dir=path.parent.resolve())
    d[ANIMATION_KEY] = Animation.from_dict(animation.to_dict()).to_dict()
    atomic_write_text(path, json.dumps(d, indent=1))
    return path


# ---------------------------------------------------------------------------- evaluation
@dataclass
class FrameStates:
    """An animation evaluated into one complete scene dict per frame.

    Attributes
    ----------
    animation
        The :class:`Animation`.
    scenes
        Per frame, scene JSON (:meth:`Scene.to_dict` form, with the volume entry);
        plain JSON values, ready to be hashed, shipped and rendered.
    base_dir
        Folder that relative volume and mesh paths in ``scenes`` refer to (absolute).
    """

    animation: Animation
    scenes: list[dict[str, Any]]
    base_dir: Path | None

    def __len__(self) -> int:
        return len(self.scenes)

    def scene(self, index: int) -> Scene:
        """The :class:`Scene` of frame ``index`` (loads the volume)."""
        return Scene.from_dict(self.scenes[index], base_dir=self.base_dir)


@dataclass
class FrameStream:
    """An animation whose per-frame scene dicts are evaluated one at a time, on demand.

    Attributes
    ----------
    animation
        The :class:`Animation`.
    count
        Number of frames ``frames`` yields.
    base_dir
        Folder that relative volume and mesh paths refer to (absolute).
    frames
        The frames' scene dicts in order (as :attr:`FrameStates.scenes`), evaluated
        lazily: frame ``i`` is computed when it is asked for. Close it (or exhaust it)
        to free the physics models.
    """

    animation: Animation
    count: int
    base_dir: Path | None
    frames: Iterator[dict[str, Any]]
    on_close: Callable[[], None] | None = field(default=None, repr=False)

    def close(self) -> None:
        """Stop evaluating and free the physics models (idempotent)."""
        close = getattr(self.frames, "close", None)
        if close is not None:
            close()
        if self.on_close is not None:
            self.on_close()


def load_animated_scene(path: str | os.PathLike, frames: int | None = None) -> FrameStates:
    """Read an animated scene file and evaluate it (see :func:`evaluate`).

    Parameters
    ----------
    path
        Scene JSON with an ``"animation"`` entry.
    frames
        Frames to render (default: the animation's).

    Returns
    -------
    FrameStates
    """
    p = Path(path)
    d = read_scene_dict(p)
    return evaluate(d, base_dir=p.parent.resolve(), frames=frames)


def stream_animated_scene(path: str | os.PathLike, frames: int | None = None) -> FrameStream:
    """Read an animated scene file and evaluate it lazily (see :func:`iter_frames`).

    The scene and every track are checked before this returns; a frame's own problem
    (say a drag that folds the model) is raised when that frame is evaluated.
    """
    p = Path(path)
    d = read_scene_dict(p)
    return iter_frames(d, base_dir=p.parent.resolve(), frames=frames)


def evaluate(
    scene: Mapping[str, Any],
    base_dir: str | os.PathLike | None = None,
    animation: Animation | None = None,
    frames: int | None = None,
) -> FrameStates:
    """Evaluate an animation serially into per-frame scene dicts (see the module doc).

    Parameters
    ----------
    scene
        Scene JSON object (with an ``"animation"`` entry unless ``animation`` is given).
    base_dir
        Folder relative paths in ``scene`` refer to.
    animation
        The animation (default: the scene's entry).
    frames
        Frames to render (default: the animation's); the keys scale to it.

    Returns
    -------
    FrameStates
        Every frame at once (:func:`iter_frames` gives them one at a time, with the
        same values).

    Raises
    ------
    AnimationError, SceneError
        When the animation or the scene is invalid, or a track does not fit the scene.
    """
    stream = iter_frames(scene, base_dir=base_dir, animation=animation, frames=frames)
    return FrameStates(stream.animation, list(stream.frames), stream.base_dir)


def iter_frames(
    scene: Mapping[str, Any],
    base_dir: str | os.PathLike | None = None,
    animation: Animation | None = None,
    frames: int | None = None,
) -> FrameStream:
    """Bind an animation to its scene and evaluate its frames one at a time.

    Parameters are those of :func:`evaluate`. The scene, the animation and every key
    value are checked here; the physics of frame ``i`` runs when frame ``i`` is taken
    from :attr:`FrameStream.frames`, so only the frames a caller holds are in memory.
    The dicts are the ones :func:`evaluate` returns, value for value.

    Raises
    ------
    AnimationError, SceneError
        When the animation or the scene is invalid, or a track does not fit the scene
        (here); when a frame is invalid (while iterating).
    """
    anim = animation if animation is not None else Animation.from_scene_dict(scene)
    count = anim.frames if frames is None else _count(frames, "frames", 1, MAX_FRAMES)
    base_path = Path(base_dir).resolve() if base_dir is not None else None
    base = Scene.from_dict(scene, base_dir=base_path)
    editor = scene.get("editor") if isinstance(scene.get("editor"), Mapping) else {}
    assert isinstance(editor, Mapping)
    steps = _physics(anim.steps_per_frame, editor.get("steps_per_frame"), DEFAULT_STEPS_PER_FRAME)
    relax = _physics(anim.relax_steps, editor.get("relax_steps"), DEFAULT_RELAX_STEPS)
    template = base.to_dict(base_dir=base_path)
    bound = _Bound(base, template, anim)

    def frames_of() -> Iterator[dict[str, Any]]:
        try:
            for index in range(count):
                f = anim.time_of(index, count)
                yield bound.frame(f, index, steps, relax)
        finally:
            bound.close()

    return FrameStream(anim, count, base_path, frames_of(), bound.close)


def _physics(own: int | None, editor: Any, default: int) -> int:
    if own is not None:
        return own
    if isinstance(editor, int) and not isinstance(editor, bool) and 0 <= editor <= 10000:
        return editor
    return default


class _Bound:
    """An animation bound to its scene: resolved key values and each family's binding."""

    def __init__(self, base: Scene, template: dict[str, Any], anim: Animation) -> None:
        self.base = base
        self.template = template
        self.tracks: list[tuple[Track, list[tuple[float, Any]], Binding | None]] = []
        #: the bound families, by handler (see :mod:`voxwarp.animation.targets`)
        self.bindings: dict[TargetFamily, Binding] = {}
        targets = {t.target for t in anim.tracks}
        if targets & {"zoom", "fov"} and (base.camera is not None or "camera" in targets):
            raise AnimationError(
                "zoom and fov tracks refit the camera of a scene without one; this scene has"
                " an explicit camera or a camera track: key the camera's distance/fov instead"
            )
        #: the held camera of a scene without an explicit one (see the module doc)
        self.camera = base.resolved_camera()
        try:
            for t in anim.tracks:
                values: list[tuple[float, Any]] = []
                for f, v in t.keys:
                    first = values[0][1] if values else None
                    values.append((f, self._resolve(t, v, f, first)))
                family = family_of(t.target)
                self.tracks.append((t, values, self.bindings.get(family) if family else None))
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Free the families' bindings (physics models); idempotent."""
        bindings, self.bindings = list(self.bindings.values()), {}
        for binding in bindings:
            binding.close()

    def _ordered(self) -> list[Binding]:
        """The bindings in the registry's order."""
        return [self.bindings[f] for f in TARGET_FAMILIES if f in self.bindings]

    # -------------------------------------------------------------- key values
    def _resolve(self, t: Track, v: Any, f: float, first: Any) -> Any:
        what = f"track {t.target}, key at frame {f:g}"
        try:
            family = family_of(t.target)
            if family is not None:
                return self._bind(family, t.target).resolve(t, v, what, first)
            return self._resolve_value(t, v, what, first)
        except AnimationError:
            raise
        except (SceneError, ValueError, TypeError) as exc:
            raise AnimationError(f"{what}: {exc}") from exc

    def _bind(self, family: TargetFamily, target: str) -> Binding:
        """The family's binding to the scene (bound at its first key)."""
        if family not in self.bindings:
            self.bindings[family] = family.bind(self.base, self.template, target)
        return self.bindings[family]

    def _resolve_value(self, t: Track, v: Any, what: str, first: Any) -> Any:
        """A key value of a scene attribute (camera, transfer function, numbers)."""
        target = t.target
        if target in SCALAR_TARGETS:
            a = np.asarray(v, dtype=np.float64)
            if target == "background" and a.shape == (3,):
                a = np.append(a, 1.0)
            return a
        if target == "camera":
            cam = self._camera(dict(v), what)
            if first is not None and first.projection != cam.projection:
                raise AnimationError(
                    f"{what}: every camera key needs the same projection; {cam.projection}"
                    f" here, {first.projection} in the first key"
                )
            return cam
        tf = TransferFunction.coerce(v, self.base.volume)
        pts = np.asarray(tf.points, dtype=np.float64)
        if first is not None and first.shape != pts.shape:
            raise AnimationError(
                f"{what}: every transfer function key needs the same number of control"
                f" points to be interpolated; {len(pts)} here, {len(first)} in the first"
            )
        return pts

    def _camera(self, v: dict[str, Any], what: str) -> Camera:
        base = self.base
        if "view" in v:
            extra = set(v) - {"view", "zoom", "fov", "projection"}
            if extra:
                raise AnimationError(
                    f"{what}: a view key takes view, zoom, fov and projection; got {sorted(extra)}"
                )
            view = v["view"]
            view = tuple(view) if isinstance(view, list) else view
            scene = base.copy(
                camera=None,
                view=view,
                zoom=v.get("zoom", base.zoom),
                fov=v.get("fov", base.fov),
                projection=v.get("projection", base.projection),
            )
            cam = scene.resolved_camera()
        else:
            unknown = set(v) - set(Camera.__dataclass_fields__)
            if unknown:
                raise AnimationError(
                    f"{what}: unknown camera keys {sorted(unknown)}; allowed:"
                    f" {', '.join(Camera.__dataclass_fields__)} (or a view key)"
                )
            cam = Camera.from_dict({**self.camera.to_dict(), **v})
        return cam

    # -------------------------------------------------------------- frames
    def frame(self, f: float, index: int, steps: int, relax: int) -> dict[str, Any]:
        """Scene dict of animation time ``f`` (advances the physics by one frame)."""
        d = dict(self.template)
        d["warps"] = list(self.template["warps"])
        d["camera"] = self.camera.to_dict()
        refit: dict[str, Any] = {}
        for t, keys, binding in self.tracks:
            if binding is not None:
                binding.apply(d, t, keys, f)
            else:
                self._apply(d, t, keys, f, refit)
        if refit:
            d["camera"] = self.base.copy(camera=None, **refit).resolved_camera().to_dict()
        for binding in self._ordered():
            binding.step(d, index, steps, relax)
        self._check_frame(d, index)
        return d

    def _apply(
        self, d: dict[str, Any], t: Track, keys: list[tuple[float, Any]], f: float, refit: dict
    ) -> None:
        """Write a scene attribute's value at ``f`` into ``d`` (``refit``: zoom and fov)."""
        target = t.target
        if target == "camera":
            d["camera"] = interpolate_camera(keys, f, t.interpolation).to_dict()
        elif target == "transfer_function":
            pts = interpolate(keys, f, t.interpolation)
            d["transfer_function"] = {
                "name": self.base.transfer_function.name,
                "points": pts.tolist(),
            }
        else:
            a = interpolate(keys, f, t.interpolation)
            value = float(a) if a.ndim == 0 else a.tolist()
            if target in ("zoom", "fov"):
                refit[target] = value
            d[target] = value

    def _check_frame(self, d: dict[str, Any], index: int) -> None:
        """Cheap checks of a frame's interpolated values (no volume, no wire field)."""
        try:
            Camera.from_dict(d["camera"])
            if isinstance(d.get("transfer_function"), Mapping):
                TransferFunction.from_dict(d["transfer_function"])
            self.base.copy(
                **{k: d[k] for k in ("step", "zoom", "fov", "window", "clip_box") if k in d},
                background=tuple(d["background"]),
            )
            for binding in self._ordered():
                binding.check(d)
        except (SceneError, ValueError, TypeError) as exc:
            raise AnimationError(f"frame {index}: {exc}") from exc
