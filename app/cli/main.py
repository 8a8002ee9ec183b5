"""The ``voxwarp`` command line: info, render, demo, samples, bench.

INPUT is a volume file or folder (npy, npz, raw + JSON sidecar, NRRD, NIfTI, DICOM
folder, TIFF), a scene JSON written by ``Scene.save``, or ``sample:NAME`` for a
bundled sample (``voxwarp samples`` lists them).
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, NamedTuple, NoReturn

from voxwarp.cli import render_options as ropt
from voxwarp.cli.animate import add_animate_parser
from voxwarp.cli.export_volume import add_export_volume_parser
from voxwarp.cli.slice import add_slice_parser
from voxwarp.core import limits
from voxwarp.core.checks import image_size as _size
from voxwarp.core.modes import MODES
from voxwarp.errors import InputError as CliOptionError
from voxwarp.errors import VoxwarpError
from voxwarp.inputs import load_input, load_lattice_file, load_wire_file


def _view(text: str) -> Any:
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


# ---------------------------------------------------------------------- mass-spring options
#: Steps ``render --massspring`` runs without ``--settle`` (and no ``--steps``). With the
#: CLI's defaults (semi-implicit, shear springs, dt ~ 24 ms) an 8³ grid is settled after
#: about 600 steps and a 16³ grid within ~5 % of the dragged distance after 1000.
MASSSPRING_STEPS = 1000
#: Most steps ``--settle`` runs when ``--steps`` is not given.
MASSSPRING_SETTLE_MAX_STEPS = 20000
#: ``--settle`` stops once every element is slower than this (mm/s).
MASSSPRING_SETTLE_TOL = 1e-3


class _Drag(tuple):
    """One ``--drag I,J,K:DX,DY,DZ``: ``(text, (i, j, k), (dx, dy, dz))``, or one
    ``--drag-at`` resolved to its element: ``(text, (i, j, k), (dx, dy, dz), "--drag-at")``."""

    @property
    def flag(self) -> str:
        return self[3] if len(self) > 3 else "--drag"

    @property
    def text(self) -> str:
        return self[0]

    @property
    def index(self) -> tuple[int, int, int]:
        return self[1]

    @property
    def offset(self) -> tuple[float, float, float]:
        return self[2]


def _grid_shape(text: str) -> tuple[int, int, int]:
    from voxwarp.deform.elements.grid import MAX_ELEMENTS_PER_AXIS as hi
    from voxwarp.deform.elements.grid import MIN_ELEMENTS_PER_AXIS as lo

    form = f"N or NX,NY,NZ elements per axis ({lo}..{hi}), e.g. 16 or 16,8,8"
    try:
        vals = tuple(int(v) for v in text.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    if any(not lo <= v <= hi for v in vals):
        raise argparse.ArgumentTypeError(f"{text!r}: out of range; expected {form}")
    return vals  # type: ignore[return-value]


def _drag(text: str) -> _Drag:
    form = "I,J,K:DX,DY,DZ (element index, then its offset in mm along x, y, z), e.g. 6,4,4:0,12,0"
    try:
        left, right = text.split(":")
        idx = tuple(int(v) for v in left.split(","))
        off = tuple(float(v) for v in right.split(","))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(idx) != 3 or len(off) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    if not all(math.isfinite(v) for v in off):
        raise argparse.ArgumentTypeError(f"{text!r}: offsets must be finite mm; expected {form}")
    if max(abs(v) for v in off) > limits.MAX_DRAG_MM:
        raise argparse.ArgumentTypeError(
            f"{text!r}: offsets must be at most {limits.MAX_DRAG_MM:g} mm (the displacement"
            " texture's range); check the units (mm expected)"
        )
    return _Drag((text, idx, off))


def _fix(text: str) -> tuple[str, tuple[tuple[int, int], ...]]:
    form = "I,J,K with each an index or a range A..B, e.g. 3,4,4 or 0..1,0..7,0..7"
    ranges = []
    try:
        parts = text.split(",")
        for part in parts:
            a, _, b = part.partition("..")
            lo, hi = int(a), int(b if b else a)
            if lo < 0 or hi < lo:
                raise ValueError(part)
            ranges.append((lo, hi))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(ranges) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    return text, tuple(ranges)


class _Cut(tuple):
    """One ``--cut PX,PY,PZ:NX,NY,NZ[:RADIUS]``: ``(text, point, normal, radius)``."""

    @property
    def text(self) -> str:
        return self[0]

    @property
    def point(self) -> tuple[float, float, float]:
        return self[1]

    @property
    def normal(self) -> tuple[float, float, float]:
        return self[2]

    @property
    def radius(self) -> float | None:
        return self[3]


def _cut(text: str) -> _Cut:
    form = (
        "PX,PY,PZ:NX,NY,NZ[:RADIUS] (a point on the cutting plane in world mm, its normal,"
        " optionally the radius in mm of the disk on it that cuts), e.g. 48,24,20:1,0,0"
    )
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError(text)
        point = tuple(float(v) for v in parts[0].split(","))
        normal = tuple(float(v) for v in parts[1].split(","))
        radius = float(parts[2]) if len(parts) == 3 else None
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if len(point) != 3 or len(normal) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    values = [*point, *normal, *([] if radius is None else [radius])]
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: numbers must be finite; expected {form}")
    if not any(normal):
        raise argparse.ArgumentTypeError(f"{text!r}: the normal must not be 0,0,0; expected {form}")
    if radius is not None and radius <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: the radius must be > 0 mm; expected {form}")
    return _Cut((text, point, normal, radius))


def _relax(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected a number of relaxation steps >= 0, e.g. 4"
        )
    if n > limits.MAX_RELAX_STEPS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: at most {limits.MAX_RELAX_STEPS} relaxation steps (each smooths the"
            " whole grid); a few (e.g. 4) smooth a drag"
        )
    return n


def _stiffness_points(text: str) -> list[tuple[float, float]]:
    form = (
        "VALUE:STIFFNESS[,VALUE:STIFFNESS...] in data units and 0..1, e.g. 100:0.2,400:0.95"
        " (write --stiffness-from-volume=-500:0.1,... for a negative first value)"
    )
    try:
        pts = [tuple(float(v) for v in pair.split(":")) for pair in text.split(",")]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}") from exc
    if not pts or any(len(p) != 2 or not all(math.isfinite(v) for v in p) for p in pts):
        raise argparse.ArgumentTypeError(f"{text!r}: expected {form}")
    if any(not 0.0 <= s <= 1.0 for _, s in pts):
        raise argparse.ArgumentTypeError(f"{text!r}: stiffnesses must be in 0..1; expected {form}")
    if len({v for v, _ in pts}) != len(pts):
        raise argparse.ArgumentTypeError(f"{text!r}: values must differ; expected {form}")
    return pts  # type: ignore[return-value]


def _steps(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = -1
    if n < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a step count >= 0, e.g. 1000")
    if n > limits.MAX_MASSSPRING_STEPS:
        raise argparse.ArgumentTypeError(
            f"{text!r}: at most {limits.MAX_MASSSPRING_STEPS} steps; use --settle to stop"
            " once the grid is at rest"
        )
    return n


def _grid_text(shape: Sequence[int]) -> str:
    return "x".join(str(n) for n in shape)


#: the options of ``render``'s deformation models, in the order of ``--help``: (flag,
#: attribute, the model that takes it: "both", "massspring" or "chainmail")
_DEFORM_OPTIONS: tuple[tuple[str, str, str], ...] = (
    ("--drag", "drag", "both"),
    ("--drag-at", "drag_at", "both"),
    ("--fix", "fix", "both"),
    ("--backend", "backend", "both"),
    ("--inverse", "inverse", "both"),
    ("--stiffness-from-volume", "stiffness_from_volume", "both"),
    ("--settle", "settle", "massspring"),
    ("--steps", "steps", "massspring"),
    ("--integrator", "integrator", "massspring"),
    ("--shear/--no-shear", "shear", "massspring"),
    ("--bend", "bend", "massspring"),
    ("--relax", "relax", "chainmail"),
    ("--variant", "variant", "chainmail"),
    ("--cut", "cut", "chainmail"),
)
#: why a mass-spring option does not apply to ChainMail
_NOT_FOR_CHAINMAIL: dict[str, str] = {
    "settle": "ChainMail settles each drag at once; --relax K smooths it",
    "steps": "ChainMail settles each drag at once; --relax K smooths it",
    "integrator": "ChainMail has no time steps",
    "shear": "ChainMail's shear limits follow the stiffness",
    "bend": "ChainMail has no bend springs",
}


def _given(args: argparse.Namespace, attr: str) -> bool:
    return getattr(args, attr) is not None  # every deformation option defaults to None


def _deform_model(args: argparse.Namespace) -> str | None:
    """``"massspring"``, ``"chainmail"`` or None (no deformation)."""
    if args.massspring is not None:
        return "massspring"
    if args.chainmail is not None:
        return "chainmail"
    return None


def _check_deform_options(args: argparse.Namespace) -> None:
    """Option checks that need no volume: deformation options without their model, both
    models at once, options of the other model, drags and fixes outside the grid, drags
    of a fixed element or of one element twice."""
    import numpy as np

    if args.massspring is not None and args.chainmail is not None:
        raise CliOptionError(
            "--massspring and --chainmail cannot be combined: deform with one model per"
            " render (a scene JSON saved with --save-scene can be rendered again with the"
            " other, which then deforms the result)"
        )
    _check_wire_options(args)
    _check_lattice_options(args)
    model = _deform_model(args)
    for opt, attr, owner in _DEFORM_OPTIONS:
        if not _given(args, attr) or owner in ("both", model):
            continue
        if model is None and owner == "chainmail":
            raise CliOptionError(
                f"{opt} needs --chainmail: add --chainmail N (the element grid over the"
                " volume, e.g. --chainmail 16)"
            )
        if model is None:
            raise CliOptionError(
                f"{opt} needs --massspring: add --massspring N (the element grid over the"
                " volume, e.g. --massspring 16)"
            )
        if model == "chainmail":
            raise CliOptionError(
                f"{opt} is a mass-spring option (--massspring) and does not apply to"
                f" --chainmail: {_NOT_FOR_CHAINMAIL[attr]}"
            )
        raise CliOptionError(
            f"{opt} is a ChainMail option (--chainmail) and does not apply to"
            " --massspring; deform with --chainmail N instead to use it"
        )
    if model is None:
        for opt, attr, _ in _DEFORM_OPTIONS:
            if _given(args, attr):  # an option of both models
                raise CliOptionError(
                    f"{opt} needs --massspring: add --massspring N (the element grid over"
                    " the volume, e.g. --massspring 16) or --chainmail N (3D ChainMail)"
                )
        return
    shape = args.massspring if model == "massspring" else args.chainmail
    grid = _grid_text(shape)
    if len(set(shape)) == 1:
        ranges_text = f"indices run 0..{shape[0] - 1}"
    else:
        ranges_text = "indices run " + ", ".join(f"0..{n - 1}" for n in shape) + " (i, j, k)"
    fixed = np.zeros(shape, dtype=bool)
    fixed[:: shape[0] - 1, :: shape[1] - 1, :: shape[2] - 1] = True
    for text, ranges in args.fix or []:
        if any(hi >= n for (_, hi), n in zip(ranges, shape, strict=True)):
            raise CliOptionError(f"--fix {text}: reaches outside the {grid} grid; {ranges_text}")
        fixed[tuple(slice(lo, hi + 1) for lo, hi in ranges)] = True
    seen: dict[tuple[int, int, int], str] = {}
    for d in args.drag or []:
        if any(not 0 <= v < n for v, n in zip(d.index, shape, strict=True)):
            raise CliOptionError(
                f"{d.flag} {d.text}: element {d.index} is outside the {grid} grid; {ranges_text}"
            )
        if fixed[d.index]:
            corner = all(v in (0, n - 1) for v, n in zip(d.index, shape, strict=True))
            what = (
                f"a corner of the {grid} grid (corners stay fixed)" if corner else "fixed by --fix"
            )
            raise CliOptionError(
                f"{d.flag} {d.text}: element {d.index} is {what}; drag an element that is not fixed"
            )
        if d.index in seen:
            raise CliOptionError(
                f"{d.flag} {d.text}: element {d.index} is already dragged by"
                f" {seen[d.index]}; give each element once"
            )
        seen[d.index] = f"{d.flag} {d.text}"


def _check_lattice_options(args: argparse.Namespace) -> None:
    """--lattice deforms alone (one deformation per render on the command line)."""
    if args.lattice is None:
        return
    if args.wires is not None or _deform_model(args) is not None:
        raise CliOptionError(
            "--lattice cannot be combined with --wires, --massspring or --chainmail in one"
            " render: save one with --save-scene and render that scene with the other"
        )


def _check_wire_options(args: argparse.Namespace) -> None:
    """--wires cannot be combined with a model; its options need it."""
    if args.wires is None:
        for opt, attr in (("--field-scale", "field_scale"), ("--layout", "layout")):
            if getattr(args, attr) is not None:
                raise CliOptionError(f"{opt} needs --wires FILE (a wire file, see --help)")
        if args.masks is not None:
            raise CliOptionError("--masks/--no-masks needs --wires FILE (a wire file)")
        return
    if _deform_model(args) is not None:
        raise CliOptionError(
            "--wires cannot be combined with --massspring or --chainmail in one render:"
            " save one with --save-scene and render that scene with the other"
        )


def _wire_warp(args: argparse.Namespace, volume: Any) -> tuple[Any, str]:
    """The wire warp of --wires on ``volume``, built, and a one-line summary."""
    from voxwarp.deform.warp import WarpError
    from voxwarp.deform.wires.field import WireFieldWarp

    entry = load_wire_file(args.wires)
    if args.field_scale is not None:
        entry["field_scale"] = args.field_scale
    if args.layout is not None:
        entry["layout"] = args.layout
    if args.masks is not None:
        entry["masks"] = args.masks
    try:
        warp = WireFieldWarp.from_dict(entry)
        warp.bind_volume(volume)
    except WarpError as exc:
        raise CliOptionError(f"--wires {args.wires}: {exc}") from exc
    st = warp.deformer.stats
    assert st is not None
    summary = (
        f"wires: {len(warp.wires)} wire(s), field {'x'.join(map(str, st.field_shape))}"
        f" (1:{st.field_scale**3}, {st.layout}), {st.planes - st.planes_dropped} planes"
        f" ({st.mask_bytes_total} bytes of masks), {st.swept} voxels swept,"
        f" {st.percent_ignored:.1f}% ignored,"
        f" built in {st.timings['total']:.2f} s ({st.backend})"
    )
    return warp, summary


def _deform_grid(args: argparse.Namespace, volume: Any) -> Any:
    """The element grid of ``render --massspring`` / ``--chainmail`` over ``volume``
    (None without either): fixed elements and materials set, drags checked against
    rigid elements (mass-spring) and cutting planes against the grid (ChainMail), all
    before any GL work."""
    model = _deform_model(args)
    if model is None:
        return None
    import numpy as np

    from voxwarp.deform.elements.grid import ElementGrid, ElementGridError

    grid = ElementGrid(volume, shape=args.massspring if model == "massspring" else args.chainmail)
    if args.drag_at:  # to the nearest elements, then checked as --drag elements are
        picks = ropt.pick_elements(grid, args.drag_at)
        for pick in picks:
            print(pick.summary(), file=sys.stderr)
        args.drag = [
            *(args.drag or []),
            *(_Drag((k.drag.text, k.index, k.drag.offset, "--drag-at")) for k in picks),
        ]
        args.drag_at = None
        _check_deform_options(args)
    for _, ranges in args.fix or []:
        mask = np.zeros(grid.shape, dtype=bool)
        mask[tuple(slice(lo, hi + 1) for lo, hi in ranges)] = True
        grid.fix(mask)
    if args.stiffness_from_volume:
        # the voxel centres span origin .. origin + spacing * (shape - 1)
        org = np.asarray(volume.origin, dtype=np.float64)
        n = np.maximum(np.asarray(volume.shape) - 1, 1)
        centres = (org, org + np.asarray(volume.spacing, dtype=np.float64) * n)
        try:
            grid.materials_from_volume(volume.data, centres, args.stiffness_from_volume)
        except ElementGridError as exc:
            raise CliOptionError(f"--stiffness-from-volume: {exc}") from exc
    if model == "massspring":
        rigid = grid.pinned()
        for d in args.drag or []:
            if rigid[d.index]:
                raise CliOptionError(
                    f"{d.flag} {d.text}: element {d.index} is rigid (stiffness 1 from"
                    " --stiffness-from-volume) and cannot move; drag another element or"
                    " map its value to a stiffness below 1"
                )
    for c in args.cut or []:
        if not _cut_crosses(grid, c):
            lo, hi = grid.lo, grid.hi
            box = ", ".join(f"{a} {lo[i]:g}..{hi[i]:g}" for i, a in enumerate("xyz"))
            where = "plane" if c.radius is None else f"disk of radius {c.radius:g} mm"
            raise CliOptionError(
                f"--cut {c.text}: the {where} crosses no link of the"
                f" {_grid_text(grid.shape)} grid, whose elements span {box} mm; give a"
                " point inside that box (world mm, as --drag offsets)"
            )
    return grid


def _cut_crosses(grid: Any, cut: _Cut) -> bool:
    """Whether ``cut`` removes a link of ``grid`` at rest (the test of ChainMail.cut)."""
    import numpy as np

    p0 = np.asarray(cut.point, dtype=np.float64)
    normal = np.asarray(cut.normal, dtype=np.float64)
    x = grid.rest_positions
    s = (x - p0) @ (normal / np.linalg.norm(normal))
    for axis in range(3):
        sa = np.moveaxis(s, axis, 0)[:-1]
        sb = np.moveaxis(s, axis, 0)[1:]
        cross = ((sa < 0) & (sb >= 0)) | ((sb < 0) & (sa >= 0))
        if cut.radius is not None and np.any(cross):
            xa = np.moveaxis(x, axis, 0)[:-1]
            xb = np.moveaxis(x, axis, 0)[1:]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(cross, sa / (sa - sb), 0.0)
            hit = xa + t[..., None] * (xb - xa)
            cross &= np.linalg.norm(hit - p0, axis=-1) <= cut.radius
        if np.any(cross):
            return True
    return False


def _run_massspring(args: argparse.Namespace, grid: Any, ctx: Any) -> tuple[Any, str]:
    """Build, drag and run the mass-spring model of ``render --massspring`` on ``grid``.

    Returns the :class:`~voxwarp.deform.elements.massspring.MassSpring` and a one-line summary.
    """
    from voxwarp.deform.elements.massspring import MassSpring, MassSpringError
    from voxwarp.deform.warp import WarpError

    backend = args.backend or "cpu"
    try:
        ms = MassSpring(
            grid,
            backend=backend,
            ctx=ctx if backend == "gpu" else None,
            integrator=args.integrator or "semi-implicit",
            shear=True if args.shear is None else args.shear,
            bend=bool(args.bend),
        )
    except MassSpringError as exc:
        raise CliOptionError(f"--massspring: {exc}") from exc
    try:
        for d in args.drag or []:
            ms.move(d.index, d.offset)
        if args.settle:
            limit = MASSSPRING_SETTLE_MAX_STEPS if args.steps is None else args.steps
            steps = ms.settle(max_steps=limit, tol=MASSSPRING_SETTLE_TOL)
            how = f"{steps} steps"
            if steps >= limit and limit > 0:
                warnings.warn(
                    f"--settle stopped at the limit of {limit} steps; the grid may still"
                    " be moving: raise --steps",
                    RuntimeWarning,
                    stacklevel=1,
                )
            else:
                how += f" (settled: every element slower than {MASSSPRING_SETTLE_TOL:g} mm/s)"
        else:
            steps = MASSSPRING_STEPS if args.steps is None else args.steps
            ms.step(steps)
            how = f"{steps} steps"
        ms.warp(inverse=args.inverse or "baked")
    except WarpError as exc:  # e.g. displacements beyond the texture's range
        ms.close()
        raise CliOptionError(f"--massspring: {exc}") from exc
    except BaseException:
        ms.close()
        raise
    summary = (
        f"massspring: {_grid_text(grid.shape)} {backend} {ms.integrator}, dt {ms.dt:.3g} s,"
        f" {len(args.drag or [])} dragged, {how}"
    )
    return ms, summary


def _run_chainmail(args: argparse.Namespace, grid: Any, ctx: Any) -> tuple[Any, str]:
    """Build, cut, drag and relax the ChainMail model of ``render --chainmail``.

    Cuts come first (through the rest state), then all ``--drag`` elements move at once
    (one :meth:`~voxwarp.deform.elements.chainmail.ChainMail.move`), then ``--relax`` steps (also
    saved
    as the model's ``relax_steps``). Returns the
    :class:`~voxwarp.deform.elements.chainmail.ChainMail`
    and a one-line summary.
    """
    import time

    import numpy as np

    from voxwarp.deform.elements.chainmail import ChainMail, ChainMailError

    backend = args.backend or "cpu"
    relax = args.relax or 0
    drags = args.drag or []
    try:
        cm = ChainMail(
            grid,
            variant=args.variant or "enhanced",
            backend=backend,
            ctx=ctx if backend == "gpu" else None,
        )
    except ChainMailError as exc:
        raise CliOptionError(f"--chainmail: {exc}") from exc
    try:
        cut = sum(cm.cut(c.point, c.normal, c.radius) for c in args.cut or [])
        if backend == "cpu":  # load the numba kernels outside the timed move: no element
            cm.move(np.zeros(grid.shape, dtype=bool), (0.0, 0.0, 0.0))
        touched, solve_ms = 0, 0.0
        if drags:
            stats = cm.move([d.index for d in drags], [d.offset for d in drags])
            touched, solve_ms = stats.touched, stats.seconds * 1000
            if stats.limited:
                what = (
                    f"{drags[0].flag} {drags[0].text}"
                    if len(drags) == 1
                    else "the dragged elements"
                )
                warnings.warn(
                    f"{what} went only {stats.fraction:.0%} of the way: the links between"
                    " the dragged and the fixed elements (the 8 corners always are fixed)"
                    " ran out of slack; fix fewer elements or drag less",
                    RuntimeWarning,
                    stacklevel=1,
                )
        t = time.perf_counter()
        cm.relax(relax)
        relax_ms = (time.perf_counter() - t) * 1000
        cm.relax_steps = relax  # saved with the model: a resumed one relaxes alike
        cm.warp(inverse=args.inverse or "baked")
        displaced = int(np.count_nonzero(np.any(cm.displacements() != 0.0, axis=-1)))
    except BaseException:
        cm.close()
        raise
    moved = (
        f"{touched} elements touched in {solve_ms:.1f} ms"
        if backend == "cpu"
        else f"solved in {solve_ms:.1f} ms"
    )
    summary = f"chainmail: {_grid_text(grid.shape)} {backend} {cm.variant}, {len(drags)} dragged"
    summary += f", {moved}"
    if relax:
        summary += f", relax {relax} step{'s' * (relax != 1)} in {relax_ms:.1f} ms"
    if args.cut:
        summary += f", {cut} links cut"
    summary += f"; {displaced} elements displaced"
    return cm, summary


def _downsample(text: str) -> int | tuple[int, int, int]:
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


def _add_volume_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--spacing", nargs=3, type=float, metavar=("SX", "SY", "SZ"), help="voxel size in mm"
    )
    p.add_argument(
        "--downsample",
        type=_downsample,
        default=1,
        metavar="N|NX,NY,NZ",
        help="reduce by N per axis (or by NX, NY, NZ along x, y, z)",
    )
    add_memory_budget_arg(p)
    p.add_argument(
        "--nan", choices=("raise", "mask"), default="raise", help="NaN/Inf voxels: reject or mask"
    )
    ropt.add_input_args(p)


def _scene_from_args(obj: Any, args: argparse.Namespace) -> Any:
    from voxwarp.scene import Scene

    tf = _tf_arg(args.tf, obj.volume if isinstance(obj, Scene) else obj)
    if isinstance(obj, Scene):
        changes: dict[str, Any] = {}
        if tf is not None:
            changes["transfer_function"] = tf  # resolved by the scene, knowing the mode
        for key in ("mode", "projection", "view", "step", "window", "seed", "iso_value", "zoom"):
            val = getattr(args, key)
            if val is not None:
                changes[key] = val
        if args.jitter is not None:
            changes["jitter"] = args.jitter
        if args.shading is not None:
            changes["shading"] = args.shading
        if changes.keys() & {"view", "projection", "zoom"}:
            changes["camera"] = None
        return obj.copy(**changes)
    kw: dict[str, Any] = {
        "mode": args.mode or "dvr",
        "transfer_function": tf,  # None: the modality's default
        "view": args.view,
        "projection": args.projection or "perspective",
        "step": args.step if args.step is not None else 1.0,
        "window": args.window,
        "jitter": True if args.jitter is None else args.jitter,
        "seed": args.seed if args.seed is not None else 0,
        "shading": args.shading,
        "iso_value": args.iso_value,
        "zoom": args.zoom if args.zoom is not None else 1.0,
    }
    return Scene(obj, **kw)


def _tf_arg(tf: str | None, volume: Any = None) -> Any:
    """``--tf`` (the one resolver): None, a preset or matplotlib colour-map name (kept as
    a name, the scene resolves it for its mode), or a file, ``FILE:NAME`` too (voxwarp,
    ParaView or Slicer; read now against ``volume``)."""
    from voxwarp.core.transfer_function import TransferFunction, file_spec

    if tf is None or file_spec(tf) is None:
        return tf
    return TransferFunction.load(tf, volume)


def cmd_info(args: argparse.Namespace) -> int:
    """``voxwarp info INPUT``: dims, dtype, spacing, value range, histogram."""
    from voxwarp.io.fields import field_info, field_summary, is_field_file, load_transform
    from voxwarp.io.volumes import dicom_series, volume_info, volume_summary
    from voxwarp.scene import Scene

    if is_field_file(args.input):  # a registration result, not a volume
        warps = load_transform(args.input, convention=args.field_convention)
        text = json.dumps([field_info(w) for w in warps], indent=2)
        print(text if args.json else field_summary(warps))
        return 0
    # info shows the file's values: padding kept
    obj = load_input(args.input, keep_padding=True, **ropt.load_options(args))
    vol = obj.volume if isinstance(obj, Scene) else obj
    series = dicom_series(args.input) if os.path.isdir(args.input) else []
    if args.json:
        info = volume_info(vol)
        if series:
            info["dicom_series"] = [dataclasses.asdict(s) for s in series]
        print(json.dumps(info, indent=2))
        return 0
    print(volume_summary(vol))
    if len(series) > 1:
        chosen = str(getattr(args, "series", None) or 1)
        print("DICOM series in this folder (choose with --series N or --series UID):")
        for s in series:
            mark = "*" if chosen in (str(s.index), s.uid) else " "
            print(f" {mark} {s.line()}")
    return 0


def _check_distinct_outputs(args: argparse.Namespace) -> None:
    """``-o``, ``--save-scene`` and ``--save-camera`` must name different files (one
    would overwrite the other); checked before anything is rendered."""
    named = [
        (flag, getattr(args, attr, None))
        for flag, attr in (
            ("-o", "output"),
            ("--save-scene", "save_scene"),
            ("--save-camera", "save_camera"),
        )
    ]
    seen: dict[str, str] = {}
    for flag, value in named:
        if value is None:
            continue
        key = os.path.normcase(os.path.realpath(os.path.expanduser(os.fspath(value))))
        if key in seen:
            raise CliOptionError(
                f"{seen[key]} and {flag} both name {value}; give each output its own file"
                " (e.g. -o image.png --save-scene scene.json)"
            )
        seen[key] = flag


class PendingDeformation(NamedTuple):
    """The deformation options of ``render`` (and ``slice``) prepared before any GL work:
    the element grid of ``--massspring``/``--chainmail`` and the warp of ``--wires`` or
    ``--lattice`` (None when not given)."""

    grid: Any
    file_warp: Any


def prepare_deformation(args: argparse.Namespace, scene: Any) -> tuple[Any, PendingDeformation]:
    """``scene`` with the ``--displacement`` fields in its chain, and the model grid and
    file warp still to add (:func:`deformed_scene`); every check that needs no GL runs
    here, so bad options fail before a context is made."""
    fields = _field_warps(args)
    for w in fields:
        w.bind_volume(scene.volume)  # a field that misses the volume warns
    if fields:  # nearest the displayed (fixed) space; the models act in the volume's
        scene = scene.copy(warps=[*fields, *scene.warps])
    grid = _deform_grid(args, scene.volume)
    file_warp = None  # --wires or --lattice (they exclude each other)
    if args.wires is not None:  # built before any GL work: bad wires fail fast
        file_warp, summary = _wire_warp(args, scene.volume)
        print(summary, file=sys.stderr)
    if args.lattice is not None:
        file_warp = load_lattice_file(args.lattice, scene.volume)
    return scene, PendingDeformation(grid, file_warp)


@contextlib.contextmanager
def deformed_scene(
    args: argparse.Namespace, scene: Any, pending: PendingDeformation, ctx: Any
) -> Iterator[Any]:
    """The finished scene: the model of ``pending`` run on ``ctx`` (current) and its warp
    last in the chain, then the file warp, then the clip/camera options; the model is
    closed when the block ends."""
    model = None
    try:
        if pending.grid is not None:
            run = _run_massspring if args.massspring is not None else _run_chainmail
            model, summary = run(args, pending.grid, ctx)
            print(summary, file=sys.stderr)
            # last in the chain: it deforms the volume itself, before the
            # scene's own warps move the result
            scene = scene.copy(warps=[*scene.warps, model.warp()])
        if pending.file_warp is not None:
            scene = scene.copy(warps=[*scene.warps, pending.file_warp])
        yield ropt.apply_render_options(scene, args)  # every warp is in place
    finally:
        if model is not None:
            model.close()


def cmd_render(args: argparse.Namespace) -> int:
    """``voxwarp render INPUT -o out.png``: render one image headless."""
    from voxwarp.io.images import check_image_format, write_image
    from voxwarp.render.offscreen import OffscreenRenderer

    _check_deform_options(args)
    ropt.check_render_options(args)
    _check_distinct_outputs(args)
    check_image_format(args.output)  # a bad -o fails before any work or other output
    obj = load_input(args.input, keep_padding=args.keep_padding, **ropt.load_options(args))
    scene, pending = prepare_deformation(args, _scene_from_args(obj, args))
    out = Path(args.output)
    dtype = "f4" if out.suffix.lower() in (".exr", ".hdr") else "u1"
    with OffscreenRenderer(*args.size, dtype=dtype) as r:
        # one frame: the per-cell octant distance maps (CPU-built) cost more than they
        # save on a single draw, so skip by 4³ blocks (the same image; docs/benchmarks.md);
        # likewise the gradient texture (a pass over every voxel) for shading
        r.renderer.cell_skipping = False
        r.renderer.gradient_texture = False
        # the GPU backends run on the renderer's context (made current here)
        with r.current(), deformed_scene(args, scene, pending, r.ctx) as scene:
            img = r.render(scene)
            if args.save_scene:  # inside: a GPU-owned field is read back to save it
                scene.save(args.save_scene)
    # what was chosen, once the image exists (a refused render prints only its error)
    print(scene.display_note(), file=sys.stderr)
    ropt.spacing_notice(scene.volume, args)
    if args.marker:  # the orientation triad (R/L, A/P, S/I letters when oriented)
        from voxwarp.render.orientation_marker import draw_scene_marker

        draw_scene_marker(img, scene)
    write_image(out, img)
    ropt.save_camera(scene, args)
    if args.save_scene:
        print(f"scene: {args.save_scene}")
    print(out)
    return 0


def load_scene_json(path: str, command: str) -> Any:
    """The :class:`~voxwarp.scene.Scene` of the scene JSON ``path`` that ``command``
    (``export-field``, ``export-volume``) reads; one line for anything else."""
    from voxwarp.scene import Scene

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


def cmd_export_field(args: argparse.Namespace) -> int:
    """``voxwarp export-field SCENE.json -o field.nii.gz``: the scene's warp chain as a
    displacement field in the ITK convention (:meth:`voxwarp.scene.Scene.displacement_field`)."""
    from voxwarp.io.fields import WRITE_SUFFIXES, field_suffix, save_displacement_field

    out = Path(args.output)
    if field_suffix(out) not in WRITE_SUFFIXES:
        raise CliOptionError(
            f"-o {out}: cannot write a displacement field as {field_suffix(out) or '(no suffix)'};"
            f" use one of {', '.join(WRITE_SUFFIXES)}"
        )
    scene = load_scene_json(args.scene, "export-field")
    box = None if args.box is None else (args.box[:3], args.box[3:])
    if not scene.warps:
        warnings.warn(f"{args.scene} has no warps: the exported field is zero", stacklevel=1)
    field = scene.displacement_field(spacing=args.spacing, box=box)
    save_displacement_field(field, out)
    grid = "x".join(str(n) for n in field.shape)
    spacing = " x ".join(f"{s:g}" for s in field.spacing)
    print(
        f"field: {grid} nodes, spacing {spacing} mm, max |u| {field.max_displacement():.3g} mm"
        f" ({len(scene.warps)} warp(s); ITK pull-back, LPS vectors)",
        file=sys.stderr,
    )
    print(out)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """``voxwarp demo NAME``: a teaching demo's figure sheet (:mod:`voxwarp.teaching.demos`);
    ``voxwarp demo [INPUT]``: render INPUT (default the bundled sample) in every mode
    into a folder."""
    from voxwarp.teaching.demos import DEMOS

    if args.input in DEMOS:
        return _teaching_demo(args)
    if args.quick or args.gui:
        raise CliOptionError(
            f"--quick and --gui are options of the teaching demos ({', '.join(DEMOS)}),"
            " e.g. voxwarp demo massspring --quick"
        )
    if (
        args.input is not None
        and not args.input.startswith("sample:")
        and not Path(args.input).exists()
    ):
        raise CliOptionError(
            f"{args.input!r} is neither a demo ({', '.join(DEMOS)}) nor a volume file or"
            " folder; e.g. voxwarp demo massspring, or voxwarp demo sample:fish"
        )
    return _demo_volume(args)


def _teaching_demo(args: argparse.Namespace) -> int:
    """``voxwarp demo NAME``: write the figure sheet (and with --gui the tour)."""
    from voxwarp.teaching.demos import run_demo

    res = run_demo(
        args.input,
        args.out,
        quick=args.quick,
        tour=args.gui,
        log=lambda s: print(s, file=sys.stderr),
    )
    for path in res.figures:
        print(path)
    if res.tour is not None:
        print(res.tour)
        print(
            f"voxwarp: step through the demo in the desktop GUI with: voxwarp gui --tour"
            f" {res.tour}",
            file=sys.stderr,
        )
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    """``voxwarp reproduce``: every demo's measurements and the report beside the
    papers' numbers (see :mod:`voxwarp.teaching.reproduce`)."""
    from voxwarp.teaching.reproduce import DEFAULT_REPORT, reproduce

    command = "voxwarp reproduce" + (" --quick" if args.quick else "")
    if Path(args.out) != DEFAULT_REPORT:
        command += f" --out {args.out}"
    path = reproduce(
        args.out, quick=args.quick, log=lambda s: print(s, file=sys.stderr), command=command
    )
    print(path)
    return 0


def _demo_volume(args: argparse.Namespace) -> int:
    """``voxwarp demo [INPUT]``: render INPUT in every mode into a folder."""
    from voxwarp.io.images import write_image
    from voxwarp.io.samples import DEFAULT_SAMPLE, suggested_transfer_function
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    spec = args.input or f"sample:{DEFAULT_SAMPLE}"
    obj = load_input(spec)
    vol = obj.volume if isinstance(obj, Scene) else obj
    out = Path(args.out)
    tf = _tf_arg(args.tf, vol)
    if tf is None:
        # samples: a function tuned to them; files: the modality's default (None)
        tf = suggested_transfer_function(vol.name) if spec.startswith("sample:") else None
    paths = []
    with OffscreenRenderer(*args.size) as r:
        for mode in MODES:
            scene = Scene(vol, mode=mode, transfer_function=tf, view=args.view, zoom=1.3)
            img = r.render(scene)
            paths.append(write_image(out / f"{vol.name}_{mode}.png", img))
        scene.save(out / f"{vol.name}_scene.json")
        # the point of voxwarp: the same volume bent at render time, not resampled
        dvr = Scene(vol, mode="dvr", transfer_function=tf, view=args.view, zoom=1.3)
        dvr.warps.append(_demo_bend(vol))
        paths.append(write_image(out / f"{vol.name}_dvr_massspring.png", r.render(dvr)))
        dvr.save(out / f"{vol.name}_massspring_scene.json")
        wired = Scene(vol, mode="dvr", transfer_function=tf, view=args.view, zoom=1.3)
        wire_warp = _demo_wire(vol, wired.resolved_camera().rotation[:, 2])
        if wire_warp is not None:
            wired.warps.append(wire_warp)
            paths.append(write_image(out / f"{vol.name}_dvr_wires.png", r.render(wired)))
            wired.save(out / f"{vol.name}_wires_scene.json")
    for p in paths:
        print(p)
    return 0


def _demo_bend(vol: Any) -> Any:
    """A settled mass-spring bend of ``vol``: an 8³ grid, the bottom quarter (lowest z)
    fixed, the centre elements of the top two layers dragged sideways by 30% of the box
    width."""
    from voxwarp.deform import ElementGrid, MassSpring

    grid = ElementGrid(vol, shape=(8, 8, 8))
    ms = MassSpring(grid, integrator="semi-implicit", shear=True)
    z = grid.rest_positions[..., 2]
    ms.fix(z < grid.lo[2] + 0.25 * (grid.hi[2] - grid.lo[2]))
    drag = 0.3 * float(grid.hi[0] - grid.lo[0])
    ms.move([(i, j, k) for i in (3, 4) for j in (3, 4) for k in (6, 7)], (drag, 0.0, 0.0))
    ms.settle(max_steps=MASSSPRING_SETTLE_MAX_STEPS, tol=MASSSPRING_SETTLE_TOL)
    return ms.warp()  # a CPU model: nothing to release


def _demo_wire(vol: Any, view: Any) -> Any:
    """A wire bend of ``vol`` laid where it is safe (:mod:`voxwarp.teaching.auto_wire`:
    along the largest object's principal axis, ends outside it, bent across ``view``),
    built; None, with one line on stderr saying why, when no object stands out."""
    from voxwarp.deform.wires.field import WireDeformer
    from voxwarp.teaching.auto_wire import auto_wire

    auto = auto_wire(vol, view)
    print(f"voxwarp: demo: {auto.message}", file=sys.stderr)
    if auto.wire is None:
        return None
    wd = WireDeformer(vol, [auto.wire], field_scale=2)
    wd.build()
    return wd.warp()


def cmd_samples(args: argparse.Namespace) -> int:
    """``voxwarp samples``: list bundled samples."""
    from voxwarp.io.samples import sample_names

    for name in sample_names():
        print(f"sample:{name}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """``voxwarp bench render``: this machine's frame rates (see voxwarp.bench.render);
    without an input the standard run: a sparse and two dense cases."""
    from voxwarp.bench.render import RenderCase, bench_render_cases, standard_cases
    from voxwarp.core.files import atomic_write_text

    path = args.input_file or args.input
    if path:
        obj = load_input(path)
        vol = getattr(obj, "volume", obj)
        cases = [RenderCase("", vol, _tf_arg(args.tf, vol), ("dvr", "mip"))]
    else:
        cases = standard_cases()
        if args.tf:  # applies to the sparse case only: the dense ones define their TF
            cases[0].transfer_function = _tf_arg(args.tf, cases[0].volume)

    def log(message: str) -> None:
        print(message, file=sys.stderr)

    reports = bench_render_cases(
        cases,
        size=args.size,
        frames=args.frames,
        warmup=args.warmup,
        step=args.step,
        view=args.view,
        log=log,
    )
    command = (
        "voxwarp " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("voxwarp")
        else ("voxwarp bench render")
    )
    text = "\n".join(report.markdown(command) for report in reports)
    print(text)
    if args.deformed:
        from voxwarp.bench.render import bench_warp_render

        warp_report = bench_warp_render(
            cases[0].volume if path else None,  # None: the standard run's 256³ CT
            size=args.size,
            frames=args.frames,
            warmup=args.warmup,
            transfer_function=cases[0].transfer_function if path else None,
            log=log,
        )
        warp_text = warp_report.markdown(command)
        print(warp_text)
        cost = warp_report.ratio("offset warp, baked")
        if cost is not None:
            print(f"deformed dvr (offset warp, baked inverse) costs {cost:.2f}x undeformed")
        text += "\n" + warp_text
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0


#: ``voxwarp bench`` commands that moved to the lab in the checkout (``benchmarks/``)
MOVED_BENCHMARKS = (
    "massspring",
    "startup",
    "chainmail",
    "wires",
    "wire-tables",
    "wire-ends",
    "lattice",
    "fields",
    "scale",
    "segments",
    "all",
)


def cmd_bench_moved(args: argparse.Namespace) -> int:
    """A ``voxwarp bench`` command that moved to the lab: one line saying where, exit 2."""
    print(
        f"voxwarp: error: 'voxwarp bench {args.bench}' moved out of the installed package:"
        f" run 'python -m benchmarks {args.bench}' from a checkout of voxwarp",
        file=sys.stderr,
    )
    return 2


def _field_scale(text: str) -> int:
    from voxwarp.deform.wires.field import FIELD_SCALES

    try:
        v = int(text)
    except ValueError:
        v = -1
    if v not in FIELD_SCALES:
        raise argparse.ArgumentTypeError(
            f"field scale must be one of {', '.join(map(str, FIELD_SCALES))} (per-axis"
            f" reduction of the attribute field); got {text!r}"
        )
    return v


def _add_field_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "displacement fields (--displacement FILE)",
        "Render the volume through registration results without resampling it: the"
        " volume is the moving image, shown in the fixed image's space. ITK/ANTs/SimpleITK"
        " fields (pull-back, LPS) as NIfTI, NRRD, MetaImage, .npz, or ITK transform files"
        " (.h5, .tfm, ANTs' .mat: displacement fields, B-splines, affines, composites). Repeat the"
        " option to compose: the first file is applied first to the displayed (fixed)"
        " point, the order antsApplyTransforms takes its -t files in (e.g. --displacement"
        " 1Warp.nii.gz --displacement 0GenericAffine.mat).",
    )
    g.add_argument(
        "--displacement",
        action="append",
        metavar="FILE",
        help="a displacement field or ITK transform file (repeatable)",
    )
    _add_field_convention_arg(g)


def _add_field_convention_arg(p: Any) -> None:
    """``--field-convention`` of ``render`` and ``info``: voxwarp.io.fields.CONVENTIONS,
    spelled out so that building the parser loads no field reader."""
    p.add_argument(
        "--field-convention",
        choices=("itk", "ras", "voxel"),
        help="what the vectors of a field whose header does not say mean: itk (LPS mm),"
        " ras (RAS mm) or voxel (index units, as voxelmorph); NIfTI intents and NRRD"
        " spaces say it themselves",
    )


def _field_warps(args: argparse.Namespace) -> list[Any]:
    """The warps of every ``--displacement`` file, in order (fails before any GL work)."""
    if not args.displacement:
        return []
    from voxwarp.io.fields import load_transform

    warps: list[Any] = []
    for path in args.displacement or []:
        warps += load_transform(path, convention=args.field_convention)
    return warps


def _add_wire_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "wires (--wires FILE)",
        "Bend, twist and scale objects along curves (the WSCG 2006 wire deformer for"
        " volumes): each wire is a base curve laid through an object and a modified copy;"
        " the object's cross-sections are swept from the base to the modified curve."
        ' A wire file is JSON: {"wires": [{"kind": "catmull-rom"|"bezier", "base":'
        ' [[x, y, z], ...], "modified": [...], "twist": [[t, radians], ...], "scale":'
        ' [[t, s], ...], "radius": mm, "beta": [lo, hi]}], "field_scale": 2}'
        " (points in world mm, t the fraction of the wire's length). Example:"
        " voxwarp render sample:fish --view +z --wires"
        " sample_volumes/fish_spine_wires.json -o bent.png",
    )
    g.add_argument("--wires", metavar="FILE", help="deform with the wires of this wire file")
    g.add_argument(
        "--field-scale",
        type=_field_scale,
        metavar="N",
        help="attribute field N times coarser than the volume per axis: 1, 2, 4, 8 or 16"
        " (1:1 ... 1:4096 voxels; default: the file's, else 2)",
    )
    g.add_argument(
        "--layout",
        choices=("float", "packed", "paper"),
        help="attribute field storage: float (5 bytes/voxel, hardware-filtered t), packed"
        " (2 bytes/voxel: flag, 7-bit wire, 8-bit t) or paper (2 bytes/voxel, the wire"
        " paper's flag, 4-bit wire, 4-bit segment, 7-bit t); default: the file's, else float",
    )
    p.add_argument(
        "--lattice",
        metavar="FILE",
        help="deform with a lattice of trilinear cells over the volume (a JSON 'lattice' warp"
        " entry; e.g. sample_volumes/fish_lattice_bend.json on sample:fish)",
    )
    g.add_argument(
        "--masks",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="plane masks: sweep only the connected cross-section the wire runs through"
        " (default on; --no-masks sweeps every object voxel within the radius)",
    )


def _add_deform_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group(
        "deformation (--massspring or --chainmail)",
        "Deform the volume before rendering: an element grid spans the volume's box (its"
        " 8 corners fixed), --drag holds elements at offsets from rest, the model moves"
        " the others along, and the resulting offset field warps the volume at render"
        " time. --massspring runs a mass-spring simulation (springs pull the rest along"
        " over time steps); --chainmail runs 3D ChainMail (links with slack: each drag is"
        " settled at once, moving every other element as little as the links allow). With"
        " --save-scene the JSON keeps the field and the model (grid, materials, held"
        " elements; ChainMail also its limits and cuts), so rendering it again gives the"
        " same image. Examples (bend the fish's tail sideways, head held):"
        " voxwarp render sample:fish --view +z --massspring 8 --fix 0..2,0..7,0..7"
        " --drag 6,4,3:0,10,0 --drag 6,3,3:0,10,0 --settle -o bent.png;"
        " voxwarp render sample:fish --view +z --chainmail 8 --fix 0..2,0..7,0..7"
        " --drag 6,4,3:0,10,0 --drag 6,3,3:0,10,0 --relax 4 -o poked.png",
    )
    g.add_argument(
        "--massspring",
        type=_grid_shape,
        metavar="N|NX,NY,NZ",
        help="deform with a mass-spring model: its element grid over the volume's"
        " bounding box (2..128 per axis, e.g. 16)",
    )
    g.add_argument(
        "--chainmail",
        type=_grid_shape,
        metavar="N|NX,NY,NZ",
        help="deform with 3D ChainMail: its element grid over the volume's bounding box"
        " (2..128 per axis, e.g. 16)",
    )
    g.add_argument(
        "--drag",
        type=_drag,
        action="append",
        metavar="I,J,K:DX,DY,DZ",
        help="hold element (i, j, k) at its rest position + (dx, dy, dz) mm (world x, y, z"
        " axes); repeatable; indices run 0..N-1 along x, y, z; corners stay fixed",
    )
    g.add_argument(
        "--drag-at",
        type=ropt.drag_at_arg,
        action="append",
        metavar="X,Y,Z:DX,DY,DZ",
        help="as --drag, on the element nearest the world point (x, y, z) mm (at rest; it"
        " says which and how far); the point may lie at most one element spacing outside"
        " the grid; repeatable",
    )
    g.add_argument(
        "--fix",
        type=_fix,
        action="append",
        metavar="I,J,K",
        help="also fix these elements at rest (the 8 corners always are); each index may"
        " be a range A..B, e.g. --fix 0..2,0..7,0..7 holds the x = low end; repeatable",
    )
    g.add_argument(
        "--backend",
        choices=("cpu", "gpu"),
        help="solve on the CPU (default: numpy for mass-spring, numba for ChainMail) or"
        " in shaders on the renderer's context (gpu)",
    )
    g.add_argument(
        "--inverse",
        choices=("approx", "exact", "baked"),
        help="offset-field inverse: baked (default: fixed point seeded by the inverse baked"
        " on a finer grid, 2 fetches), exact (fixed point from p, 6 fetches) or approx (one"
        " step, q = p - u(p), the thesis')",
    )
    g.add_argument(
        "--stiffness-from-volume",
        type=_stiffness_points,
        metavar="V:S,...",
        help="element stiffness from the volume value at each element, piecewise linear"
        " through VALUE:STIFFNESS points (data units : 0..1; constant beyond the ends),"
        " e.g. 100:0.2,400:0.95 makes CT bone stiff; stiffness 1 is rigid (default:"
        " 0.5 everywhere); ChainMail's link slack is 1 - stiffness",
    )

    m = p.add_argument_group("mass-spring options (with --massspring)")
    m.add_argument(
        "--settle",
        action="store_true",
        default=None,
        help=f"run until every element is slower than {MASSSPRING_SETTLE_TOL:g} mm/s, at"
        f" most --steps steps (default {MASSSPRING_SETTLE_MAX_STEPS})",
    )
    m.add_argument(
        "--steps",
        type=_steps,
        metavar="N",
        help=f"time steps to run (default {MASSSPRING_STEPS}: a smooth, nearly settled"
        " deformation); with --settle the most steps",
    )
    m.add_argument(
        "--integrator",
        choices=("explicit", "semi-implicit"),
        help="semi-implicit (default; ~10x larger stable steps) or explicit Euler (the thesis')",
    )
    m.add_argument(
        "--shear",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="face-diagonal shear springs (default on; without them the grid does not"
        " resist shearing and a sideways drag tears it)",
    )
    m.add_argument(
        "--bend",
        action="store_true",
        default=None,
        help="second-neighbour bend springs (default off)",
    )

    c = p.add_argument_group(
        "3D ChainMail options (with --chainmail)",
        "Each link lets its two elements stretch or compress by up to half a spacing and"
        " shear by up to half a spacing, each times 1 - stiffness (0.5 by default); a drag"
        " moves other elements only once a link is taut, which leaves straight, sheared"
        " blocks; --relax smooths them within the same limits.",
    )
    c.add_argument(
        "--relax",
        type=_relax,
        metavar="K",
        help="relaxation steps after each drag (default 0; the thesis shows 0, 1 and 4):"
        " constrained Laplacian smoothing that keeps every link within its limits",
    )
    c.add_argument(
        "--variant",
        choices=("gibson", "enhanced"),
        help="propagation: enhanced (default; Schill et al.'s priority queue) or gibson"
        " (Gibson's sponsor lists); a single drag ends in the same state",
    )
    c.add_argument(
        "--cut",
        type=_cut,
        action="append",
        metavar="PX,PY,PZ:NX,NY,NZ[:R]",
        help="before the drags, remove the links crossing the plane through point P (world"
        " mm) with normal N, or only a disk of radius R mm on it; the two sides then move"
        " independently; repeatable, e.g. --cut 48,24,20:1,0,0",
    )


class OneLineErrorParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line: ``PROG: error: MESSAGE (see PROG
    --help)``, exit code 2, instead of argparse's usage block followed by the error.
    Subcommand parsers inherit it (``add_subparsers`` uses the parent's class)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


class _VersionAction(argparse.Action):
    """``--version``: prints the installed version, which it looks up only when asked
    (``importlib.metadata`` is slow to import, and every command builds the parser)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.setdefault("help", "show the version and exit")
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> NoReturn:
        from voxwarp import __version__

        print(f"voxwarp {__version__}")
        parser.exit()


def build_parser(*, bench: bool = True) -> argparse.ArgumentParser:
    """The argument parser of the ``voxwarp`` command.

    ``bench=False`` leaves out the benchmarks whose modules are heavy to import (``bench
    interactive``, ``slices``): :func:`main` does so unless a ``bench``
    command runs, which keeps ``voxwarp --help`` and every other command quick to start.
    """
    p = OneLineErrorParser(prog="voxwarp", description=__doc__.split("\n")[0])
    p.add_argument("--version", action=_VersionAction)
    sub = p.add_subparsers(dest="command", required=True)

    pi = sub.add_parser(
        "info",
        help="print dims, dtype, spacing, value range, histogram; for a displacement field"
        " or transform file its grid, extent and |u|",
    )
    pi.add_argument("input")
    pi.add_argument("--json", action="store_true", help="machine-readable output")
    _add_field_convention_arg(pi)
    _add_volume_args(pi)
    pi.set_defaults(func=cmd_info)

    pr = sub.add_parser("render", help="render INPUT (volume or scene JSON) to an image")
    pr.add_argument("input")
    pr.add_argument("-o", "--output", default="out.png", help="PNG/EXR/TIFF by extension")
    pr.add_argument("--mode", choices=MODES)
    pr.add_argument("--projection", choices=("perspective", "orthographic"))
    pr.add_argument("--view", type=_view, help=ropt.VIEW_HELP)
    pr.add_argument("--size", type=_size, default=(512, 512), help="WxH pixels")
    pr.add_argument("--tf", help=TF_HELP)
    pr.add_argument("--step", type=float, help="sample distance in voxels (default 1)")
    pr.add_argument("--window", nargs=2, type=float, metavar=("LEVEL", "WIDTH"))
    pr.add_argument("--iso", dest="iso_value", type=float, help="isovalue for --mode iso")
    pr.add_argument("--zoom", type=float)
    pr.add_argument("--seed", type=int, help="jitter seed")
    pr.add_argument("--jitter", action=argparse.BooleanOptionalAction, default=None)
    pr.add_argument("--shading", action=argparse.BooleanOptionalAction, default=None)
    pr.add_argument(
        "--keep-padding",
        action="store_true",
        help="keep the padding outside a CT's field of view (default: shown as air)",
    )
    pr.add_argument("--save-scene", metavar="JSON", help="also write the scene JSON")
    pr.add_argument(
        "--marker", action="store_true", help="draw an orientation marker (bottom left)"
    )
    _add_volume_args(pr)
    ropt.add_render_options(pr)
    _add_deform_args(pr)
    _add_wire_args(pr)
    _add_field_args(pr)
    pr.set_defaults(func=cmd_render)
    add_animate_parser(sub)
    _add_export_field_parser(sub)
    add_slice_parser(sub)
    add_export_volume_parser(sub)

    from voxwarp.teaching import DEMO_TITLES, DEMOS

    pd = sub.add_parser(
        "demo",
        help=f"teaching demo NAME ({', '.join(DEMOS)}): a figure sheet; or render a volume"
        " in every mode into a folder",
        description="voxwarp demo NAME writes the figure sheet of a teaching demo to"
        " OUT/NAME.png: "
        + "; ".join(f"{n}: {t}" for n, t in DEMO_TITLES.items())
        + ". voxwarp demo [INPUT] (a volume, scene JSON or sample:NAME; default the bundled"
        " real CT) renders it in every mode, bent by a mass-spring drag and by a wire.",
    )
    add_memory_budget_arg(pd)
    pd.add_argument(
        "input",
        nargs="?",
        metavar="NAME|INPUT",
        help=f"a teaching demo ({', '.join(DEMOS)}) or a volume (default: the bundled real CT)",
    )
    pd.add_argument("--out", default="out", help="output folder (default out)")
    pd.add_argument("--size", type=_size, default=(512, 512), help="INPUT: image WxH")
    pd.add_argument("--tf", help=TF_HELP + " (default: suits the sample)")
    pd.add_argument(
        "--view", type=_view, help="INPUT: view (default anterior for oriented volumes, else -y)"
    )
    pd.add_argument(
        "--quick",
        action="store_true",
        help="NAME: small volumes, grids and images (seconds instead of a minute)",
    )
    pd.add_argument(
        "--gui",
        action="store_true",
        help="NAME: also write OUT/NAME_tour.json, the steps of a guided walk through the"
        " model (title, explanation, scene JSON per step) for the desktop GUI",
    )
    pd.set_defaults(func=cmd_demo)

    prp = sub.add_parser(
        "reproduce",
        help="run every teaching demo and write the papers' numbers beside ours",
        description="Regenerates the papers' tables and figures on this machine (the"
        " teaching demos' measurements) and writes a markdown report with the hardware,"
        " the papers' numbers beside ours, and the figure sheets in a folder beside it.",
    )
    prp.add_argument("--quick", action="store_true", help="small sizes (seconds; not comparable)")
    prp.add_argument(
        "--out",
        default="docs/reproduction.md",
        metavar="FILE",
        help="the report (default docs/reproduction.md; figures in docs/reproduction/)",
    )
    prp.set_defaults(func=cmd_reproduce)

    ps = sub.add_parser("samples", help="list bundled sample volumes")
    ps.set_defaults(func=cmd_samples)

    pb = sub.add_parser("bench", help="benchmarks")
    bsub = pb.add_subparsers(dest="bench", required=True)
    pbr = bsub.add_parser("render", help="raycaster timings vs no-skipping")
    pbr.add_argument(
        "input",
        nargs="?",
        help="volume (default: the standard run: the real CT upsampled to 256³, a dense CT-like"
        " phantom and the bundled MRI)",
    )
    pbr.add_argument("--input", dest="input_file", metavar="FILE", help="same as INPUT")
    pbr.add_argument("--view", type=_view, help=ropt.VIEW_HELP)
    pbr.add_argument("--size", type=_size, default=(512, 512))
    pbr.add_argument("--frames", type=int, default=10)
    pbr.add_argument("--warmup", type=int, default=2)
    pbr.add_argument("--step", type=float, default=1.0)
    pbr.add_argument(
        "--tf", help=TF_HELP + " (default: suits the bench volume; standard run: sparse)"
    )
    pbr.add_argument(
        "--no-vtk", action="store_true", help="no effect: VTK is in 'python -m benchmarks render'"
    )
    pbr.add_argument(
        "--deformed", action="store_true", help="also time dvr through a mass-spring offset warp"
    )
    pbr.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbr.set_defaults(func=cmd_bench)
    for name in MOVED_BENCHMARKS:  # no option of theirs is parsed here ("\0": none is one)
        help_ = f"moved: python -m benchmarks {name} (from a checkout)"
        pmv = bsub.add_parser(name, help=help_, add_help=False, prefix_chars="\0")
        pmv.add_argument("rest", nargs="*")
        pmv.set_defaults(func=cmd_bench_moved)
    if bench:
        _add_heavy_bench_parsers(bsub)
    return p


def _add_export_field_parser(sub: Any) -> None:
    p = sub.add_parser(
        "export-field",
        help="write a scene's warp chain as a displacement field (ITK, ANTs, Slicer)",
        description="Samples the warp chain of SCENE.json (voxwarp render ... --save-scene)"
        " as the pull-back field u(p) = warp(p) - p and writes it in the ITK convention (LPS"
        " vectors in mm): SimpleITK.Resample(volume, DisplacementFieldTransform(field))"
        " reproduces the deformed volume voxwarp draws. Default grid: the volume's own.",
    )
    p.add_argument("scene", metavar="SCENE.json")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FIELD",
        help="the field file: .nii.gz, .nii, .nrrd, .mha, .h5 (ITK transform) or .npz",
    )
    p.add_argument(
        "--spacing",
        nargs="+",
        type=float,
        metavar="S",
        help="node spacing in mm, one number or three (default: the volume's voxels)",
    )
    p.add_argument(
        "--box",
        nargs=6,
        type=float,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        help="sample this world box (RAS mm, axis-aligned) instead of the volume's",
    )
    p.add_argument(
        "--convention",
        choices=("itk",),
        default="itk",
        help="the written convention: itk (pull-back, LPS vectors in mm; the only one for now)",
    )
    add_memory_budget_arg(p)
    p.set_defaults(func=cmd_export_field)


def _add_heavy_bench_parsers(bsub: Any) -> None:
    """``bench interactive|slices``: their modules define their options (and load numpy,
    numba, ...), so the parser adds them only when a ``bench`` command runs."""
    from voxwarp.bench.interactive import add_bench_interactive_parser
    from voxwarp.bench.slices import add_bench_slices_parser

    add_bench_interactive_parser(bsub)
    add_bench_slices_parser(bsub)


def wants_bench(argv: Sequence[str] | None) -> bool:
    """Whether ``argv`` (default ``sys.argv[1:]``) runs a ``bench`` command."""
    args = list(sys.argv[1:] if argv is None else argv)
    return bool(args) and args[0] == "bench"


#: ``--tf`` help, the same wherever it is accepted (one resolver: :func:`_tf_arg`).
TF_HELP = (
    "preset (ct-bone, mri, ...), matplotlib colour map (viridis, ...), or a file: voxwarp"
    " or ParaView colour-map JSON, Slicer presets.xml or .vp; FILE:NAME picks one map"
)

#: options whose value may start with "-" (a negative number or "-y"): joined as --opt=value
_NEGATIVE_VALUE_OPTIONS = (
    "--view",
    "--stiffness-from-volume",
    "--cut",
    "--clip",
    "--drag-at",
    "--plane",
)


def _join_negative_views(argv: list[str]) -> list[str]:
    # "--view -y" / "--view -30,20": argparse would take the value for an option
    out: list[str] = []
    i = 0
    while i < len(argv):
        negative = i + 1 < len(argv) and argv[i + 1].startswith("-")
        # slice's --window LEVEL,WIDTH (render's takes two values, never a comma)
        pair = argv[i] == "--window" and negative and "," in argv[i + 1]
        if pair or (argv[i] in _NEGATIVE_VALUE_OPTIONS and negative):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


def main(argv: Sequence[str] | None = None, parser: argparse.ArgumentParser | None = None) -> int:
    """Entry point of the ``voxwarp`` console script.

    ``parser`` replaces :func:`build_parser`'s (the desktop GUI's entry point,
    :func:`voxwarp.ui.cli.main`, adds its ``gui`` command to it: ``app`` never imports ``ui``).
    """
    parser = parser or build_parser(bench=wants_bench(argv))
    args = parser.parse_args(_join_negative_views(list(sys.argv[1:] if argv is None else argv)))
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        old_format = warnings.formatwarning
        warnings.formatwarning = lambda msg, cat, *a, **k: f"voxwarp: warning: {msg}\n"
        try:
            limits.set_memory_budget(getattr(args, "memory_budget", None))
            return int(args.func(args) or 0)
        except VoxwarpError as exc:  # OutputError too: a write that failed, cleaned up
            print(f"voxwarp: error: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:  # a file operation outside the checked writers: one line
            where = f"{exc.filename}: " if exc.filename else ""
            print(f"voxwarp: error: {where}{exc.strerror or exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130
        finally:
            limits.set_memory_budget(None)
            warnings.formatwarning = old_format


if __name__ == "__main__":
    sys.exit(main())
