"""``python -m benchmarks wire-ends``: the rigid sweep against smooth wire ends on real scans.

Issue 20: a wire that ends inside an object cuts it with the wire paper's rigid sweep,
and coarse attribute fields leave blocky seams along the cut. Per case and ends mode
(``rigid``, ``smooth``), the field is built at 1:1, 1:8 and 1:64 and each render is
compared with the 1:1 render of the same mode: the share of pixels differing by more
than :data:`SEAM_LEVEL`/255 in a channel and the mean difference (what the coarse field
adds), beside the median build time and frame time of smooth over rigid at 1:8.

Cases (bundled samples):

* ``colin27``: the MRI head, a wire up the middle ending 14 mm below the top of the
  head (the content's top), its top moved 40 mm sideways, radius 80 mm;
* ``stent``: the CT's stent graft, a wire along its upper part (radius 30 mm) bent
  25 mm sideways, falloff 20 mm;
* ``stentbody``: the automatic wire of ``voxwarp demo INPUT`` on the same CT
  (:func:`voxwarp.teaching.auto_wire.auto_wire` is teaching code, so this case lays the
  same kind of wire itself: :func:`benchmarks.wire_tables.axis_wire` along the body).

Frames exclude warm-up (two untimed frames per scene); builds exclude the first, untimed.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.wire_tables import axis_wire
from benchmarks.wires import content_box
from voxwarp.bench.command import add_bench_parser, emit_report
from voxwarp.core.checks import image_size
from voxwarp.core.volume import Volume

#: cases of the run
CASES: tuple[str, ...] = ("colin27", "stent", "stentbody")
#: field scales compared with 1:1
SCALES: tuple[int, ...] = (2, 4)
#: a pixel differs when a channel differs by more than this (of 255)
SEAM_LEVEL = 24
ENDS: tuple[str, ...] = ("rigid", "smooth")


@dataclass
class EndsRow:
    """One case and ends mode."""

    case: str
    ends: str
    #: scale -> (% pixels differing from 1:1, mean difference /255)
    seams: dict[int, tuple[float, float]] = field(default_factory=dict)
    build_s: float = 0.0  # median build at 1:8
    frame_ms: float = 0.0  # median frame at 1:8


def head_wire(vol: Volume, ends: str) -> Any:
    """The colin27 case: up the middle of the head, ending 14 mm below its top."""
    from voxwarp.deform.wires.field import Wire

    lo, hi = content_box(vol)
    c = 0.5 * (lo + hi)
    zs = np.linspace(lo[2] + 0.25 * (hi[2] - lo[2]), hi[2] - 14.0, 4)
    s = (zs - zs[0]) / (zs[-1] - zs[0])
    base = [[c[0], c[1], z] for z in zs]
    mod = [[c[0] + 40.0 * si**2, c[1], z] for si, z in zip(s, zs, strict=True)]
    return Wire(base, mod, radius=80.0, beta=(20, 255), ends=ends, sides="rigid")


def graft_wire(vol: Volume, ends: str) -> Any:
    """The stent case: along the graft's upper part, moved sideways."""
    from voxwarp.deform.wires.field import Wire

    zs = np.array([150.0, 190.0, 230.0, 262.0])
    s = (zs - zs[0]) / (zs[-1] - zs[0])
    base = [[62.0, 64.0, z] for z in zs]
    mod = [[62.0 + 25.0 * si**2, 64.0, z] for si, z in zip(s, zs, strict=True)]
    return Wire(base, mod, radius=30.0, beta=(8, 40), ends=ends, falloff=20.0, sides="rigid")


def body_wire(vol: Volume, ends: str) -> Any:
    """The stentbody case: along the body's principal axis, bent sideways."""
    from voxwarp.deform.wires.field import Wire

    lo, hi = vol.value_range
    w = axis_wire(vol, lo + 0.25 * (hi - lo), bend=0.2)
    return Wire(
        w.base.control_points,
        w.modified.control_points,
        radius=w.radius,
        beta=w.beta,
        ends=ends,
        sides="rigid",
    )


_CASES: dict[str, tuple[str, Callable[[Volume, str], Any]]] = {
    "colin27": ("colin27", head_wire),
    "stent": ("stent", graft_wire),
    "stentbody": ("stent", body_wire),
}


def _render(r: Any, scene: Any) -> np.ndarray:
    return r.render(scene)[..., :3].astype(np.float64)


