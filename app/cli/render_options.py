"""The command line's view and input options beyond the scene's own: clip box and slabs,
a camera from a file, the framing, drags at world points, and how an input is read.

``voxwarp render`` parses them with the argument types here (a malformed value is one
argparse line, exit code 2) and applies them to the finished scene with
:func:`apply_render_options` once every warp is in it, so ``--slab`` and the checks
against the volume see the deformed box the rays march in. All coordinates are world
mm (RAS+: +x the patient's right, +y anterior, +z superior).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, NamedTuple

from voxwarp.core.checks import interactive_downsample_arg
from voxwarp.core.files import atomic_write_text
from voxwarp.core.json_input import read_json
from voxwarp.errors import InputError, SceneError

#: ``--slab`` axis letters: world axis and sign (L, P, I count along -x, -y, -z)
SLAB_AXES: dict[str, tuple[int, int]] = {
    "x": (0, 1),
    "y": (1, 1),
    "z": (2, 1),
    "r": (0, 1),
    "a": (1, 1),
    "s": (2, 1),
    "l": (0, -1),
    "p": (1, -1),
    "i": (2, -1),
}
#: the camera JSON's entries (:meth:`voxwarp.core.camera.Camera.to_dict`)
CAMERA_KEYS = ("center", "rotation", "distance", "fov", "projection", "ortho_height", "radius")
#: options that fit a camera, which ``--camera`` replaces
_FITTING_OPTIONS = (("--view", "view"), ("--projection", "projection"), ("--zoom", "zoom"))

VIEW_HELP = (
    "+x,-x,+y,-y,+z,-z (the side the camera is on), anterior, posterior, left, right,"
    " superior, inferior (for a volume with a patient orientation) or AZIMUTH,ELEVATION in"
    " degrees: the camera at AZIMUTH about +z counted from +x towards +y, ELEVATION above"
    " the xy plane, so 0,0 is +x and 90,0 is +y; in patient (RAS) space +x is the"
    " patient's right, +y anterior, +z superior, so 90,0 is the anterior view"
)


def _floats(text: str, n: int, form: str, whole: str | None = None) -> tuple[float, ...]:
    """``n`` finite comma-separated numbers; errors quote ``whole`` (default ``text``)."""
    shown = text if whole is None else whole
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{shown!r}: expected {form}") from exc
    if len(vals) != n:
        raise argparse.ArgumentTypeError(f"{shown!r}: expected {form}")
    if not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(f"{shown!r}: numbers must be finite; expected {form}")
    return vals


Box = tuple[tuple[float, float, float], tuple[float, float, float]]


def clip_arg(text: str) -> Box:
    """``--clip X0,X1,Y0,Y1,Z0,Z1``: the box ``((x0, y0, z0), (x1, y1, z1))`` in mm."""
    form = "X0,X1,Y0,Y1,Z0,Z1 (world mm, low then high per axis), e.g. -40,40,-30,30,0,60"
    v = _floats(text, 6, form)
    for a, name in enumerate("xyz"):
        if v[2 * a + 1] <= v[2 * a]:
            raise argparse.ArgumentTypeError(
                f"{text!r}: the box is empty along {name} ({v[2 * a]:g} >= {v[2 * a + 1]:g});"
                f" expected {form}"
            )
    return (v[0], v[2], v[4]), (v[1], v[3], v[5])


class Slab(NamedTuple):
    """One ``--slab AXIS:CENTRE:THICKNESS``."""

    text: str
    axis: int
    centre: float  # along +axis, mm
    thickness: float


def slab_arg(text: str) -> Slab:
    """``--slab AXIS:CENTRE:THICKNESS``: AXIS x, y, z or R, A, S (L, P, I count the
    centre along -x, -y, -z), CENTRE and THICKNESS in mm."""
    form = (
        "AXIS:CENTRE:THICKNESS with AXIS x, y, z (or R, A, S; L, P, I count the centre"
        " along -x, -y, -z) and mm, e.g. z:40:10"
    )
    parts = text.split(":")
    if len(parts) != 3 or parts[0].strip().lower() not in SLAB_AXES:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    axis, sign = SLAB_AXES[parts[0].strip().lower()]
    try:
        centre, thickness = float(parts[1]), float(parts[2])
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if not (math.isfinite(centre) and math.isfinite(thickness)):
        raise argparse.ArgumentTypeError(f"{text!r}: numbers must be finite; expected {form}")
    if thickness <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: the thickness must be > 0 mm; expected {form}")
    return Slab(text, axis, sign * centre, thickness)


class DragAt(NamedTuple):
    """One ``--drag-at X,Y,Z:DX,DY,DZ``."""

    text: str
    point: tuple[float, float, float]
    offset: tuple[float, float, float]


def drag_at_arg(text: str) -> DragAt:
    """``--drag-at X,Y,Z:DX,DY,DZ``: a world point (mm) and the drag offset (mm)."""
    form = (
        "X,Y,Z:DX,DY,DZ (a world point in mm, then the offset in mm along x, y, z),"
        " e.g. 30,12,-4:0,10,0"
    )
    parts = text.split(":")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    point = _floats(parts[0], 3, form, text)
    offset = _floats(parts[1], 3, form, text)
    return DragAt(text, point, offset)  # type: ignore[arg-type]


def series_arg(text: str) -> int | str:
    """``--series UID|INDEX``: a SeriesInstanceUID, or its 1-based index in ``voxwarp info``'s
    list (largest series first)."""
    text = text.strip()
    if not text:
        raise argparse.ArgumentTypeError(
            "expected a SeriesInstanceUID or a series index (voxwarp info FOLDER lists them)"
        )
    return int(text) if text.isdigit() else text


def camera_arg(text: str) -> Any:
    """``--camera FILE``: the camera of a scene JSON (its ``"camera"``) or of a camera JSON
    (``Camera.to_dict``, as ``--save-camera`` writes it); a bad file is one argparse line."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.camera import Camera

    path = Path(text)
    try:
        d = read_json(path)
    except FileNotFoundError as exc:
        raise argparse.ArgumentTypeError(f"{text}: no such file") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise argparse.ArgumentTypeError(f"{text}: cannot read it ({exc})") from exc
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text}: not valid JSON ({exc})") from exc
    if not isinstance(d, dict):
        raise argparse.ArgumentTypeError(
            f"{text}: expected a scene JSON or a camera JSON object (written by --save-camera)"
        )
    if d.get("format") == "voxwarp-scene":
        d = d.get("camera")
        if d is None:
            raise argparse.ArgumentTypeError(
                f"{text}: this scene has no saved camera (it fits one from its view); write"
                f" one with voxwarp render {text} --save-camera camera.json and pass that"
            )
        if not isinstance(d, dict):
            raise argparse.ArgumentTypeError(f"{text}: the scene's 'camera' must be an object")
    missing = [k for k in CAMERA_KEYS if k not in d]
    unknown = sorted(set(d) - set(CAMERA_KEYS))
    if missing or unknown:
        what = f"lacks {', '.join(missing)}" if missing else f"has unknown keys {unknown}"
        raise argparse.ArgumentTypeError(
            f"{text}: a camera JSON {what}; it needs exactly {', '.join(CAMERA_KEYS)} (as"
            " voxwarp render --save-camera writes it)"
        )
    try:
        return Camera.from_dict(d)
    except (SceneError, TypeError, ValueError) as exc:
        raise argparse.ArgumentTypeError(f"{text}: {exc}") from exc


