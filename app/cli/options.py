"""Argument types and option groups that several ``voxwarp`` commands share.

The volume options (``--spacing``, ``--downsample``, ``--memory-budget``, ``--nan`` and
:func:`~voxwarp.cli.render_options.add_input_args`), ``--view``, ``--window``, ``--tf``
and its help, ``--field-convention``, the scene JSON that the export commands read, the
parser whose errors are one line, ``--version``, and the rewrite of ``argv`` that lets
option values start with ``-``. Importing it loads no numpy or Qt (``voxwarp --help``
stays quick).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO, Any, NoReturn

import voxwarp
from voxwarp.cli import render_options as ropt
from voxwarp.core import limits
from voxwarp.core.allowed_folders import ALLOW_DIRS_ENV
from voxwarp.errors import InputError as CliOptionError
from voxwarp.inputs import load_input


def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return math.nan


def mm_arg(option: str) -> Callable[[str], float]:
    """An argparse ``type`` for ``option``: a finite length in mm > 0 (one line otherwise)."""

    def parse(text: str) -> float:
        v = _number(text)
        if not (math.isfinite(v) and v > 0):
            raise argparse.ArgumentTypeError(f"{option} must be a number of mm > 0; got {text!r}")
        return v

    return parse


def fraction_arg(option: str) -> Callable[[str], float]:
    """An argparse ``type`` for ``option``: a number in 0..1 (one line otherwise)."""

    def parse(text: str) -> float:
        v = _number(text)
        if not (math.isfinite(v) and 0.0 <= v <= 1.0):
            raise argparse.ArgumentTypeError(f"{option} must be a number in 0..1; got {text!r}")
        return v

    return parse


__all__ = [
    "NEGATIVE_VALUE_OPTIONS",
    "TF_HELP",
    "WINDOW_HELP",
    "CliOptionError",
    "OneLineErrorParser",
    "VersionAction",
    "add_allow_dir_arg",
    "add_field_convention_arg",
    "add_memory_budget_arg",
    "add_volume_args",
    "downsample_arg",
    "join_negative_views",
    "load_scene_json",
    "tf_arg",
    "view_arg",
    "window_arg",
    "window_pair_arg",
]


def view_arg(text: str) -> Any:
    """``--view``: a view name (``+z``, ``anterior``, ...) or ``AZIMUTH,ELEVATION`` degrees."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.camera import VIEW_NAMES

    if text in VIEW_NAMES:
        return text
    try:
        az, el = (float(v) for v in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"view must be one of {','.join(VIEW_NAMES)} or AZIMUTH,ELEVATION degrees; got {text!r}"
        ) from exc
    return (az, el)


def window_arg(text: str) -> str | tuple[float, float]:
    """``--window NAME|LEVEL,WIDTH``: a preset name (lung, mediastinum, bone, brain,
    percentile; resolved per volume by :func:`voxwarp.core.window_presets.resolve_window`)
    or two numbers in data units with the width > 0."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.window_presets import parse_window

    try:
        return parse_window(text)
    except CliOptionError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def window_pair_arg(text: str) -> str | list[float]:
    """``render --window NAME|LEVEL,WIDTH`` (also written ``--window LEVEL WIDTH``: see
    :func:`join_negative_views`): a preset name, or two numbers as a list (the scene
    checks their values)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.window_presets import PRESET_NAMES

    if text.strip().lower() in PRESET_NAMES:
        return text.strip().lower()
    try:
        level, width = (float(v) for v in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected {', '.join(PRESET_NAMES)} or LEVEL,WIDTH (or LEVEL WIDTH)"
            " in data units, e.g. 40,400"
        ) from exc
    return [level, width]


#: ``--window`` help, the same for ``slice`` and ``render``
WINDOW_HELP = (
    "grey window: a preset (CT in HU: lung -600/1500, mediastinum 40/400, bone 400/1800,"
    " brain 40/80; any volume: percentile) or LEVEL,WIDTH in data units (default: the"
    " scene's, else mediastinum for a CT in HU and the percentile window otherwise)"
)


