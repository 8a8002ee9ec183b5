"""The deformation options of ``render`` and ``slice`` at work: the checks that need no
volume, then the element grid, the mass-spring or ChainMail model, the wire, lattice and
displacement-field warps, and the scene they deform (:func:`prepare_deformation` before
any GL work, :func:`deformed_scene` on the renderer's context).

The options themselves are defined in :mod:`voxwarp.cli.deform_options`.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import warnings
from collections.abc import Iterator, Sequence
from typing import Any, NamedTuple

import numpy as np

from voxwarp.cli import render_options as ropt
from voxwarp.cli.deform_options import (
    MASSSPRING_SETTLE_TOL,
)

# the moved bodies below keep the names they had in voxwarp.cli.main
from voxwarp.cli.deform_options import Cut as _Cut
from voxwarp.cli.deform_options import Drag as _Drag
from voxwarp.cli.deform_options import grid_text as _grid_text
from voxwarp.deform.elements.anchors import DEFAULT as DEFAULT_REGION
from voxwarp.deform.elements.anchors import MODEL_DEFAULT, anchor_mask
from voxwarp.editing import model_settings as ms
from voxwarp.editing.model_settings import LatticeSettings, SettingError, WireSettings
from voxwarp.errors import InputError as CliOptionError
from voxwarp.inputs import load_wire_file

#: the options of ``render``'s deformation models, in the order of ``--help``: (flag,
#: attribute, the model that takes it: "both", "massspring" or "chainmail")
_DEFORM_OPTIONS: tuple[tuple[str, str, str], ...] = (
    ("--drag", "drag", "both"),
    ("--drag-at", "drag_at", "both"),
    ("--fix", "fix", "both"),
    ("--backend", "backend", "both"),
    ("--inverse", "inverse", "both"),
    ("--stiffness-from-volume", "stiffness_from_volume", "both"),
    ("--grid-margin", "grid_margin", "both"),
    ("--anchor", "anchor", "both"),
    ("--fix-outside", "fix_outside", "both"),
    ("--settle", "settle", "massspring"),
    ("--steps", "steps", "massspring"),
    ("--integrator", "integrator", "massspring"),
    ("--shear/--no-shear", "shear", "massspring"),
    ("--bend", "bend", "massspring"),
    ("--relax", "relax", "chainmail"),
    ("--variant", "variant", "chainmail"),
    ("--cut", "cut", "chainmail"),
    ("--join", "join", "chainmail"),
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


def check_deform_options(args: argparse.Namespace) -> None:
    """Option checks that need no volume: deformation options without their model, both
    models at once, options of the other model, drags and fixes outside the grid, drags
    of a fixed element or of one element twice."""

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
    anchor = _grid_anchor(args, model)
    fixed = anchor_mask(tuple(shape), anchor)
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
            by_anchor = anchor_mask(tuple(shape), anchor)[d.index]
            what = (
                f"on the {grid} grid's {anchor} (--anchor {anchor} fixes it)"
                if by_anchor
                else "fixed by --fix"
            )
            raise CliOptionError(
                f"{d.flag} {d.text}: element {d.index} is {what}; drag an element that is not"
                " fixed" + (", or choose another --anchor" if by_anchor else "")
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


#: the per-wire options of --wires that every wire of the file takes: (option, key)
_WIRE_SIDE_OPTIONS = (
    ("--sides", "sides"),
    ("--side-falloff", "side_falloff"),
    ("--vacated", "vacated"),
)


def _apply_side_options(args: argparse.Namespace, entry: dict[str, Any]) -> None:
    """--sides, --side-falloff and --vacated into every wire of a wire file's entry."""
    for _, key in _WIRE_SIDE_OPTIONS:
        value = getattr(args, key, None)
        if value is None:
            continue
        for wire in entry.get("wires") or []:
            if isinstance(wire, dict):
                wire[key] = value


def _check_wire_options(args: argparse.Namespace) -> None:
    """--wires cannot be combined with a model; its options need it."""
    if args.wires is None:
        for opt, attr in (("--field-scale", "field_scale"), ("--layout", "layout")):
            if getattr(args, attr) is not None:
                raise CliOptionError(f"{opt} needs --wires FILE (a wire file, see --help)")
        if args.masks is not None:
            raise CliOptionError("--masks/--no-masks needs --wires FILE (a wire file)")
        for opt, attr in _WIRE_SIDE_OPTIONS:
            if getattr(args, attr, None) is not None:
                raise CliOptionError(f"{opt} needs --wires FILE (a wire file, see --help)")
        return
    if _deform_model(args) is not None:
        raise CliOptionError(
            "--wires cannot be combined with --massspring or --chainmail in one render:"
            " save one with --save-scene and render that scene with the other"
        )