def add_input_args(p: argparse.ArgumentParser) -> None:
    """``--axis-order``, ``--series``, ``--frame-index`` and ``--channel``: how INPUT is
    read (``render``, ``slice``, ``info``)."""
    p.add_argument(
        "--axis-order",
        choices=("xyz", "zyx"),
        help="how a .npy/.npz array is indexed: xyz (array[i, j, k], default) or zyx"
        " (napari/tifffile order, transposed on load)",
    )
    add_series_arg(p)


def add_series_arg(p: argparse.ArgumentParser) -> None:
    """``--series UID|INDEX`` for DICOM folders holding several series, and
    ``--frame-index N`` / ``--channel N`` for 4-D and multi-channel files."""
    p.add_argument(
        "--frame-index",
        type=index_arg,
        metavar="N",
        help="the time point (0-based) to read from a 4-D file (a NIfTI time series, a"
        " NRRD time axis, a TIFF hyperstack's T); required when it holds several",
    )
    p.add_argument(
        "--channel",
        type=index_arg,
        metavar="N",
        help="the channel or vector component (0-based) to read from a multi-channel file"
        " (5-D NIfTI, NRRD list/vector axis, TIFF C/S, MetaImage with several components);"
        " required when it holds several",
    )
    p.add_argument(
        "--series",
        type=series_arg,
        metavar="UID|INDEX",
        help="the DICOM series to read from a folder holding several: its"
        " SeriesInstanceUID or its number (1, 2, ...) in the list voxwarp info FOLDER prints"
        " (default: the largest)",
    )