#: ``--tf`` help, the same wherever it is accepted (one resolver: :func:`tf_arg`).
TF_HELP = (
    "preset (ct-bone, mri, ...), matplotlib colour map (viridis, ...), or a file: voxwarp"
    " or ParaView colour-map JSON, Slicer presets.xml or .vp; FILE:NAME picks one map"
)


def tf_arg(tf: str | None, volume: Any = None) -> Any:
    """``--tf`` (the one resolver): None, a preset or matplotlib colour-map name (kept as
    a name, the scene resolves it for its mode), or a file, ``FILE:NAME`` too (voxwarp,
    ParaView or Slicer; read now against ``volume``)."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.core.transfer_function import TransferFunction, file_spec

    if tf is None or file_spec(tf) is None:
        return tf
    return TransferFunction.load(tf, volume)


def downsample_arg(text: str) -> int | tuple[int, int, int]:
    """argparse type of ``--downsample N`` or ``--downsample NX,NY,NZ``."""
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (1, 3) or min(values) < 1:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected a positive integer N or three NX,NY,NZ, e.g. 2 or 8,1,1"
        )
    return values[0] if len(values) == 1 else (values[0], values[1], values[2])


def add_memory_budget_arg(p: argparse.ArgumentParser) -> None:
    """``--memory-budget SIZE`` (:func:`main` makes it the budget of every load)."""
    p.add_argument(
        "--memory-budget",
        type=limits.size_arg,
        metavar="SIZE",
        help="most memory a volume file's voxels may take, e.g. 2G, 512M or unlimited"
        f" (default {limits.DEFAULT_MEMORY_FRACTION * 100:.0f}%% of the physical memory); checked"
        " before reading",
    )


def add_allow_dir_arg(p: argparse.ArgumentParser) -> None:
    """``--allow-dir DIR`` (repeatable; :func:`main` allows them for every read): folders a
    scene or a detached header may name files in, besides its own folder."""
    p.add_argument(
        "--allow-dir",
        action="append",
        metavar="DIR",
        help="also read files that a scene or a detached NRRD/MetaImage header names in DIR"
        " (repeatable; by default only the naming file's folder, its subfolders and"
        f" ${ALLOW_DIRS_ENV})",
    )


def add_volume_args(p: argparse.ArgumentParser) -> None:
    """How a volume file is read: spacing, downsampling, memory budget, NaNs, axis order, series."""
    p.add_argument(
        "--spacing",
        nargs=3,
        type=limits.spacing_mm,
        metavar=("SX", "SY", "SZ"),
        help=f"voxel size in mm ({limits.MIN_SPACING_MM:g} to {limits.MAX_SPACING_MM:g})",
    )
    p.add_argument(
        "--downsample",
        type=downsample_arg,
        default=1,
        metavar="N|NX,NY,NZ",
        help="reduce by N per axis (or by NX, NY, NZ along x, y, z)",
    )
    add_memory_budget_arg(p)
    add_allow_dir_arg(p)
    p.add_argument(
        "--nan", choices=("raise", "mask"), default="raise", help="NaN/Inf voxels: reject or mask"
    )
    ropt.add_input_args(p)


def add_field_convention_arg(p: Any) -> None:
    """``--field-convention`` of ``render`` and ``info``: voxwarp.io.fields.CONVENTIONS,
    spelled out so that building the parser loads no field reader."""
    p.add_argument(
        "--field-convention",
        choices=("itk", "ras", "voxel"),
        help="what the vectors of a field whose header does not say mean: itk (LPS mm),"
        " ras (RAS mm) or voxel (index units, as voxelmorph); NIfTI intents and NRRD"
        " spaces say it themselves",
    )


def load_scene_json(path: str, command: str) -> Any:
    """The :class:`~voxwarp.scene.Scene` of the scene JSON ``path`` that ``command``
    (``export-field``, ``export-volume``) reads; one line for anything else."""
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.io.samples import resolve_sample_path
    from voxwarp.scene import Scene

    path = str(resolve_sample_path(path))  # sample:NAME: a bundled scene JSON
    scene_path = Path(path)
    if scene_path.suffix.lower() != ".json" or not scene_path.is_file():
        what = "is not a .json file" if scene_path.is_file() else "does not exist"
        raise CliOptionError(
            f"{path} {what}; {command} reads a scene JSON (write one with voxwarp"
            " render INPUT ... --save-scene SCENE.json)"
        )
    scene = load_input(path)
    if not isinstance(scene, Scene):
        raise CliOptionError(f"{path} is not a voxwarp scene JSON (render --save-scene)")
    return scene


def scene_files(scene: Any, scene_path: str) -> list[Path]:
    """The files ``scene`` (read from ``scene_path``) was made from: the scene JSON, its
    volume's, a comparison's fixed volume's and the warps' (e.g. a displacement field)."""
    files = [Path(scene_path)]
    volumes = [scene.volume] + ([scene.comparison.fixed] if scene.comparison is not None else [])
    files += [Path(v.source) for v in volumes if v.source and not v.source.startswith("sample:")]
    for warp in scene.warps:
        d = warp.to_dict() if warp.file_keys else {}
        files += [Path(d[k]) for k in warp.file_keys if isinstance(d.get(k), str)]
    return files


def refuse_overwriting_inputs(out: Path, scene: Any, scene_path: str, option: str = "-o") -> None:
    """Raise a one-line error when ``out`` is one of :func:`scene_files` (writing it would
    destroy what the scene reads, and the scene would then read the result)."""
    if not out.exists():
        return  # a new file: nothing of the scene's there
    for f in scene_files(scene, scene_path):
        if f.exists() and out.samefile(f):  # links and the same file by another name
            raise CliOptionError(
                f"{option} {out} is a file {scene_path} reads ({f}): writing it would destroy"
                " the scene's own input; write to another file"
            )


class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line: ``PROG: error: MESSAGE (see PROG
    --help)``, exit code 2, instead of argparse's usage block followed by the error.
    Subcommand parsers inherit it (``add_subparsers`` uses the parent's class). Unlike
    argparse's, it lets a closed pipe's :class:`BrokenPipeError` through (``voxwarp --help
    | head -1``), so that :func:`voxwarp.cli.main.main` ends every command alike then."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")

    def _print_message(self, message: str, file: IO[str] | None = None) -> None:
        stream = file or sys.stderr
        if not message or stream is None:  # no stream at all under pythonw
            return
        try:
            stream.write(message)
        except BrokenPipeError:
            raise
        except OSError:  # as argparse: a stream that fails otherwise is ignored
            pass


class VersionAction(argparse.Action):
    """``--version``: prints the installed version, which it looks up only when asked
    (``importlib.metadata`` is slow to import, and every command builds the parser)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.setdefault("help", "show the version and exit")
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> NoReturn:
        print(f"voxwarp {voxwarp.__version__}")  # read from the metadata only now
        parser.exit()


#: options whose value may start with "-" (a negative number or "-y"): joined as --opt=value
NEGATIVE_VALUE_OPTIONS = (
    "--view",
    "--stiffness-from-volume",
    "--cut",
    "--join",
    "--clip",
    "--drag-at",
    "--plane",
)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def join_negative_views(argv: Sequence[str]) -> list[str]:
    """``argv`` as the parser reads it (:func:`voxwarp.cli.main.main` does this first): a
    value that starts with "-" joined to its option (``--view -y`` -> ``--view=-y``;
    argparse would take ``-y`` for an option), and ``--window LEVEL WIDTH`` (two numbers)
    joined into ``--window=LEVEL,WIDTH``, the one form every ``--window`` parses."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        value = argv[i + 1] if i + 1 < len(argv) else None
        if (
            argv[i] == "--window"
            and value is not None
            and i + 2 < len(argv)
            and _is_number(value)
            and _is_number(argv[i + 2])
        ):
            out.append(f"--window={value},{argv[i + 2]}")
            i += 3
            continue
        negative = value is not None and value.startswith("-")
        if negative and argv[i] in (*NEGATIVE_VALUE_OPTIONS, "--window"):
            out.append(f"{argv[i]}={value}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out
