"""The files voxwarp opens by name, for the command line and the GUI alike.

:func:`load_input` opens INPUT: a volume file or folder (npy, npz, raw + JSON sidecar,
NRRD, NIfTI, DICOM folder, TIFF), a scene JSON written by ``Scene.save``, or
``sample:NAME`` for a bundled sample (a volume, or a bundled scene JSON by its file's
stem: :func:`voxwarp.io.samples.resolve_sample_path`; ``--wires``/``--lattice`` take
``sample:NAME`` of a bundled wire or lattice file too). :func:`read_wire_file` /
:func:`load_wire_file` and :func:`load_lattice_file` read the deformation files of ``--wires`` and
``--lattice``. Bad files raise :class:`~voxwarp.errors.InputError` naming the file and
the fix.

The command line imports this module to build its parser; to keep ``voxwarp --help``
light, the readers, the scene and the deformation models load inside the functions that
use them (the lattice warp brings scipy).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from voxwarp.core.json_input import read_json
from voxwarp.errors import InputError, VolumeError


def is_scene_json(path: Path) -> bool:
    """Whether ``path`` is a scene JSON file (``"format": "voxwarp-scene"``)."""
    if path.suffix.lower() != ".json" or not path.is_file():
        return False
    try:
        d = read_json(path)
    except (OSError, ValueError):
        return False
    return isinstance(d, dict) and d.get("format") == "voxwarp-scene"


def load_input(
    spec: str,
    *,
    spacing: Sequence[float] | None = None,
    downsample: int | tuple[int, int, int] = 1,
    nan_policy: str = "raise",
    axis_order: str = "xyz",
    series: int | str | None = None,
    keep_padding: bool = False,
    frame_index: int | None = None,
    channel: int | None = None,
) -> Any:
    """Load INPUT: returns a Volume, or a Scene for scene JSON.

    ``axis_order`` (``"xyz"`` or ``"zyx"``) says how a .npy/.npz array is indexed;
    ``series`` picks one series of a DICOM folder (its UID or index); both are passed to
    :func:`voxwarp.io.volumes.load_volume` and refused for samples and scene JSON, as
    are ``frame_index`` and ``channel`` (one time point or channel of a 4-D/5-D file).
    The padding outside a CT's field of view is masked
    (:func:`voxwarp.core.modality.mask_padding`) unless ``keep_padding``.
    """
    from voxwarp.core.modality import mask_padding
    from voxwarp.io.samples import load_sample, resolve_sample_path
    from voxwarp.scene import Scene

    spec = str(resolve_sample_path(spec))  # sample:NAME of a bundled scene: its file
    path = Path(spec)
    if path.suffix.lower() == ".json" and path.is_file():
        _check_json_input(path)
    named = "a bundled sample" if spec.startswith("sample:") else "a scene JSON"
    if spec.startswith("sample:") or is_scene_json(path):
        if axis_order != "xyz":
            raise InputError(f"--axis-order applies to .npy/.npz arrays; {spec} is {named}")
        if series is not None:
            raise InputError(f"--series applies to DICOM folders; {spec} is {named}")
        for option, value in (("--frame-index", frame_index), ("--channel", channel)):
            if value is not None:
                raise InputError(f"{option} applies to 4-D/multi-channel files; {spec} is {named}")
    if spec.startswith("sample:"):
        vol = load_sample(spec.split(":", 1)[1], spacing=spacing)
        vol = vol.downsample(downsample) if downsample != 1 else vol
        return vol if keep_padding else mask_padding(vol)[0]
    if is_scene_json(path):
        scene = Scene.load(path)
        return scene if keep_padding else _scene_without_padding(scene)
    from voxwarp.io.volumes import load_volume  # the file readers: only for files

    given = {"series": series, "frame_index": frame_index, "channel": channel}
    extra: dict[str, Any] = {k: v for k, v in given.items() if v is not None}
    vol = load_volume(
        path,
        spacing=spacing,
        nan_policy=nan_policy,  # type: ignore[arg-type]
        downsample=downsample,
        axis_order=axis_order,  # type: ignore[arg-type]
        **extra,
    )
    return vol if keep_padding else mask_padding(vol)[0]


#: Keys that make a JSON object without ``"format"`` a scene rather than a raw sidecar.
_SCENE_HINT_KEYS = ("volume", "mode", "warps", "transfer_function", "camera")


def _check_json_input(path: Path) -> None:
    """A JSON INPUT that is not valid JSON, or a scene without its ``"format"`` key, is an
    :class:`InputError` saying so (instead of a hunt for a raw file beside a sidecar)."""
    from voxwarp.scene import SCENE_FORMAT, json_error_text

    try:
        d = read_json(path)
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read {path}: {exc}") from exc
    except ValueError as exc:
        raise InputError(f"{path} is not valid JSON: {json_error_text(exc)}") from exc
    if not isinstance(d, dict) or "format" in d or "dims" in d:
        return  # a scene, another voxwarp file or a raw sidecar: their readers check it
    kind = "wire" if "wires" in d else "lattice" if d.get("type") == "lattice" else ""
    if kind:
        raise InputError(
            f"{path} is a {kind} file, not a volume or a scene; deform a volume with it:"
            f" voxwarp render INPUT --{kind if kind == 'lattice' else 'wires'} {path}"
            " (add --save-scene SCENE.json to keep the result as a scene)"
        )
    hints = [k for k in _SCENE_HINT_KEYS if k in d]
    if hints:
        raise InputError(
            f"{path} looks like a scene JSON (it has {', '.join(hints)}) but lacks"
            f' "format": "{SCENE_FORMAT}"; add that key (Scene.save writes it), or for a'
            ' raw volume give the sidecar its "dims"'
        )


def _scene_without_padding(scene: Any) -> Any:
    """``scene`` on its volume with the padding masked (warps rebound to it)."""
    from voxwarp.core.modality import mask_padding

    vol, count = mask_padding(scene.volume)
    if count == 0:
        return scene
    for warp in scene.warps:
        warp.bind_volume(vol)
    return scene.copy(volume=vol)


#: keys of a wire file (``--wires``) that make its warp entry, and its free notes
WIRE_FILE_KEYS = {"wires", "field_scale", "layout", "masks", "mask_resolution", "dilation"}
FILE_NOTES = {"description", "sample", "type"}


def read_json_option(option: str, path: str | Path) -> Any:
    """The JSON in the file an option names; :class:`InputError` naming the option,
    the file and what is wrong with it otherwise; ``sample:NAME`` is a bundled file."""
    from voxwarp.io.samples import resolve_sample_path

    try:
        path = resolve_sample_path(path)
        return read_json(path)
    except VolumeError as exc:
        raise InputError(f"{option} {path}: {exc}") from exc
    except FileNotFoundError as exc:
        raise InputError(f"{option} {path}: no such file") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{option} {path}: cannot read it ({exc})") from exc
    except ValueError as exc:
        raise InputError(f"{option} {path}: not valid JSON ({exc})") from exc


def load_wire_file(path: str | Path) -> dict[str, Any]:
    """Read a wire file: JSON ``{"wires": [...], "field_scale": ..., ...}``.

    The keys are those of a ``"wires"`` warp in scene JSON (see
    :class:`voxwarp.deform.wires.field.WireFieldWarp`), plus the free-text notes ``description`` and
    ``sample``. Returns the warp entry (``{"type": "wires", ...}``); raises
    :class:`InputError` naming the problem.
    """
    d = read_wire_file(path)
    return {"type": "wires", **{k: v for k, v in d.items() if k in WIRE_FILE_KEYS}}


def read_wire_file(path: str | Path) -> dict[str, Any]:
    """The whole JSON object of a wire file, its notes included, after the checks of
    :func:`load_wire_file` (which builds the warp entry from it)."""
    d = read_json_option("--wires", path)
    if not isinstance(d, dict) or "wires" not in d:
        raise InputError(
            f"--wires {path}: a wire file is a JSON object with a 'wires' list (see"
            " sample_volumes/fish_spine_wires.json)"
        )
    unknown = set(d) - WIRE_FILE_KEYS - FILE_NOTES
    if unknown:
        raise InputError(
            f"--wires {path}: unknown keys {sorted(unknown)}; allowed:"
            f" {sorted(WIRE_FILE_KEYS | FILE_NOTES)}"
        )
    return d


def load_lattice_file(path: str | Path, volume: Any) -> Any:
    """Read a lattice file (a ``"lattice"`` warp entry of scene JSON: ``grid`` with its
    ``nodes``, optional ``box`` (default: the volume's box), ``inverse``, and either
    ``tolerance`` / ``max_iterations`` (Newton steps until a step moves the point by at
    most ``tolerance`` mm) or ``iterations`` (a fixed count); plus the free-text notes
    ``description`` and ``sample``) and build the warp."""
    from voxwarp.deform.lattice.warp import LatticeWarp
    from voxwarp.deform.warp import WarpError

    d = read_json_option("--lattice", path)
    if not isinstance(d, dict) or "grid" not in d:
        raise InputError(
            f"--lattice {path}: a lattice file is a JSON object with a 'grid' ({{'nodes':"
            " [...]}}, see sample_volumes/fish_lattice_bend.json)"
        )
    entry = {k: v for k, v in d.items() if k not in FILE_NOTES}
    entry.setdefault("box", [list(map(float, b)) for b in volume.bounds])
    try:
        return LatticeWarp.from_dict(entry)
    except WarpError as exc:
        raise InputError(f"--lattice {path}: {exc}") from exc