def load_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keywords of :func:`voxwarp.inputs.load_input` that the input options give:
    ``--spacing``, ``--downsample`` and ``--nan`` where the command has them, and
    ``--axis-order``, ``--series``, ``--frame-index`` and ``--channel`` when given."""
    names = {"spacing": "spacing", "downsample": "downsample", "nan": "nan_policy"}
    out: dict[str, Any] = {kw: getattr(args, a) for a, kw in names.items() if hasattr(args, a)}
    if getattr(args, "axis_order", None) is not None:
        out["axis_order"] = args.axis_order
    for name in ("series", "frame_index", "channel"):
        if getattr(args, name, None) is not None:
            out[name] = getattr(args, name)
    return out


def index_arg(text: str) -> int:
    """A 0-based index: a whole number >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number (0, 1, 2, ...)") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; indices count from 0")
    return value


def add_render_options(p: argparse.ArgumentParser) -> None:
    """``render``'s clip, slab, camera and framing options."""
    g = p.add_argument_group(
        "clipping and camera",
        "World coordinates are mm in patient space where the file states one (RAS+: +x"
        " the patient's right, +y anterior, +z superior), else the volume's own x, y, z.",
    )
    g.add_argument(
        "--clip",
        type=clip_arg,
        metavar="X0,X1,Y0,Y1,Z0,Z1",
        help="cut the rays to this box (world mm, in the deformed space the image shows);"
        " replaces a scene's clip box",
    )
    g.add_argument(
        "--slab",
        type=slab_arg,
        action="append",
        metavar="AXIS:CENTRE:THICKNESS",
        help="cut the volume to a slab THICKNESS mm thick around CENTRE mm along AXIS (x, y,"
        " z or R, A, S; L, P, I count along -x, -y, -z), e.g. z:40:10; repeatable; with"
        " --clip (or a scene's clip box) their intersection",
    )
    g.add_argument(
        "--camera",
        type=camera_arg,
        metavar="FILE",
        help="use the camera of FILE: a scene JSON with a saved camera, or a camera JSON"
        " written by --save-camera (so a before and an after image share it)",
    )
    g.add_argument(
        "--save-camera",
        metavar="FILE",
        help="also write the camera this image used as camera JSON (for --camera)",
    )
    g.add_argument(
        "--frame",
        choices=("undeformed", "deformed"),
        help="what the fitted camera frames: undeformed (default: the volume's own box, so"
        " before and after images share the framing and a translation shows as a shift)"
        " or deformed (the warped volume's box)",
    )
    g.add_argument(
        "--interactive-downsample",
        type=interactive_downsample_arg,
        metavar="N",
        help="the volume resolution the GUI interacts at with the scene --save-scene writes"
        " (1/N per axis, 1-16; its 'interactive_downsample'); the image itself is a still,"
        " rendered from the full volume",
    )


def check_render_options(args: argparse.Namespace) -> None:
    """Combinations that need no volume: ``--camera`` gives the whole camera, so the
    options that fit one do not apply."""
    if getattr(args, "camera", None) is None:
        return
    for opt, attr in (*_FITTING_OPTIONS, ("--frame", "frame")):
        if getattr(args, attr, None) is not None:
            raise InputError(
                f"{opt} cannot be combined with --camera, which gives the whole camera"
                f" (view, projection, zoom and framing): drop {opt} or --camera"
            )


def _box_text(lo: Any, hi: Any) -> str:
    return ", ".join(f"{a} {lo[i]:g}..{hi[i]:g}" for i, a in enumerate("xyz"))


def clip_box_for(scene: Any, args: argparse.Namespace) -> Any:
    """The clip box of ``--clip`` and ``--slab`` on ``scene`` (its warps in place), or the
    scene's own when neither is given; :class:`InputError` for an empty box or one that
    misses the (deformed) volume."""
    import numpy as np

    clip, slabs = getattr(args, "clip", None), getattr(args, "slab", None) or []
    if clip is None and not slabs:
        return scene.clip_box
    vlo, vhi = (np.asarray(v, dtype=np.float64) for v in scene.deformed_bounds())
    vol_text = f"the volume's box spans {_box_text(vlo, vhi)} mm"
    box = clip if clip is not None else scene.clip_box
    what = "--clip" if clip is not None else ("the scene's clip box" if box is not None else "")
    lo = np.array(box[0] if box is not None else vlo, dtype=np.float64)  # copies
    hi = np.array(box[1] if box is not None else vhi, dtype=np.float64)
    for s in slabs:
        a = s.axis
        slo, shi = s.centre - s.thickness / 2, s.centre + s.thickness / 2
        if shi <= vlo[a] or slo >= vhi[a]:
            raise InputError(
                f"--slab {s.text}: the slab ({'xyz'[a]} {slo:g}..{shi:g} mm) lies outside the"
                f" volume: {vol_text}"
            )
        new_lo, new_hi = max(lo[a], slo), min(hi[a], shi)
        if new_hi <= new_lo:
            raise InputError(
                f"--slab {s.text}: the slab ({'xyz'[a]} {slo:g}..{shi:g} mm) does not overlap"
                f" {what or 'the other slabs'} ({'xyz'[a]} {lo[a]:g}..{hi[a]:g} mm): the clip"
                " box would be empty"
            )
        lo[a], hi[a] = new_lo, new_hi
        what = what or "the other slabs"
    if np.any(np.minimum(hi, vhi) <= np.maximum(lo, vlo)):
        label = "--clip" if clip is not None else "the clip box"
        raise InputError(
            f"{label}: the box ({_box_text(lo, hi)} mm) misses the volume, so the image"
            f" would be empty: {vol_text}"
        )
    return tuple(map(float, lo)), tuple(map(float, hi))