def _wire_warp(args: argparse.Namespace, volume: Any) -> tuple[Any, str]:
    """The wire warp of --wires on ``volume``, built, and a one-line summary."""
    # loads scipy: only when used
    from voxwarp.deform.warp import WarpError
    from voxwarp.editing.families.wires import WiresFamily

    entry = load_wire_file(args.wires)
    if args.field_scale is not None:
        entry["field_scale"] = args.field_scale
    if args.layout is not None:
        entry["layout"] = args.layout
    if args.masks is not None:
        entry["masks"] = args.masks
    _apply_side_options(args, entry)
    try:
        warp = WiresFamily.build(WireSettings(entry), volume).warp
    except WarpError as exc:
        raise CliOptionError(f"--wires {args.wires}: {exc}") from exc
    st = warp.deformer.stats
    assert st is not None
    summary = (
        f"wires: {len(warp.wires)} wire(s), field {'x'.join(map(str, st.field_shape))}"
        f" (1:{st.field_scale**3}, {st.layout}), {st.planes - st.planes_dropped} planes"
        f" ({st.mask_bytes_total} bytes of masks), {st.swept} voxels swept,"
        f" {st.percent_ignored:.1f}% ignored,"
        f" built in {st.timings['total']:.2f} s ({st.backend}); sides: {_sides_text(warp.wires)}"
    )
    if st.seam_faded:
        short = warp.wire_shortfall()
        summary += (
            f"; {st.seam_faded} voxels faded at seams (closest point jumps), so the wire's"
            f" content lands up to {short:.1f} mm short of the bend (a gentler bend, or a"
            " smaller radius and --side-falloff, keeps the closest point from jumping)"
        )
    return warp, summary


def _sides_text(wires: list[Any]) -> str:
    """The wires' sides in a few words (e.g. ``smooth, falloff 35 mm``)."""
    parts = []
    for w in wires:
        if w.smooth_sides:
            parts.append(f"smooth, falloff {w.side_falloff:.3g} mm")
        else:
            parts.append(f"rigid, vacated {w.vacated}")
    return "; ".join(dict.fromkeys(parts))


def _grid_anchor(args: argparse.Namespace, model: str) -> str:
    """The anchor mode the grid of ``--massspring``/``--chainmail`` gets: ``--anchor``, or
    the model's own (its settings class's ``default_anchor``)."""
    settings = ms.MassSpringSettings if model == "massspring" else ms.ChainMailSettings
    return args.anchor or settings.default_anchor


def _element_settings(args: argparse.Namespace) -> Any:
    """The model builder's settings of ``render --massspring`` / ``--chainmail``
    (:mod:`voxwarp.editing.model_settings`; None without either)."""
    model = _deform_model(args)
    if model is None:
        return None
    common: dict[str, Any] = {
        "backend": args.backend or "cpu",
        "fixed": tuple(ranges for _, ranges in args.fix or []),
        "stiffness_from_volume": args.stiffness_from_volume,
        "anchor": args.anchor or MODEL_DEFAULT,
        "fix_outside": DEFAULT_REGION if args.fix_outside is None else args.fix_outside,
        "drags": tuple(ms.Drag(d.index, d.offset) for d in args.drag or []),
        "inverse": args.inverse or "baked",
        "margin": args.grid_margin,
    }
    if model == "massspring":
        return ms.MassSpringSettings(
            shape=tuple(args.massspring),
            integrator=args.integrator or "semi-implicit",
            shear=True if args.shear is None else args.shear,
            bend=bool(args.bend),
            run=ms.SettleRule(settle=bool(args.settle), steps=args.steps),
            **common,
        )
    relax = args.relax or 0
    return ms.ChainMailSettings(
        shape=tuple(args.chainmail),
        variant=args.variant or "enhanced",
        cuts=tuple(ms.Cut(c.point, c.normal, c.radius) for c in args.cut or []),
        joins=tuple(ms.Cut(c.point, c.normal, c.radius) for c in args.join or []),
        relax=relax,
        relax_steps=relax,  # saved with the model: a resumed one relaxes alike
        warm_up=True,  # the reported move time is the move's alone
        **common,
    )


