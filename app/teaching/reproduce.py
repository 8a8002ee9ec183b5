"""``voxwarp reproduce``: the papers' tables and figures regenerated on this machine.

Runs every teaching demo of :mod:`voxwarp.teaching.demos` (their measurements, not copies of them),
writes their figure sheets into a folder beside the report (``docs/reproduction/`` for
``docs/reproduction.md``) and a markdown report: the hardware (CPU model, cores, memory,
GL renderer, OpenCL device), the date, the command, and per table or figure the papers'
numbers beside ours.

The papers' numbers come from :mod:`voxwarp.teaching.papers` (each with its table or
figure); a cell says :data:`voxwarp.teaching.papers.PAPER_HAS_NONE` where the paper prints
no number for that row (the thesis prints none at all). Absolute times of 2006-2010
hardware do not compare with ours, so the report puts ratios beside ratios. Timings
exclude compilation and warm-up (each demo runs every timed case at least once before
timing it). With ``--quick`` the sizes are too small for timing ratios to mean anything:
those cells say :data:`QUICK_SKIP` instead of a number.
"""

from __future__ import annotations

import datetime
import math
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from voxwarp.core.files import atomic_write_text
from voxwarp.core.timing import cpu_count, cpu_model, load_average
from voxwarp.teaching.demos import DEMO_TITLES, DEMOS, DemoResult, run_demo
from voxwarp.teaching.papers import (
    LATTICE_FPS,
    LATTICE_SHADER_COMPLEXITY,
    PAPER_HAS_NONE,
    WIRE_FIG12_BUILD_S,
    WIRE_FLOAT_BYTES_PER_VOXEL,
    WIRE_PAPER_LAYOUT_BITS,
    WIRE_TABLE1,
    WIRE_TIMING_IMAGE,
    WIRE_TIMING_MACHINE,
    WIRE_TIMINGS,
    fmt_ratio,
    wire_render_ratio_range,
)

#: the report ``voxwarp reproduce`` writes by default (figures go to its stem's folder)
DEFAULT_REPORT = Path("docs/reproduction.md")
#: what the thesis columns say: the thesis reports images, no measured numbers
THESIS_HAS_NONE = "none in the thesis"
#: the lab's commands behind the numbers the installed demos leave to it
WIRE_TABLES_COMMAND = "python -m benchmarks wire-tables"
LATTICE_COMMAND = "python -m benchmarks lattice"
#: what a timing cell says in a ``--quick`` run
QUICK_SKIP = "not measured in --quick"


def reproduce(
    out_md: str | os.PathLike = DEFAULT_REPORT,
    quick: bool = False,
    *,
    log: Callable[[str], None] | None = None,
    command: str | None = None,
) -> Path:
    """Run every demo and write the reproduction report.

    Parameters
    ----------
    out_md
        The markdown report; the figure sheets go to the folder of the same name without
        the suffix (``docs/reproduction.md`` -> ``docs/reproduction/``).
    quick
        The demos' quick sizes (seconds; the numbers then do not compare with the
        papers', and the report says so).
    log
        Progress messages go here (default: nowhere).
    command
        The command line to record (default: ``voxwarp reproduce`` with its options).

    Returns
    -------
    pathlib.Path
        The report.
    """
    say = log or (lambda _s: None)
    out = Path(out_md)
    fig_dir = out.with_suffix("")
    if command is None:
        command = "voxwarp reproduce" + (" --quick" if quick else "")
        if out != DEFAULT_REPORT:
            command += f" --out {out}"
    started = datetime.datetime.now(datetime.UTC)
    t0 = time.perf_counter()
    load = [load_average()]
    results = {name: _run_keeping_figures(name, fig_dir, quick, say) for name in DEMOS}
    seconds = time.perf_counter() - t0
    load.append(load_average())
    text = report_markdown(results, out, command, started, seconds, quick, load=tuple(load))
    atomic_write_text(out, text)
    say(f"reproduce: {out} ({seconds:.0f} s)")
    return out


