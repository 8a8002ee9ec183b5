"""The ``voxwarp`` command: the top-level parser, built from one module per command
(each module of :mod:`voxwarp.cli` adds its command with ``add_parser(sub)``), and
:func:`main`, the entry point of the console script and of ``python -m voxwarp``."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import warnings
from collections.abc import Sequence

from voxwarp.cli import (
    animate,
    demo,
    export_field,
    export_volume,
    gui,
    info,
    render,
    reproduce,
    samples,
)
from voxwarp.cli import bench as bench_command
from voxwarp.cli import slice as slice_command
from voxwarp.cli.bench import wants_bench
from voxwarp.cli.options import OneLineErrorParser, VersionAction, join_negative_views
from voxwarp.core import limits
from voxwarp.core.allowed_folders import set_allowed_folders
from voxwarp.errors import VoxwarpError

#: ``voxwarp --help``'s description (the commands and their help lines follow it)
DESCRIPTION = (
    "voxwarp renders 3D volumes (CT, MRI, microscopy) deformed at render time, without"
    " resampling them: mass-spring and 3D ChainMail element grids, wires, trilinear"
    " lattices and registration fields bend what is drawn. INPUT is a volume file or"
    " folder (npy, npz, raw + JSON sidecar, NRRD, NIfTI, DICOM folder, TIFF), a scene JSON"
    " written by --save-scene, or sample:NAME (voxwarp samples lists them). Each command"
    " has its own --help."
)

#: the exit status when stdout's reader has gone (``voxwarp samples | head -1``): 128 +
#: SIGPIPE, what a shell reports for a program that the signal ended
CLOSED_PIPE_EXIT = 141


def build_parser(*, bench: bool = True) -> argparse.ArgumentParser:
    """The argument parser of the ``voxwarp`` command.

    ``bench=False`` leaves out the benchmarks whose modules are heavy to import (``bench
    wires``, ``lattice``, ``interactive``): :func:`main` does so unless a ``bench``
    command runs, which keeps ``voxwarp --help`` and every other command quick to start.
    """
    p = OneLineErrorParser(prog="voxwarp", description=DESCRIPTION)
    p.add_argument("--version", action=VersionAction)
    sub = p.add_subparsers(dest="command", required=True, title="commands", metavar="command")
    info.add_parser(sub)
    render.add_parser(sub)
    animate.add_parser(sub)
    export_field.add_parser(sub)
    slice_command.add_parser(sub)
    export_volume.add_parser(sub)
    demo.add_parser(sub)
    reproduce.add_parser(sub)
    samples.add_parser(sub)
    bench_command.add_parser(sub, bench=bench)
    gui.add_parser(sub)  # after demo: it completes demo NAME --gui
    return p


def _quiet_closed_stdout() -> int:
    """stdout's reader has gone: point stdout at the null device (the interpreter's last
    flush must not fail again), print nothing, return :data:`CLOSED_PIPE_EXIT`."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    return CLOSED_PIPE_EXIT


def _flush_stdout() -> None:
    if sys.stdout is not None:
        sys.stdout.flush()


def _run(argv: Sequence[str] | None, parser: argparse.ArgumentParser) -> int:
    try:
        args = parser.parse_args(join_negative_views(list(sys.argv[1:] if argv is None else argv)))
    except SystemExit:
        _flush_stdout()  # --help into a closed pipe: a BrokenPipeError here, handled by main
        raise
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        old_format = warnings.formatwarning
        warnings.formatwarning = lambda msg, cat, *a, **k: f"voxwarp: warning: {msg}\n"
        try:
            limits.set_memory_budget(getattr(args, "memory_budget", None))
            set_allowed_folders(getattr(args, "allow_dir", None))
            code = int(args.func(args) or 0)
            _flush_stdout()  # a closed pipe shows here, not in the interpreter's last flush
            return code
        except VoxwarpError as exc:  # OutputError too: a write that failed, cleaned up
            print(f"voxwarp: error: {exc}", file=sys.stderr)
            return 2
        except BrokenPipeError:
            raise
        except OSError as exc:  # a file operation outside the checked writers: one line
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"voxwarp: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130
        finally:
            limits.set_memory_budget(None)
            set_allowed_folders(None)
            warnings.formatwarning = old_format


def main(argv: Sequence[str] | None = None, parser: argparse.ArgumentParser | None = None) -> int:
    """Entry point of the ``voxwarp`` console script (and of ``python -m voxwarp``).

    ``argv`` defaults to ``sys.argv[1:]``; ``parser`` replaces :func:`build_parser`'s.
    Errors are one line on stderr and exit status 2; a closed stdout pipe (``voxwarp
    samples | head -1``) ends quietly with :data:`CLOSED_PIPE_EXIT`.
    """
    parser = parser or build_parser(bench=wants_bench(argv))
    try:
        return _run(argv, parser)
    except BrokenPipeError:
        return _quiet_closed_stdout()


if __name__ == "__main__":
    sys.exit(main())