def _deform_grid(args: argparse.Namespace, volume: Any) -> Any:
    """The element grid of ``render --massspring`` / ``--chainmail`` over ``volume``
    (None without either): fixed elements and materials set, drags checked against
    rigid elements (mass-spring) and cutting and joining planes against the grid
    (ChainMail), all before any GL work."""
    model = _deform_model(args)
    if model is None:
        return None
    # loads scipy: only when used
    from voxwarp.editing.families.elements import ElementFamily, material_preset

    _resolve_margin(args)
    if args.drag_at:  # to the nearest elements at rest, then checked as --drag elements are
        # loads scipy: only when used
        from voxwarp.deform.elements.grid import ElementGrid, ElementGridError

        shape = args.massspring if model == "massspring" else args.chainmail
        try:
            pick_grid = ElementGrid(
                volume,
                shape=shape,
                margin=args.grid_margin,
                anchor=_grid_anchor(args, model),
            )
        except ElementGridError as exc:
            raise CliOptionError(f"--grid-margin: {exc}") from exc
        picks = ropt.pick_elements(pick_grid, args.drag_at)
        for pick in picks:
            print(pick.summary(), file=sys.stderr)
        args.drag = [
            *(args.drag or []),
            *(_Drag((k.drag.text, k.index, k.drag.offset, "--drag-at")) for k in picks),
        ]
        args.drag_at = None
        check_deform_options(args)
    try:
        grid = ElementFamily.grid(_element_settings(args), volume)
    except SettingError as exc:
        flags = {"margin": "--grid-margin", "anchor": "--anchor"}
        flag = flags.get(exc.setting, "--stiffness-from-volume")
        raise CliOptionError(f"{flag}: {exc}") from exc
    if isinstance(args.stiffness_from_volume, str):
        preset = material_preset(args.stiffness_from_volume, volume)
        s = grid.stiffness
        print(
            f"voxwarp: materials: --stiffness-from-volume {args.stiffness_from_volume}:"
            f" the {preset} preset, element stiffness {s.min():.2f}..{s.max():.2f}",
            file=sys.stderr,
        )
    if model == "massspring":
        rigid = grid.pinned()
        for d in args.drag or []:
            if rigid[d.index]:
                raise CliOptionError(
                    f"{d.flag} {d.text}: element {d.index} is rigid (stiffness 1 from"
                    " --stiffness-from-volume) and cannot move; drag another element or"
                    " map its value to a stiffness below 1"
                )
    _check_cuts(args, grid)
    _say_margin(args)
    return grid


def _resolve_margin(args: argparse.Namespace) -> None:
    """Set ``args.grid_margin`` (mm): as given, else the largest offset component of the
    drags (``default_margin``)."""
    from voxwarp.deform.elements.grid import default_margin

    args.grid_margin_given = args.grid_margin is not None
    if not args.grid_margin_given:
        offsets = [d.offset for d in args.drag or []] + [d.offset for d in args.drag_at or []]
        args.grid_margin = default_margin(offsets)


def _say_margin(args: argparse.Namespace) -> None:
    """The one stderr line of a grid margin above 0 (after every check passed)."""
    if args.grid_margin > 0.0:
        why = "--grid-margin" if args.grid_margin_given else "default: the largest drag offset"
        print(
            f"grid margin: the element grid reaches {args.grid_margin:g} mm beyond the"
            f" volume's box on every side ({why}; --grid-margin 0 keeps the box)",
            file=sys.stderr,
        )


def _check_cuts(args: argparse.Namespace, grid: Any) -> None:
    """Every ``--cut`` must cross a link of ``grid`` at rest and every ``--join`` a link
    that a ``--cut`` removed (one-line errors naming the option and the fix)."""
    cut: list[np.ndarray] | None = None
    for c in args.cut or []:
        crossed = _crossings(grid, c)
        if not any(np.any(m) for m in crossed):
            lo, hi = grid.lo, grid.hi
            box = ", ".join(f"{a} {lo[i]:g}..{hi[i]:g}" for i, a in enumerate("xyz"))
            raise CliOptionError(
                f"--cut {c.text}: the {_where(c)} crosses no link of the"
                f" {_grid_text(grid.shape)} grid, whose elements span {box} mm; give a"
                " point inside that box (world mm, as --drag offsets)"
            )
        cut = crossed if cut is None else [m | k for m, k in zip(crossed, cut, strict=True)]
    for c in args.join or []:
        crossed = _crossings(grid, c)
        if cut is None or not any(np.any(m & k) for m, k in zip(crossed, cut, strict=True)):
            raise CliOptionError(
                f"--join {c.text}: the {_where(c)} crosses no link that a --cut removed;"
                " --join links again what --cut cut: give a plane or disk across a --cut"
            )