def measure_case(
    case: str, size: tuple[int, int] = (384, 384), frames: int = 3, repeats: int = 2
) -> list[EndsRow]:
    """Both ends modes of one case (see the module docstring)."""
    from voxwarp.deform.wires.field import WireDeformer
    from voxwarp.io.samples import load_sample, suggested_transfer_function
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    sample, make = _CASES[case]
    vol = load_sample(sample)
    base = Scene(
        vol,
        mode="dvr",
        transfer_function=suggested_transfer_function(sample),
        view="-y",
        zoom=1.3,
        jitter=False,
    )
    rows = []
    with OffscreenRenderer(*size) as r, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rigid sweep warns about its cut ends
        for ends in ENDS:
            row = EndsRow(case, ends)
            images = {}
            for scale in (1, *SCALES):
                wd = WireDeformer(vol, [make(vol, ends)], field_scale=scale)
                wd.build()
                scene = base.copy(warps=[wd.warp()])
                images[scale] = _render(r, scene)
                if scale == 2:
                    times = []
                    for _ in range(max(1, repeats)):
                        t = time.perf_counter()
                        wd.build()
                        times.append(time.perf_counter() - t)
                    row.build_s = statistics.median(times)
                    row.frame_ms = statistics.median(r.time_frames(scene, frames, warmup=2))
                wd.warp().release()
            for scale in SCALES:
                d = np.abs(images[scale] - images[1]).max(axis=-1)
                row.seams[scale] = (100.0 * float((d > SEAM_LEVEL).mean()), float(d.mean()))
            rows.append(row)
    return rows


def bench_wire_ends(
    cases: Sequence[str] = CASES,
    size: tuple[int, int] = (384, 384),
    log: Callable[[str], None] = print,
) -> list[EndsRow]:
    """:func:`measure_case` for each case."""
    rows: list[EndsRow] = []
    for case in cases:
        rows += measure_case(case, size)
        log(f"{case}: " + ", ".join(f"{r.ends} 1:8 {r.seams[2][0]:.2f} %" for r in rows[-2:]))
    return rows


def markdown(rows: Sequence[EndsRow], command: str) -> str:
    """The report: seams per case, mode and scale; smooth / rigid costs."""
    head = " | ".join(f"1:{s**3} % px (mean)" for s in SCALES)
    lines = [
        f"Command: `{command}`",
        "",
        f"| case | ends | {head} | build s (1:8) | frame ms (1:8) |",
        "|---|---|" + "---:|" * (len(SCALES) + 2),
    ]
    for r in rows:
        cells = " | ".join(f"{r.seams[s][0]:.2f} ({r.seams[s][1]:.2f})" for s in SCALES)
        lines.append(f"| {r.case} | {r.ends} | {cells} | {r.build_s:.2f} | {r.frame_ms:.0f} |")
    lines.append("")
    by = {(r.case, r.ends): r for r in rows}
    for case in dict.fromkeys(r.case for r in rows):
        rigid, smooth = by.get((case, "rigid")), by.get((case, "smooth"))
        if rigid and smooth and rigid.build_s and rigid.frame_ms:
            lines.append(
                f"* {case}: smooth / rigid build {smooth.build_s / rigid.build_s:.2f}x,"
                f" frame {smooth.frame_ms / rigid.frame_ms:.2f}x"
            )
    return "\n".join([*lines, ""])


def cmd_bench_wire_ends(args: argparse.Namespace) -> int:
    """``python -m benchmarks wire-ends``."""
    rows = bench_wire_ends(
        args.cases or CASES, size=args.size, log=lambda s: print(s, file=sys.stderr)
    )
    text = markdown(rows, "python -m benchmarks wire-ends " + " ".join(sys.argv[2:]))
    return emit_report(text, args.markdown)


def add_bench_wire_ends_parser(bsub: Any) -> None:
    """Add ``wire-ends`` to the ``bench`` sub-commands."""
    p = add_bench_parser(
        bsub,
        "wire-ends",
        "rigid vs smooth wire ends: seams at coarse fields on real scans, and cost",
        __doc__,
    )
    p.add_argument(
        "--case",
        dest="cases",
        action="append",
        choices=CASES,
        help="a case (repeat for several; default all)",
    )
    p.add_argument("--size", type=image_size, default=(384, 384), help="image WxH")
    p.add_argument("--markdown", metavar="FILE", help="also write the table to FILE")
    p.set_defaults(func=cmd_bench_wire_ends)
