"""The lines of the ``python -m benchmarks costs`` table and their markdown.

Each :class:`Line` shows numbers of one measurement of :mod:`benchmarks.costs_measure`
(one measurement may feed several lines: the big volume's first frame and its memory)
through a format template, beside its target. :func:`markdown` makes the table of a
run's JSON (:func:`benchmarks.costs.run_costs`): one column per revision measured.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Line:
    """One line of the table: the measurement it shows, whether it is measured per
    volume, what it is, its target and the format of its numbers (``str.format``
    fields are the measurement's keys; ``extra`` is left out when its keys are not)."""

    key: str
    measure: str
    per_volume: bool
    what: str
    target: str
    template: str
    #: more numbers, shown after the template's when the run has them
    extra: str = ""


#: the table's lines, in order
LINES: tuple[Line, ...] = (
    Line(
        "chainmail_local",
        "chainmail_local",
        True,
        "a local ChainMail drag (16³ grid, middle element dragged 15 mm, 16 relaxation"
        " steps: most of the volume does not move) / undeformed",
        "≤ 1.3x",
        "{ratio:.2f}x",
    ),
    Line(
        "chainmail_identity",
        "chainmail_identity",
        True,
        "the same 16³ ChainMail, nothing moved (identity warp) / undeformed",
        "≈ 1x (nothing moves)",
        "{ratio:.2f}x",
    ),
    Line(
        "massspring_settled",
        "massspring_settled",
        True,
        "a settled 16³ mass-spring drag (corners fixed: everything moves) / undeformed",
        "≤ 1.8x",
        "{ratio:.2f}x",
    ),
    Line(
        "vtk_per_pixel",
        "vtk_per_pixel",
        True,
        "undeformed dvr vs VTK fixed-point, per covered pixel (both unshaded); raw in brackets",
        "≥ 2.0x",
        "{per_pixel:.2f}x ({raw:.2f}x raw)",
    ),
    Line(
        "wire_build",
        "wire_build",
        False,
        "wire field on the MRI head upsampled to 256³, radius 40 mm: build at 1:8 / 1:1",
        "0.15 / 1.0 s",
        "{s_1_8:.2f} / {s_1_1:.2f} s",
        " (CPU {cpu_1_8:.2f} / {cpu_1_1:.2f} s)",
    ),
    Line(
        "first_steady",
        "big_volume",
        True,
        "the volume resampled to 512³: first frame / steady frame",
        "≤ 15x",
        "{first_steady:.1f}x",
    ),
    Line(
        "memory",
        "big_volume",
        True,
        "the volume resampled to 512³: peak memory of the first frame beyond the array",
        "≤ 2x its bytes",
        "+{memory:.1f}x its bytes",
    ),
    Line(
        "gui_drag",
        "gui_drag",
        False,
        "GUI while dragging (`bench interactive`, bundled CT, default window, adaptive"
        " quality): ChainMail / mass-spring",
        "≥ 10 fps",
        "{chainmail_fps:.1f} / {massspring_fps:.1f} fps",
    ),
)
#: the measurements, in running order
MEASUREMENTS: tuple[str, ...] = tuple(dict.fromkeys(line.measure for line in LINES))
#: the measurements made once, not per volume
GLOBAL: frozenset[str] = frozenset(line.measure for line in LINES if not line.per_volume)


def medians(repeats: Sequence[dict[str, float]]) -> dict[str, float]:
    """Per key, the median over the repeats that have it."""
    keys = dict.fromkeys(k for r in repeats for k in r)
    return {k: statistics.median(r[k] for r in repeats if k in r) for k in keys}


def cell(line: Line, result: dict[str, Any] | None) -> str:
    """The text of one revision's result on ``line``: its medians through the template,
    or why there are none."""
    if result is None:
        return "—"
    values = result.get("median", {})
    try:
        text = line.template.format(**values)
    except (KeyError, ValueError):
        text = ""
    if text and all(math.isfinite(v) for v in values.values()):
        try:
            return text + line.extra.format(**values)
        except (KeyError, ValueError):
            return text
    return f"failed: {result.get('error') or 'no numbers'}"


def _load(loads: Sequence[float]) -> str:
    if not loads:
        return "—"
    lo, hi = min(loads), max(loads)
    return f"{lo:.1f}" if abs(hi - lo) < 0.05 else f"{lo:.1f}–{hi:.1f}"


#: what the header says of a ``--quick`` run
QUICK_NOTE = " (quick: tiny sizes, not a measurement)"


def _tf_note(run: dict[str, Any]) -> str:
    """`` with transfer function NAME`` when the run set one for every volume."""
    tf = run.get("transfer_function")
    return f" with transfer function {tf}" if tf else ""


def markdown(run: dict[str, Any]) -> str:
    """The table of one run (the JSON of :func:`benchmarks.costs.run_costs`)."""
    revs = run["revisions"]
    head = " | ".join(f"{r['label']} (`{r['commit'][:10]}`)" for r in revs)
    lines = [
        f"Command: `{run['command']}`",
        "",
        f"* {run['machine']}; {run['size'][0]}x{run['size'][1]} dvr{_tf_note(run)};"
        f" median of {run['repeats']} repeat(s), each ratio against its reference measured in"
        " the same repeat, the revisions' repeats interleaved; wall time"
        f" {run['wall_s']:.0f} s{QUICK_NOTE if run['quick'] else ''}",
        f"* load average (1 min) at start {run['load'][0]:.1f}, at end {run['load'][1]:.1f}",
        "",
        f"| what | volume | {head} | target | load avg |",
        "|---|---|" + "---|" * len(revs) + "---|---|",
    ]
    previous = ""
    for row in run["rows"]:
        line = next(ln for ln in LINES if ln.key == row["line"])
        cells = " | ".join(cell(line, row["results"].get(r["label"])) for r in revs)
        volume = row["volume"] or "—"
        what = line.what if line.key != previous else "″"  # the line above's, another volume
        previous = line.key
        lines.append(f"| {what} | {volume} | {cells} | {line.target} | {_load(row['load'])} |")
    return "\n".join(lines) + "\n"