def _where(cut: _Cut) -> str:
    return "plane" if cut.radius is None else f"disk of radius {cut.radius:g} mm"


def _crossings(grid: Any, cut: _Cut) -> list[np.ndarray]:
    """Per axis, the links of ``grid`` at rest that ``cut`` (a --cut or --join plane or
    disk) crosses (the test of ChainMail.cut), each with that axis first."""
    out = []
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
        out.append(cross)
    return out


def _run_massspring(args: argparse.Namespace, grid: Any, ctx: Any) -> tuple[Any, str]:
    """Build, drag and run the mass-spring model of ``render --massspring`` on ``grid``
    (the model builder: ``MassSpringFamily.build_on``).

    Returns the :class:`~voxwarp.deform.elements.massspring.MassSpring` and a one-line summary.
    """
    # loads scipy: only when used
    from voxwarp.deform.warp import WarpError
    from voxwarp.editing.families.elements import MassSpringFamily

    settings = _element_settings(args)
    try:
        ms, _, report = MassSpringFamily.build_on(settings, grid, ctx)
    except (SettingError, WarpError) as exc:  # e.g. displacements beyond the texture's range
        raise CliOptionError(f"--massspring: {exc}") from exc
    how = f"{report.steps} steps"
    if report.hit_limit:
        warnings.warn(
            f"--settle stopped at the limit of {settings.run.limit} steps; the grid may still"
            " be moving: raise --steps",
            RuntimeWarning,
            stacklevel=1,
        )
    elif report.settling:
        how += f" (settled: every element slower than {MASSSPRING_SETTLE_TOL:g} mm/s)"
    summary = (
        f"massspring: {_grid_text(grid.shape)} {settings.backend} {ms.integrator},"
        f" dt {ms.dt:.3g} s, {len(settings.drags)} dragged, {how}"
    )
    return ms, summary


def _run_chainmail(args: argparse.Namespace, grid: Any, ctx: Any) -> tuple[Any, str]:
    """Build, cut, drag and relax the ChainMail model of ``render --chainmail`` (the
    model builder: ``ChainMailFamily.build_on``).

    Cuts come first (through the rest state), then the joins (``--join``: cut links
    linked again), then all ``--drag`` elements move at once
    (one :meth:`~voxwarp.deform.elements.chainmail.ChainMail.move`), then ``--relax`` steps
    (also saved as the model's ``relax_steps``). Returns the
    :class:`~voxwarp.deform.elements.chainmail.ChainMail` and a one-line summary.
    """
    # loads scipy: only when used
    from voxwarp.editing.families.elements import ChainMailFamily

    settings = _element_settings(args)
    drags = args.drag or []
    try:
        cm, _, report = ChainMailFamily.build_on(settings, grid, ctx)
    except SettingError as exc:
        raise CliOptionError(f"--chainmail: {exc}") from exc
    if report.limited_fraction is not None:
        shell = " (the grid's shell is fixed: --anchor shell)" if grid.anchor == "shell" else ""
        what = f"{drags[0].flag} {drags[0].text}" if len(drags) == 1 else "the dragged elements"
        warnings.warn(
            f"{what} went only {report.limited_fraction:.0%} of the way: the links between"
            f" the dragged and the fixed or anchored elements ran out of slack{shell};"
            " drag less, lower the stiffness, or fix fewer elements (--anchor corners,"
            " --fix-outside off)",
            RuntimeWarning,
            stacklevel=1,
        )
    backend, relax = settings.backend, settings.relax
    moved = (
        f"{report.touched} elements touched in {report.solve_ms:.1f} ms"
        if backend == "cpu"
        else f"solved in {report.solve_ms:.1f} ms"
    )
    summary = f"chainmail: {_grid_text(grid.shape)} {backend} {cm.variant}, {len(drags)} dragged"
    summary += f", {moved}"
    if relax:
        summary += f", relax {relax} step{'s' * (relax != 1)} in {report.relax_ms:.1f} ms"
    if args.cut:
        summary += f", {report.cut} links cut"
    if args.join:
        summary += f", {report.joined} joined again"
    summary += f"; {report.displaced} elements displaced"
    return cm, summary


