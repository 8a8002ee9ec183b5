"""``python -m benchmarks render``: voxwarp's raycaster against VTK's, in the same run.

The installed ``voxwarp bench render`` (:mod:`voxwarp.bench.render`) times voxwarp alone
(and without skipping, and with gradients on the fly); this adds VTK's
``vtkFixedPointVolumeRayCastMapper`` (CPU) and ``vtkGPUVolumeRayCastMapper`` (on whatever
OpenGL the machine has), when ``vtk`` is installed (extra ``[bench]``), with the same
array, transfer function, sample distance, image size and camera. Ratios are ``reference
time / voxwarp time`` (above 1: voxwarp is faster).
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path
from typing import Any

from benchmarks import vtk as bench_vtk
from voxwarp.bench import render as installed
from voxwarp.bench.render import BenchReport, BenchRow, RenderCase
from voxwarp.cli.bench import add_render_bench_args, render_bench_cases
from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.render.raycaster import LIGHT
from voxwarp.scene import Scene

#: the VTK mappers compared by default
VTK_MAPPERS: tuple[str, ...] = ("fixed_point", "gpu")


def vtk_rows(
    report: BenchReport,
    vol: Volume,
    scenes: dict[str, Scene],
    cam: Camera,
    size: tuple[int, int],
    frames: int,
    warmup: int,
    log: Any,
    mappers: tuple[str, ...] = ("fixed_point", "gpu"),
) -> None:
    """Time VTK's raycasters (``mappers``: fixed_point, gpu) on ``scenes`` and append
    their rows to ``report``; a row that cannot run says why (VTK missing, no GL)."""
    names = {"fixed_point": "VTK fixed-point (CPU)", "gpu": "VTK GPU raycaster"}
    names = {k: v for k, v in names.items() if k in mappers}
    if not bench_vtk.vtk_available():
        for name in names.values():
            report.rows.append(
                BenchRow(name, "-", 0, 0, "skipped: VTK not installed (pip install '.[bench]')")
            )
        log("VTK not installed: VTK rows skipped (pip install '.[bench]')")
        return
    spec = bench_vtk.camera_spec(cam)
    for mapper, name in names.items():
        for m, scene in scenes.items():
            try:
                res = bench_vtk.render_vtk(
                    vol.data,
                    vol.spacing,
                    vol.origin,
                    list(scene.transfer_function.points),
                    mapper=mapper,  # type: ignore[arg-type]
                    mode=m,  # type: ignore[arg-type]
                    sample_distance_mm=scene.sample_distance_mm,
                    opacity_unit_distance_mm=scene.opacity_reference_mm,
                    size=size,
                    camera=spec,
                    frames=frames,
                    warmup=warmup,
                    shading=LIGHT if scene.use_shading() else None,
                )
            except (RuntimeError, ValueError) as exc:
                report.rows.append(BenchRow(name, m, 0, 0, f"skipped: {exc}"))
                log(f"{name} {m}: skipped ({exc})")
                continue
            report.rows.append(BenchRow(name, m, res.median_ms, res.min_ms))
            log(f"{name} {m}: {res.median_ms:.1f} ms")


def bench_render(
    volume: Volume | None = None,
    *,
    use_vtk: bool = True,
    vtk_mappers: tuple[str, ...] = VTK_MAPPERS,
    **kwargs: Any,
) -> BenchReport:
    """:func:`voxwarp.bench.render.bench_render` with the VTK references (``kwargs`` as
    there)."""
    refs = [functools.partial(vtk_rows, mappers=vtk_mappers)] if use_vtk else []
    return installed.bench_render(volume, references=refs, **kwargs)


def bench_render_cases(cases: list[RenderCase], **kwargs: Any) -> list[BenchReport]:
    """:func:`bench_render` of each case (``kwargs`` as there), one report per case."""
    return [
        bench_render(
            c.volume, transfer_function=c.transfer_function, modes=c.modes, label=c.label, **kwargs
        )
        for c in cases
    ]


def case_summary(report: BenchReport) -> dict[str, Any]:
    """The key numbers of one case: voxwarp dvr ms, covered share, ms per covered
    megapixel and the speed-ups over the references measured (JSON-ready)."""
    ours = report.find("voxwarp", "dvr")
    pixels = report.size[0] * report.size[1] * max(report.covered, 0.0)
    out: dict[str, Any] = {
        "case": report.label or report.volume,
        "volume": report.volume,
        "voxwarp_dvr_ms": None if ours is None else round(ours.median_ms, 2),
        "covered": round(report.covered, 4),
        "ms_per_covered_mpixel": (
            None if ours is None or pixels <= 0 else round(ours.median_ms / (pixels / 1e6), 2)
        ),
    }
    for ref in (
        "voxwarp, no skipping",
        installed.GRADIENTS_ON_THE_FLY,
        "VTK fixed-point (CPU)",
        "VTK GPU raycaster",
    ):
        ratio = report.ratio(ref, "dvr")
        out[f"speedup_vs_{ref}"] = None if ratio is None else round(ratio, 3)
    return out


def add_bench_render_parser(bsub: Any) -> None:
    """The ``render`` sub-command (the options of the former ``voxwarp bench render``)."""
    pbr = bsub.add_parser("render", help="raycaster timings vs VTK and no-skipping")
    add_render_bench_args(pbr)
    pbr.add_argument("--no-vtk", action="store_true", help="skip the VTK references")
    pbr.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    pbr.set_defaults(func=cmd_bench_render)


def cmd_bench_render(args: argparse.Namespace) -> int:
    """``python -m benchmarks render``: without an input the standard run (a sparse and
    two dense cases)."""
    from voxwarp.core.files import atomic_write_text

    cases = render_bench_cases(args)
    reports = bench_render_cases(
        cases,
        size=args.size,
        frames=args.frames,
        warmup=args.warmup,
        use_vtk=not args.no_vtk,
        step=args.step,
        view=args.view,
        log=lambda s: print(s, file=sys.stderr),
    )
    command = "python -m benchmarks " + " ".join(sys.argv[1:])
    text = "\n".join(report.markdown(command) for report in reports)
    print(text)
    for report in reports:
        for mode in ("dvr", "mip"):
            ratio = report.ratio("VTK fixed-point (CPU)", mode)
            if ratio is not None:
                print(
                    f"{report.label or report.volume} {mode}: voxwarp is {ratio:.2f}x the"
                    " speed of VTK's fixed-point raycaster"
                )
    if args.markdown:
        atomic_write_text(Path(args.markdown), text)
    return 0