def _run_keeping_figures(
    name: str, fig_dir: Path, quick: bool, say: Callable[[str], None]
) -> DemoResult:
    """Run demo ``name`` in a scratch folder and move only its figure sheets into
    ``fig_dir`` (demos also write data for the reader to try, e.g. the registration's
    transform files: tens of MB that do not belong beside a report)."""
    say(f"reproduce: {name} ...")
    fig_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=".reproduce-", dir=fig_dir) as tmp:
        result = run_demo(name, Path(tmp), quick=quick, log=say)
        kept = []
        for fig in result.figures:
            dest = fig_dir / fig.name
            os.replace(fig, dest)
            kept.append(dest)
    result.figures = kept
    return result


# ---------------------------------------------------------------------- hardware


def memory_gib() -> float | None:
    """Total memory (GiB) from /proc/meminfo, or None."""
    try:
        with open("/proc/meminfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) / 2**20
    except (OSError, ValueError, IndexError):
        pass
    return None


def hardware(results: dict[str, DemoResult], load: Sequence[float] = ()) -> list[tuple[str, str]]:
    """The hardware section's rows.

    Parameters
    ----------
    results
        The demos' results (their GL renderer and OpenCL device).
    load
        1-minute load averages at the start and the end of the run (-1: unknown).

    Returns
    -------
    list of (str, str)
        (what, value) rows.
    """
    gl = next((r.numbers.get("gl_renderer") for r in results.values()), None) or "?"
    cl = ""
    if "wires" in results:
        cl = results["wires"].numbers.get("opencl_device") or ""
    mem = memory_gib()
    versions = [f"Python {platform.python_version()}"]
    for mod in ("numpy", "scipy", "numba", "moderngl", "matplotlib"):
        m = sys.modules.get(mod)
        if m is not None and hasattr(m, "__version__"):
            versions.append(f"{mod} {m.__version__}")
    return [
        ("CPU", f"{cpu_model()}, {cpu_count()} cores usable ({os.cpu_count()} logical)"),
        ("memory", f"{mem:.1f} GiB" if mem is not None else "unknown"),
        ('GL renderer (every "GPU" number below)', gl),
        (
            "OpenCL device (wire field propagation)",
            cl or "none: scipy fallback",
        ),
        ("OS", f"{platform.system()} {platform.release()} ({platform.machine()})"),
        ("software", ", ".join(versions)),
    ] + (
        [
            (
                "1-minute load average, start / end of the run",
                " / ".join(f"{v:.2f}" if v >= 0 else "?" for v in load),
            )
        ]
        if load
        else []
    )


# ---------------------------------------------------------------------- markdown
def _f(x: Any, fmt: str = ".3g") -> str:
    if x is None:
        return "—"
    return format(float(x), fmt)


def _rate(x: Any) -> str:
    """A rate: one decimal below 100, whole numbers above."""
    if x is None:
        return "—"
    return f"{float(x):.1f}" if float(x) < 100 else f"{float(x):.0f}"


def _table(head: Sequence[str], rows: Sequence[Sequence[Any]], align: str = "") -> list[str]:
    """A markdown table; ``align`` one character per column: l or r (default l then r)."""
    align = align or "l" + "r" * (len(head) - 1)
    sep = ["---:" if a == "r" else "---" for a in align]
    out = ["| " + " | ".join(head) + " |", "| " + " | ".join(sep) + " |"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return [*out, ""]


def _figure_link(result: DemoResult, out: Path, figure: Path | None = None, title: str = "") -> str:
    """A markdown image of the demo's (first) figure sheet, relative to the report."""
    fig = result.figure if figure is None else figure
    rel = os.path.relpath(fig.resolve(), out.parent.resolve())
    return f"![{title or DEMO_TITLES[result.name]}]({Path(rel).as_posix()})"


def _extra_figure_links(result: DemoResult, out: Path) -> list[str]:
    """Links to the further sheets a demo's numbers name (``extra_figures``: ``[{"file":
    "NAME.png", "title": ...}]``), each followed by a blank line."""
    by_name = {f.name: f for f in result.figures}
    lines = []
    for extra in result.numbers.get("extra_figures", []):
        fig = by_name.get(extra["file"])
        if fig is not None:
            lines += [_figure_link(result, out, fig, extra["title"]), ""]
    return lines


def report_markdown(
    results: dict[str, DemoResult],
    out: Path,
    command: str,
    started: datetime.datetime,
    seconds: float,
    quick: bool,
    load: Sequence[float] = (),
) -> str:
    """The reproduction report (markdown) of the demos' ``results``.

    Parameters
    ----------
    results
        :func:`voxwarp.teaching.demos.run_demo`'s result per demo.
    out
        Where the report goes (figure links are relative to its folder).
    command
        The command line to record.
    started, seconds
        When the run started (UTC) and how long it took.
    quick
        Whether the demos ran at their quick sizes (the report then says so).
    load
        1-minute load averages at the start and the end of the run.

    Returns
    -------
    str
        The markdown text.
    """
    per_demo = ", ".join(f"{n} {r.seconds:.0f} s" for n, r in results.items())
    lines = [
        "# Reproduction: the papers' tables and figures on this machine",
        "",
        f"Generated by `{command}` on {started:%Y-%m-%d %H:%M} UTC; the whole run took"
        f" {seconds / 60:.1f} min ({per_demo})."
        " Each section is one teaching demo (`voxwarp demo NAME` draws the same sheet);"
        " all timings of a table come from the same run, on a shared machine (noisy).",
        "",
    ]
    if quick:
        lines += [
            "**Quick run (`--quick`)**: every size is reduced so that the run takes"
            " seconds; the numbers below do not compare with the papers'.",
            "",
        ]
    lines += [
        "Every paper number below is quoted with its table or figure"
        " (`voxwarp/teaching/papers.py` holds them; a test checks them against the papers'"
        f' text). "{PAPER_HAS_NONE}" / "{THESIS_HAS_NONE}" mark rows the source does not'
        " measure: the 2008 thesis shows images only. Absolute times of the papers' 2006-2010"
        " machines do not compare with ours, so ratios stand beside ratios. Timings exclude"
        " program compilation, kernel builds and first-use allocations: every timed case"
        " runs at least once untimed first. The full benchmarks are the lab's, in a checkout:"
        " `python -m benchmarks massspring | chainmail | wires | wire-tables | lattice`"
        " (`docs/bench-*.md`).",
        "",
        "## Hardware",
        "",
        *_table(["", ""], hardware(results, load), "ll"),
    ]
    sections = {
        "massspring": _massspring_section,
        "chainmail": _chainmail_section,
        "compare": _compare_section,
        "wires": _wires_section,
        "lattice": _lattice_section,
        "registration": _registration_section,
    }
    for i, name in enumerate(DEMOS, start=1):
        if name not in results:
            continue
        r = results[name]
        lines += [f"## {i}. {DEMO_TITLES[name]}", "", _figure_link(r, out), ""]
        lines += _extra_figure_links(r, out)
        lines += sections[name](r.numbers, quick)
        for extra in r.figures[1:]:  # a demo's further sheets close its section
            rel = os.path.relpath(extra.resolve(), out.parent.resolve())
            lines += [f"![{DEMO_TITLES[name]}: {extra.stem}]({Path(rel).as_posix()})", ""]
    return "\n".join(lines).rstrip() + "\n"


def _thresholds(sweep: dict[str, Any], integ: str) -> tuple[float | None, float | None]:
    """(largest dt that stayed below 2x its starting energy, smallest dt that grew past
    1000x) of one integrator in the stability sweep, in ms."""
    stable = unstable = None
    for dt, g in zip(sweep["dt_s"], sweep["growth"][integ], strict=True):
        if g is not None and g < 2.0:
            stable = dt * 1000
        if (g is None or g > 1e3) and unstable is None:
            unstable = dt * 1000
    return stable, unstable


def _massspring_section(n: dict[str, Any], quick: bool = False) -> list[str]:
    sw = n["sweep"]
    st = n["stable_dt_s"]
    rows = []
    for integ in ("explicit", "semi-implicit"):
        ok, bad = _thresholds(sw, integ)
        rows.append(
            [
                f"{integ} Euler: time step",
                THESIS_HAS_NONE,
                f"guaranteed stable {st[integ] * 1000:.2f} ms; measured: stays below 2x its"
                f" energy up to {_f(ok, '.3g')} ms, grows past 1000x from"
                f" {_f(bad, '.3g')} ms ({sw['steps']} steps)",
            ]
        )
    e0 = n["initial_energy"]
    blew = n["explicit_blew_up_at_s"]
    t_end = n["time_s"][-1]
    for label in ("explicit", "explicit + clamp", "semi-implicit"):
        final = n["final_energy"][label]
        if label == "explicit" and blew is not None:
            what = f"blew up (> 1e9x) at t = {blew:.2f} s"
        else:
            what = f"{final / e0:.3g}x the energy at t = 0 after {t_end:.1f} s"
        rows.append([f"{label} at dt = {n['dt_s'] * 1000:.1f} ms", THESIS_HAS_NONE, what])
    rows.append(
        [
            "semi-implicit: steps until settled (< 0.001 mm/s)",
            THESIS_HAS_NONE,
            str(n["settle_steps"]),
        ]
    )
    return [
        f"The {n['volume']} on an {'x'.join(map(str, n['grid']))} element grid, elements"
        f" {n['fixed']} fixed, two tail elements dragged {n['drag_mm'][1]:g} mm sideways;"
        " structural and shear springs. The thesis uses explicit Euler with a displacement"
        " clamp (section 3.5.2) and gives no stability figures.",
        "",
        *_table(["quantity", "thesis", "here"], rows, "lll"),
    ]


def _chainmail_section(n: dict[str, Any], quick: bool = False) -> list[str]:
    se, fe = n["smoothness_energy"], n["fish"]["smoothness_energy"]
    rows = [
        [
            "elements moved by one drag (Gibson / enhanced)",
            THESIS_HAS_NONE,
            f"{n['touched']['gibson']} / {n['touched']['enhanced']}",
        ],
        [
            "constraint checks (Gibson lists / enhanced queue pops)",
            THESIS_HAS_NONE,
            f"{n['checks']['gibson']} / {n['checks']['enhanced']}",
        ],
        [
            "Gibson's move order follows its sponsor rule (x lists, then y, then z)",
            "(the algorithm)",
            "yes" if n["sponsor_rule_holds"] else "NO",
        ],
        [
            "largest difference of the two variants' end states",
            "(same state for one drag)",
            f"{n['variants_max_difference_mm']:.3g} mm",
        ],
    ]
    for k in (0, 1, 4):
        rows.append(
            [
                f"smoothness energy after {k} relaxation step{'s' * (k != 1)} (12x9x3 grid / fish)",
                "Figure 13: images, no numbers",
                f"{_f(se[k], '.0f')} / {_f(fe[k], '.0f')} mm²",
            ]
        )
    rows.append(
        [
            "largest link violation after relaxing",
            "(0: links stay within limits)",
            f"{n['violation_after_relax_mm']:.3g} mm",
        ]
    )
    return [
        f"A {'x'.join(map(str, n['grid']))} grid (10 mm spacing, {n['fixed']} fixed), element"
        f" {tuple(n['dragged'])} dragged {n['drag_mm'][1]:g} mm along +y; the fish as in"
        " section 1. The thesis' Figure 13 shows the fish after 0, 1 and 4 relaxation steps.",
        "",
        *_table(["quantity", "thesis", "here"], rows, "lll"),
    ]


def _registration_section(n: dict[str, Any], quick: bool = False) -> list[str]:
    """Not a paper's result: a demons registration rendered through its field."""
    rows = [
        [
            "mean abs. difference of the renders",
            f"{n['render_mad_before']:.1f}",
            f"{n['render_mad_after']:.1f}",
        ],
        [
            "mean abs. difference of the volumes",
            f"{n['volume_mad_before']:.1f}",
            f"{n['volume_mad_after']:.1f}",
        ],
    ]
    return [
        f"No paper: SimpleITK demons ({n['registration_seconds']:.1f} s) on colin27 and a"
        f" known deformation; mean |u| {n['recovered_mean_mm']:.2f} mm recovered vs"
        f" {n['known_mean_mm']:.2f} mm known, mean error {n['field_error_mm']:.2f} mm.",
        "",
        *_table(["fixed vs moving", "before", "after (through the field)"], rows, "lrr"),
    ]


def _compare_section(n: dict[str, Any], quick: bool = False) -> list[str]:
    ms, cm = n["massspring"], n["chainmail"]
    rows = [
        [
            f"elements moved (of {math.prod(n['grid'])})",
            THESIS_HAS_NONE,
            f"{ms['moved']}",
            f"{cm['moved']} (+4 relaxation steps: {cm['moved_after_relax4']})",
        ],
        [
            "time to the settled shape",
            THESIS_HAS_NONE,
            f"{ms['seconds'] * 1000:.0f} ms ({ms['settle_steps']} steps)",
            f"{cm['move_ms']:.2f} ms (one move)",
        ],
        [
            "largest displacement",
            THESIS_HAS_NONE,
            f"{ms['max_displacement_mm']:.1f} mm",
            f"{max(n['drag_mm']):.1f} mm (the drag)",
        ],
    ]
    lines = [
        "Thesis Figures 12-13: the same drag in both models (images, no numbers)."
        " RMS difference of the settled mass-spring and the relaxed ChainMail grids:"
        f" {n['rms_difference_mm']:.1f} mm.",
        "",
        *_table(["quantity", "thesis", "mass-spring", "ChainMail"], rows, "llll"),
    ]
    tm = n["timings"]
    sizes = sorted({r["size"] for r in tm["massspring"]})
    rows = []
    for size in sizes:
        rate = {r["backend"]: r["steps_per_s"] for r in tm["massspring"] if r["size"] == size}
        cpu, gpu = rate.get("numpy"), rate.get("gpu")
        ratio = f"{gpu / cpu:.2f}x" if cpu and gpu else "—"
        rows.append([f"{size}³", THESIS_HAS_NONE, _rate(cpu), _rate(gpu), ratio])
    lines += [
        f"Mass-spring steps per second ({tm['massspring_integrator']} Euler, the benchmark"
        f" model of `python -m benchmarks massspring`); GPU = {n['gl_renderer']}:",
        "",
        *_table(["grid", "thesis", "CPU (numpy)", "GPU", "GPU / CPU"], rows),
    ]
    rows = []
    csizes = sorted({r["size"] for r in tm["chainmail"]})
    for size in csizes:
        for drag in ("local", "large"):
            ms_by = {
                r["solver"]: r["ms"]
                for r in tm["chainmail"]
                if r["size"] == size and r["drag"] == drag
            }
            touched = next(
                (
                    r["touched"]
                    for r in tm["chainmail"]
                    if r["size"] == size and r["drag"] == drag and r["solver"] != "gpu"
                ),
                "—",
            )
            rows.append(
                [
                    f"{size}³ {drag}",
                    THESIS_HAS_NONE,
                    _f(ms_by.get("gibson")),
                    _f(ms_by.get("enhanced")),
                    _f(ms_by.get("gpu")),
                    touched,
                ]
            )
    lines += [
        "ChainMail ms per move (`python -m benchmarks chainmail`'s drags: local = 1 spacing,"
        f" large = 20 spacings); GPU = {tm['gl_renderer']}:",
        "",
        *_table(
            ["grid, drag", "thesis", "CPU Gibson", "CPU enhanced", "GPU", "elements moved"],
            rows,
        ),
    ]
    return lines


def _wires_section(n: dict[str, Any], quick: bool = False) -> list[str]:
    lines = _wires_fig12(n, quick)
    if n["rows"] and "error_vs_1to1" in n["rows"][0]:
        lines += _wires_fig12_error(n)
    if n.get("storage"):
        lines += _wires_storage(n["storage"])
    lines += _wires_tables()
    rc = n["render_cost"]
    if rc:
        lo, hi = wire_render_ratio_range()
        here = f"{rc['ratio']:.2f}x ({rc['deformed_ms']:.1f} vs {rc['undeformed_ms']:.1f} ms)"
        lines += _table(
            ["render cost, deformed / undeformed", "paper (Tables 2-3)", "here"],
            [
                [
                    f"dvr, the fish bent, field 1:{rc['scale'] ** 3},"
                    f" {n['image'][0]}x{n['image'][1]}",
                    f"{lo:.2f}-{hi:.2f}x (identity deformation, software raycaster)",
                    QUICK_SKIP if quick else here,
                ]
            ],
            "lll",
        )
    return lines


def _wires_fig12(n: dict[str, Any], quick: bool) -> list[str]:
    """Figure 12: field build time per scale, relative to 1:1 on both sides."""
    rows = []
    base = n["rows"][0]["build_s"] if n["rows"] else None
    paper_base = WIRE_FIG12_BUILD_S[1]
    for r in n["rows"]:
        paper = WIRE_FIG12_BUILD_S.get(r["scale"])
        rel = QUICK_SKIP if quick or not base else f"{r['build_s'] / base:.3f}"
        rows.append(
            [
                r["ratio"],
                "x".join(map(str, r["field_shape"])),
                "—" if paper is None else f"{paper:.2f}",
                "—" if paper is None else f"{paper / paper_base:.3f}",
                f"{r['build_s']:.3f}",
                rel,
                f"{r['percent_ignored_voxels']:.2f}",
                f"{r['pixels_differing_from_1to1']:.2f}",
            ]
        )
    return [
        f"{n['volume']}, wires `{n['wire_file']}`; float field layout, OpenCL:"
        f" {n['opencl_device'] or 'none'}. The paper's Figure 12 times builds on the"
        " Visible Human (its own deformation); both columns of times are also given"
        " relative to their 1:1 build. Each build was run once untimed before the timed"
        " ones (OpenCL kernels and buffers of that grid size).",
        "",
        *_table(
            [
                "field",
                "shape",
                "paper build s (Fig. 12)",
                "paper / 1:1",
                "build s",
                "here / 1:1",
                "% field voxels ignored",
                "% pixels differing from 1:1",
            ],
            rows,
            "llrrrrrr",
        ),
    ]


def _wires_fig12_error(n: dict[str, Any]) -> list[str]:
    """Figure 12's artefacts measured: each coarse field's mapping against the 1:1
    field's at the same points (:func:`voxwarp.teaching.wire_measure.field_error`)."""
    rows = []
    for r in n["rows"]:
        e = r["error_vs_1to1"]
        om, sm = e["object_mm"], e["swept_mm"]
        rows.append(
            [
                r["ratio"],
                f"{e['object_points']:,}",
                f"{e['percent_reclassified']:.2f}",
                f"{e['percent_value_off']:.2f}",
                f"{om['rms']:.3f} / {om['p99']:.3f} / {om['max']:.3f}",
                f"{sm['rms']:.4f} / {sm['max']:.3f}",
                f"{r['pixels_differing_from_1to1']:.2f}",
            ]
        )
    voxel = min(n["spacing"]) if n.get("spacing") else float("nan")
    last = n["rows"][-1]["error_vs_1to1"]["object_mm"]
    return [
        "Figure 12's artefacts, measured: the paper shows the Visible Human blocky at"
        " 1:512-1:4096 (trilinear interpolation across the coarse field's large gaps)."
        " Here each coarse field maps the same points as the 1:1 field (voxel centres,"
        f" {n.get('error_stride', 1)} voxels apart per axis, that either field moves and"
        " whose value through either mapping is the object's); distances in mm between the"
        " two mapped points. voxwarp's field stores per voxel whether it is swept, by"
        " which wire (nearest voxel) and the fraction t along the wire (trilinear); the"
        " displacement itself is computed per sample from the wire, so interpolating t,"
        " which changes smoothly along the wire, errs little even across 16 voxels"
        ' (the "both swept" column). What coarsens is where the swept region ends:'
        " coarse voxels classify a sample swept or not in blocks, mostly in air beside the"
        f" object. At {n['rows'][-1]['ratio']} the mapping's RMS error over the object is"
        f" {last['rms']:.3f} mm, {last['rms'] / voxel:.2f} of a voxel ({voxel:.3f} mm),"
        " and the pictures differ from the 1:1 one in few pixels (last column; the close-up"
        " of the bent tail at each scale and its differences from 1:1 close this section).",
        "",
        *_table(
            [
                "field",
                "object points",
                "% classified otherwise",
                "% values off > 5 % of range",
                "object mm RMS / p99 / max",
                "both swept mm RMS / max",
                "% pixels differing from 1:1",
            ],
            rows,
            "lrrrrrr",
        ),
    ]


def _wires_storage(rows: Sequence[dict[str, Any]]) -> list[str]:
    """Section 7.2's storage per layout and 7.1's plane-mask memory."""
    flag, wire, segment, t = WIRE_PAPER_LAYOUT_BITS
    paper = {
        "float": f"at least {WIRE_FLOAT_BYTES_PER_VOXEL} (float t, 7-bit wire, flag)",
        "packed": "none (voxwarp's: flag, 7-bit wire, 8-bit t over the wire)",
        "paper": f"2 (flag {flag} bit, wire {wire}, segment {segment}, t {t})",
    }
    table = [
        [
            r["layout"],
            paper.get(r["layout"], PAPER_HAS_NONE),
            f"{r['bytes_per_voxel']:g}",
            f"{r['field_bytes'] / 2**20:.2f}",
            f"{r['mask_bytes']:,}",
        ]
        for r in rows
    ]
    shape = "x".join(map(str, rows[0]["field_shape"]))
    return [
        f"Storage (section 7.2) of the fish's {shape} field, and the plane masks' memory"
        " (section 7.1: the sum over the planes of area times resolution / 8 bytes; the"
        " paper gives the formula, no number).",
        "",
        *_table(
            ["layout", "paper bytes / voxel", "bytes / voxel", "field MiB", "mask bytes"],
            table,
        ),
    ]


def _wires_tables() -> list[str]:
    """Tables 1-3, the paper's rows: voxwarp's, measured the paper's way on its datasets,
    come from the lab (``python -m benchmarks wire-tables`` in a checkout)."""
    t1 = [[p.dataset, f"{p.samples:,}", f"{p.percent:.1f}"] for p in WIRE_TABLE1]
    t23 = [
        [
            p.dataset,
            f"{p.standard_s:.2f} s",
            f"{p.preprocessing_s:.2f} s",
            f"{p.render_s:.2f} s",
            fmt_ratio(p.render_ratio),
            fmt_ratio(p.total_ratio),
        ]
        for p in WIRE_TIMINGS
    ]
    w, h = WIRE_TIMING_IMAGE
    return [
        "Table 1 (ray samples inside the attribute field that need no mapping) and Tables"
        " 2-3 (the render without deformation and through an identity deformation, at"
        f" {w}x{h} on a {WIRE_TIMING_MACHINE}), the paper's numbers. voxwarp's, counted and"
        " timed the paper's way on its datasets, are a full study of the lab:"
        f" `{WIRE_TABLES_COMMAND}` in a checkout (docs/benchmarks.md).",
        "",
        *_table(["dataset (Table 1)", "samples in the field", "% ignored"], t1),
        *_table(
            [
                "dataset (Tables 2-3)",
                "standard render",
                "preprocessing",
                "identity render",
                "render ratio",
                "total ratio",
            ],
            t23,
        ),
    ]


def _lattice_section(n: dict[str, Any], quick: bool = False) -> list[str]:
    spheres, *helices = LATTICE_FPS
    cpu_paper = " / ".join(f"{h.ratio:.1%} ({h.objects} objects)" for h in helices)
    vertex_paper = f"none (its shader: ~{LATTICE_SHADER_COMPLEXITY:g}x the work, section 6)"
    here = f"`{LATTICE_COMMAND}`"
    rows = [
        ["vertex throughput, vertex stage only", vertex_paper, here],
        ["composition, static redraw", PAPER_HAS_NONE, here],
        [
            "normals (section 4.2): angle to the exact normals, direct (J n) and tangent space",
            "Figure 5: images, no numbers",
            here + " (section 5); the demo's figure shows both",
        ],
    ]
    return [
        "The paper's table (section 6, GeForce 8800) gives linear (4x4) and trilinear frame"
        f" rates of its own scenes: {spheres.ratio:.1%} for {spheres.triangles} triangles on"
        f" the GPU and {cpu_paper} when many objects are composed on the CPU (its text rounds"
        " them to 75, 80 and 77 %). voxwarp rebuilds the three scenes with the same object"
        " and triangle counts (`voxwarp.teaching.grapp_scenes`: a bent body with chains of"
        " spheres anchored to it; a rope of spheres wound into a helix under a swaying"
        " root) and times them here, each row beside the paper's:",
        "",
        *_grapp_table(n.get("grapp_scenes", []), quick, n.get("gl_renderer", "?")),
        "Further studies, with a torus of 1.5 M triangles and 2,000 composed objects, are"
        f" the lab's: `{LATTICE_COMMAND}` in a checkout (docs/benchmarks.md).",
        "",
        *_table(["configuration", "paper", "measured by"], rows, "lll"),
        "Figure 8 (attachments following an animated base mesh): `voxwarp animate"
        " sample_volumes/lattice_accessories_anim.json -o body.mp4` (the paper's figure has"
        " no numbers).",
        "",
    ]


def _grapp_table(rows: Sequence[dict[str, Any]], quick: bool, renderer: str) -> list[str]:
    """The paper's scenes: its FPS beside ours (:mod:`voxwarp.teaching.grapp_measure`)."""
    if not rows:
        return ["(not measured in this run)", ""]
    w, h = rows[0]["size"]
    table = []
    for r in rows:
        if quick:
            ours = ratio = spent = QUICK_SKIP
        else:
            ours = f"{r['linear_fps']:.2f} / {r['trilinear_fps']:.2f}"
            ratio = f"{r['ratio']:.1%}"
            spent = (
                f"compose + wrap {r['trilinear_compose_ms']:.0f} of {r['trilinear_ms']:.0f} ms"
                f" trilinear, {r['linear_compose_ms']:.0f} of {r['linear_ms']:.0f} ms linear"
            )
        table.append(
            [
                f"{r['scene']} ({r['measures']})",
                f"{r['objects']:,}",
                f"{r['triangles']:,} (paper {r['paper_triangles']})",
                f"{r['paper_linear_fps']:g} / {r['paper_trilinear_fps']:g}",
                f"{r['paper_ratio']:.1%}",
                ours,
                ratio,
                spent,
                r.get("layout", ""),
            ]
        )
    return [
        *_table(
            [
                "scene",
                "objects",
                "triangles",
                "paper FPS linear / trilinear",
                "paper trilinear / linear",
                "here FPS linear / trilinear",
                "here trilinear / linear",
                "where a frame's time goes here",
                "our scene (the paper's differs)",
            ],
            table,
            "lrrrrrrll",
        ),
        f"Here: {w}x{h} images on GL {renderer} (the paper: a GeForce 8800 and a Core 2 Quad"
        f" 6600; its image size is not given), {rows[0]['frames']} timed frame(s) per"
        " variant after a warm-up, linear and trilinear frames alternated, medians. A frame"
        " is what an animated scene graph pays: `compose_scene` (per object from scratch, numpy),"
        " one mesh instance per object, one draw call per object and, for a lattice, a new"
        " node texture. The linear graphs are the same graphs with a rigid 4x4 in place of"
        " each lattice (the paper's scenes and its linear variant are its own; the meshes"
        " and layout here are ours). The frames are in the second figure.",
        "",
    ]