def _field_warps(args: argparse.Namespace) -> list[Any]:
    """The warps of every ``--displacement`` file, in order (fails before any GL work)."""
    if not args.displacement:
        return []
    # loaded when used: voxwarp --help stays light (see voxwarp.cli)
    from voxwarp.io.fields import load_transform

    warps: list[Any] = []
    for path in args.displacement or []:
        warps += load_transform(path, convention=args.field_convention)
    return warps


def boundary_line(model: Any, chainmail: bool = False) -> str:
    """The one stderr line naming the boundary conditions of a built element model
    (``chainmail``: say that its links keep a drag local without a fixed shell)."""
    held = model.to_dict().get("held", [])
    drag = max((float(np.linalg.norm(h["offset"])) for h in held), default=None)
    grid = model.grid
    count = f"; {int(grid.anchored.sum())} anchored" if grid.anchored.any() else ""
    local = "; ChainMail's link slack keeps a drag local" if chainmail else ""
    return (
        f"voxwarp: boundary: {grid.describe_anchors(drag)}{count}{local} (--anchor, --fix-outside)"
    )


class PendingDeformation(NamedTuple):
    """The deformation options of ``render`` (and ``slice``) prepared before any GL work:
    the element grid of ``--massspring``/``--chainmail``, the warp of ``--wires`` or
    ``--lattice`` (None when not given) and the ``--displacement`` warps."""

    grid: Any
    file_warp: Any
    fields: tuple[Any, ...] = ()


def prepare_deformation(args: argparse.Namespace, scene: Any) -> tuple[Any, PendingDeformation]:
    """``scene`` and what :func:`deformed_scene` adds to its chain: the ``--displacement``
    fields, the model grid and the file warp; every check that needs no GL runs here, so
    bad options fail before a context is made."""
    fields = _field_warps(args)
    for w in fields:
        w.bind_volume(scene.volume)  # a field that misses the volume warns
    grid = _deform_grid(args, scene.volume)
    file_warp = None  # --wires or --lattice (they exclude each other)
    if args.wires is not None:  # built before any GL work: bad wires fail fast
        file_warp, summary = _wire_warp(args, scene.volume)
        print(summary, file=sys.stderr)
    if args.lattice is not None:
        # loads scipy: only when used
        from voxwarp.editing.families.lattice import LatticeFamily

        file_warp = LatticeFamily.build(LatticeSettings(file=args.lattice), scene.volume).warp
    return scene, PendingDeformation(grid, file_warp, tuple(fields))


def compose_chain(
    scene_warps: Sequence[Any], fields: Sequence[Any], correction: Sequence[Any]
) -> list[Any]:
    """The chain of ``render``/``slice`` (deformed -> original, first warp nearest the
    picture).

    With ``--displacement`` fields, the models (``--massspring``/``--chainmail``, then
    ``--wires``/``--lattice``) correct the registration in the displayed (fixed)
    space: ``[*correction, *fields, *scene_warps]``, so a ``--drag`` moves what is
    seen at its point by its offset. Without fields they deform the volume itself,
    before the scene's own warps move the result: ``[*scene_warps, *correction]``.
    """
    if fields:
        return [*correction, *fields, *scene_warps]
    return [*scene_warps, *correction]


@contextlib.contextmanager
def deformed_scene(
    args: argparse.Namespace, scene: Any, pending: PendingDeformation, ctx: Any
) -> Iterator[Any]:
    """The finished scene: the model of ``pending`` run on ``ctx`` (current), its warp and
    the file warp put in the chain (:func:`compose_chain`), then the clip/camera options;
    the model is closed when the block ends."""
    model = None
    correction: list[Any] = []
    try:
        if pending.grid is not None:
            run = _run_massspring if args.massspring is not None else _run_chainmail
            model, summary = run(args, pending.grid, ctx)
            print(summary, file=sys.stderr)
            folds = model.warp().fold_summary()
            if folds is not None:  # one line: meshes and the inverse are wrong there
                print(f"warning: {folds}", file=sys.stderr)
            print(boundary_line(model, args.chainmail is not None), file=sys.stderr)
            correction.append(model.warp())
        if pending.file_warp is not None:
            correction.append(pending.file_warp)
        scene = scene.copy(warps=compose_chain(scene.warps, pending.fields, correction))
        yield ropt.apply_render_options(scene, args)  # every warp is in place
    finally:
        if model is not None:
            model.close()
