"""``voxwarp reproduce``: the papers' tables and figures regenerated on this machine.

Runs every teaching demo of :mod:`voxwarp.teaching.demos` (their measurements, not copies of them),
writes their figure sheets into a folder beside the report (``docs/reproduction/`` for
``docs/reproduction.md``) and a markdown report: the hardware (CPU model, cores, memory,
GL renderer, OpenCL device), the date, the command, and per table or figure the papers'
numbers beside ours.

The papers' numbers come only from what this repository already quotes (and cites):
the GRAPP 2010 lattice paper's 75-80 % of the linear frame rate
(:data:`voxwarp.bench.lattice.PAPER_RATIO`, ``docs/bench-lattice.md``) and the wire paper's
software renderer paying 2.2-5.3x the undeformed frame (``docs/benchmarks.md``). Every
other paper cell says "not in the repo" instead of a number from memory.
"""

from __future__ import annotations

import datetime
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from voxwarp.core.files import atomic_write_text
from voxwarp.teaching.demos import DEMO_TITLES, DEMOS, DemoResult, run_demo

#: the report ``voxwarp reproduce`` writes by default (figures go to its stem's folder)
DEFAULT_REPORT = Path("docs/reproduction.md")
#: what a table says where a paper's number is not quoted in this repository
NOT_IN_REPO = "not in the repo"
#: the wire paper's render cost (deformed / undeformed frame of its software renderer),
#: as quoted in docs/benchmarks.md ("the paper's software renderer paid 2.2-5.3x")
PAPER_WIRE_RENDER_COST: tuple[float, float] = (2.2, 5.3)


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
    from voxwarp.bench.render import load_average

    started = datetime.datetime.now(datetime.UTC)
    t0 = time.perf_counter()
    load = [load_average()]
    results: dict[str, DemoResult] = {}
    for name in DEMOS:
        say(f"reproduce: {name} ...")
        results[name] = run_demo(name, fig_dir, quick=quick, log=say)
    seconds = time.perf_counter() - t0
    load.append(load_average())
    text = report_markdown(results, out, command, started, seconds, quick, load=tuple(load))
    atomic_write_text(out, text)
    say(f"reproduce: {out} ({seconds:.0f} s)")
    return out