def apply_render_options(scene: Any, args: argparse.Namespace) -> Any:
    """``scene`` with ``--frame``, ``--camera``, ``--clip``, ``--slab`` and
    ``--interactive-downsample`` applied; call it once every warp is in the scene
    (``--slab`` spans the deformed box)."""
    changes: dict[str, Any] = {}
    if getattr(args, "interactive_downsample", None) is not None:
        changes["interactive_downsample"] = args.interactive_downsample
    if getattr(args, "frame", None) is not None:
        changes["frame"] = args.frame
        changes["camera"] = None  # refit with this framing
    if getattr(args, "camera", None) is not None:
        changes["camera"] = args.camera
    if getattr(args, "clip", None) is not None or getattr(args, "slab", None):
        changes["clip_box"] = clip_box_for(scene, args)
    return scene.copy(**changes) if changes else scene


def save_camera(scene: Any, args: argparse.Namespace) -> None:
    """``--save-camera FILE``: write the camera ``scene`` renders with, atomically."""
    path = getattr(args, "save_camera", None)
    if path is None:
        return
    text = json.dumps(scene.resolved_camera().to_dict(), indent=2)
    atomic_write_text(Path(path), text + "\n")  # OutputError: one line, path and cause
    print(f"camera: {path}")


def spacing_notice(volume: Any, args: argparse.Namespace) -> None:
    """One line on stderr when ``volume``'s spacing was assumed (nobody stated it)."""
    if getattr(args, "spacing", None) is not None:
        return
    if getattr(volume, "spacing_source", "file") != "assumed":
        return
    sp = " x ".join(f"{v:g}" for v in volume.spacing)
    print(
        f"voxwarp: note: {volume.name} states no voxel spacing; assuming {sp} mm (give the"
        " real one with --spacing SX SY SZ)",
        file=sys.stderr,
    )


class Pick(NamedTuple):
    """The element a ``--drag-at`` picked."""

    drag: DragAt
    index: tuple[int, int, int]
    position: tuple[float, float, float]
    distance: float

    def summary(self) -> str:
        """One line: which element, where, how far from the point."""
        pos = ", ".join(f"{v:.4g}" for v in self.position)
        return (
            f"--drag-at {self.drag.text}: element {self.index} at ({pos}) mm,"
            f" {self.distance:.3g} mm from the point"
        )


def pick_elements(grid: Any, drags: list[DragAt]) -> list[Pick]:
    """The element of ``grid`` nearest each ``--drag-at`` point (at rest) that is not
    fixed (no drag can hold the anchor's shell; when every element is fixed, the nearest);
    :class:`InputError` for a point more than one element spacing outside the grid box."""
    import numpy as np

    rest = np.asarray(grid.rest_positions, dtype=np.float64)
    flat = rest.reshape(-1, 3)
    lo, hi, spacing = (np.asarray(v, dtype=np.float64) for v in (grid.lo, grid.hi, grid.spacing))
    picks = []
    for d in drags:
        p = np.asarray(d.point, dtype=np.float64)
        outside = np.maximum(np.maximum(lo - p, p - hi), 0.0)
        if np.any(outside > spacing * (1 + 1e-9)):
            shape = "x".join(str(n) for n in grid.shape)
            raise InputError(
                f"--drag-at {d.text}: the point lies more than one element spacing"
                f" ({', '.join(f'{s:.3g}' for s in spacing)} mm) outside the {shape} element"
                f" grid, whose elements span {_box_text(lo, hi)} mm; give a point inside"
                " that box (world mm)"
            )
        dist = np.linalg.norm(flat - p, axis=1)
        fixed = np.asarray(grid.fixed).reshape(-1)
        if not fixed.all():  # all fixed: the nearest, which the drag checks refuse
            dist[fixed] = np.inf
        k = int(np.argmin(dist))
        index = tuple(int(v) for v in np.unravel_index(k, rest.shape[:3]))
        picks.append(Pick(d, index, tuple(map(float, flat[k])), float(dist[k])))  # type: ignore[arg-type]
    return picks