# ---------------------------------------------------------------------- hardware
def cpu_model() -> str:
    """The CPU's model name from /proc/cpuinfo (else :func:`platform.processor`)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


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
    from voxwarp.bench.render import cpu_count

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


def _figure_link(result: DemoResult, out: Path) -> str:
    rel = os.path.relpath(result.figure.resolve(), out.parent.resolve())
    return f"![{DEMO_TITLES[result.name]}]({Path(rel).as_posix()})"


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
        "Where a paper's number is not quoted anywhere in this repository, the tables say"
        f' "{NOT_IN_REPO}" instead of a number from memory. Quoted: the GRAPP 2010'
        " lattice paper's 75-80 % of the linear frame rate (`docs/bench-lattice.md`) and"
        " the wire paper's software renderer at 2.2-5.3x the undeformed frame"
        " (`docs/benchmarks.md`). The full benchmarks are `voxwarp bench massspring |"
        " chainmail | wires | lattice` (`docs/bench-*.md`).",
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
        lines += sections[name](r.numbers)
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


def _massspring_section(n: dict[str, Any]) -> list[str]:
    sw = n["sweep"]
    st = n["stable_dt_s"]
    rows = []
    for integ in ("explicit", "semi-implicit"):
        ok, bad = _thresholds(sw, integ)
        rows.append(
            [
                f"{integ} Euler: time step",
                NOT_IN_REPO,
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
        rows.append([f"{label} at dt = {n['dt_s'] * 1000:.1f} ms", NOT_IN_REPO, what])
    rows.append(
        [
            "semi-implicit: steps until settled (< 0.001 mm/s)",
            NOT_IN_REPO,
            str(n["settle_steps"]),
        ]
    )
    return [
        f"The {n['volume']} on an {'x'.join(map(str, n['grid']))} element grid, elements"
        f" {n['fixed']} fixed, two tail elements dragged {n['drag_mm'][1]:g} mm sideways;"
        " structural and shear springs. The thesis uses explicit Euler with a displacement"
        " clamp (3.5.2); its stability figures are not quoted in the repo.",
        "",
        *_table(["quantity", "thesis", "here"], rows, "lll"),
    ]


def _chainmail_section(n: dict[str, Any]) -> list[str]:
    se, fe = n["smoothness_energy"], n["fish"]["smoothness_energy"]
    rows = [
        [
            "elements moved by one drag (Gibson / enhanced)",
            NOT_IN_REPO,
            f"{n['touched']['gibson']} / {n['touched']['enhanced']}",
        ],
        [
            "constraint checks (Gibson lists / enhanced queue pops)",
            NOT_IN_REPO,
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


def _registration_section(n: dict[str, Any]) -> list[str]:
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


def _compare_section(n: dict[str, Any]) -> list[str]:
    ms, cm = n["massspring"], n["chainmail"]
    rows = [
        [
            f"elements moved (of {math.prod(n['grid'])})",
            NOT_IN_REPO,
            f"{ms['moved']}",
            f"{cm['moved']} (+4 relaxation steps: {cm['moved_after_relax4']})",
        ],
        [
            "time to the settled shape",
            NOT_IN_REPO,
            f"{ms['seconds'] * 1000:.0f} ms ({ms['settle_steps']} steps)",
            f"{cm['move_ms']:.2f} ms (one move)",
        ],
        [
            "largest displacement",
            NOT_IN_REPO,
            f"{ms['max_displacement_mm']:.1f} mm",
            f"{max(n['drag_mm']):.1f} mm (the drag)",
        ],
    ]
    lines = [
        "Thesis Figures 12-13: the same drag in both models (images, no numbers in the"
        f" repo). RMS difference of the settled mass-spring and the relaxed ChainMail grids:"
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
        rows.append([f"{size}³", NOT_IN_REPO, _rate(cpu), _rate(gpu), ratio])
    lines += [
        f"Mass-spring steps per second ({tm['massspring_integrator']} Euler, the benchmark"
        f" model of `voxwarp bench massspring`); GPU = {n['gl_renderer']}:",
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
                    NOT_IN_REPO,
                    _f(ms_by.get("gibson")),
                    _f(ms_by.get("enhanced")),
                    _f(ms_by.get("gpu")),
                    touched,
                ]
            )
    lines += [
        "ChainMail ms per move (`voxwarp bench chainmail`'s drags: local = 1 spacing,"
        f" large = 20 spacings); GPU = {tm['gl_renderer']}:",
        "",
        *_table(
            ["grid, drag", "thesis", "CPU Gibson", "CPU enhanced", "GPU", "elements moved"],
            rows,
        ),
    ]
    return lines


def _wires_section(n: dict[str, Any]) -> list[str]:
    rows = []
    for r in n["rows"]:
        rows.append(
            [
                r["ratio"],
                "x".join(map(str, r["field_shape"])),
                NOT_IN_REPO,
                f"{r['build_s']:.3f}",
                NOT_IN_REPO,
                f"{r['percent_ignored_voxels']:.2f}",
                f"{r['percent_ignored_samples']:.2f}",
                f"{r['pixels_differing_from_1to1']:.2f}",
            ]
        )
    lines = [
        f"{n['volume']}, wires `{n['wire_file']}`; float field layout, OpenCL:"
        f" {n['opencl_device'] or 'none'}. Ray samples: every {n['ray_subsample']}th pixel"
        f" of {n['image'][0]}x{n['image'][1]} from view {tuple(n['stats_view'])} (as"
        " `voxwarp bench wires`, whose full report is `docs/bench-wires.md`).",
        "",
        *_table(
            [
                "field",
                "shape",
                "paper build s (Fig. 12)",
                "build s",
                "paper % ignored (Table 1)",
                "% field voxels ignored",
                "% ray samples ignored",
                "% pixels differing from 1:1",
            ],
            rows,
            "llrrrrrr",
        ),
    ]
    rc = n["render_cost"]
    if rc:
        lo, hi = PAPER_WIRE_RENDER_COST
        lines += _table(
            ["render cost, deformed / undeformed", "paper", "here"],
            [
                [
                    f"dvr, field 1:{rc['scale'] ** 3}, {n['image'][0]}x{n['image'][1]}",
                    f"{lo:g}-{hi:g}x (software renderer)",
                    f"{rc['ratio']:.2f}x ({rc['deformed_ms']:.1f} vs {rc['undeformed_ms']:.1f} ms)",
                ]
            ],
            "lll",
        )
    return lines


def _lattice_section(n: dict[str, Any]) -> list[str]:
    lo, hi = n["paper_fps_ratio"]
    paper = f"{lo:.0%}-{hi:.0%}"
    rows = []
    normals = {"normal": "normals by J^-T n", "tangent": "normals by tangents"}
    for t in n["throughput"]:
        what = "frame" if t["stage"] == "frame" else "vertex stage only"
        rows.append(
            [
                f"{t['cells']}³ cells, {what}, {normals.get(t['normal_method'], '?')},"
                f" {t['position']} position",
                paper if t["stage"] == "frame" else NOT_IN_REPO,
                f"{t['fps_ratio']:.0%}",
                f"{t['lattice_ms']:.1f} / {t['linear_ms']:.1f}",
            ]
        )
    c = n["composition"]
    rows.append(
        [
            f"composition, {n['objects']} objects, animated frame",
            paper,
            f"{(c['animated_fps_ratio'] or 0):.0%}",
            f"{c['trilinear_frame_ms']:.1f} / {c['linear_frame_ms']:.1f}",
        ]
    )
    rows.append(
        [
            f"composition, {n['objects']} objects, static redraw",
            paper,
            f"{(c['static_fps_ratio'] or 0):.0%}",
            "—",
        ]
    )
    return [
        f"Vertex throughput: a torus of {n['triangles']:,} triangles at"
        f" {n['size'][0]}x{n['size'][1]}, lattice and 4x4 frames alternated, medians of"
        f" {n['frames']}; GL: {n['gl_renderer']}. The paper reports trilinear transforms at"
        f" {paper} of the linear frame rate.",
        "",
        *_table(["configuration", "paper", "lattice FPS / 4x4 FPS", "ms (lattice / 4x4)"], rows),
    ]
