"""``python -m benchmarks readme RUN.json``: the README's benchmark paragraph, written from
the JSON of a ``python -m benchmarks costs --json RUN.json`` run.

The paragraph quotes the undeformed dvr against VTK's fixed-point raycaster per covered
pixel on every volume of the run (the last revision measured: the checkout), so a sparse
scan and a dense one are quoted side by side. It lives in ``README.md`` between
:data:`BEGIN` and :data:`END`; the command replaces what is there (``--check`` only says
whether it would change anything). The run behind the README is kept in
``docs/costs-run.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from benchmarks import ROOT
from voxwarp.bench.command import add_bench_parser

BEGIN = "<!-- costs paragraph: written by `python -m benchmarks readme docs/costs-run.json` -->"
END = "<!-- end of the costs paragraph -->"
#: the keys of a run's JSON the paragraph reads
RUN_KEYS: tuple[str, ...] = ("rows", "revisions", "size", "machine", "repeats")
#: the run the README quotes
RUN_JSON = ROOT / "docs" / "costs-run.json"


class ReadmeError(ValueError):
    """A run or README the paragraph cannot be made from or put into."""


def volume_words(spec: str) -> str:
    """How the paragraph names a volume: ``the bundled stent CT`` for ``sample:stent``,
    the file's name otherwise."""
    from voxwarp.io.samples import SAMPLE_MODALITIES

    if spec.startswith("sample:"):
        name = spec.split(":", 1)[1]
        kind = {"CT": "CT", "MR": "MRI"}.get(SAMPLE_MODALITIES.get(name, ""), "phantom")
        return f"the bundled `{name}` {kind}"
    return f"`{Path(spec).name}`"


def _vtk_rows(run: dict[str, Any]) -> list[tuple[str, dict[str, float], list[float]]]:
    """(volume, medians of the checkout's column, load averages) of each VTK line; the
    medians also hold ``low`` and ``high``, the least and greatest per-pixel ratio of
    the repeats (the median itself where the run kept no repeats)."""
    label = run["revisions"][-1]["label"]
    out = []
    for row in run["rows"]:
        if row["line"] != "vtk_per_pixel":
            continue
        result = row["results"].get(label, {})
        median = dict(result.get("median", {}))
        if {"per_pixel", "raw", "covered"} <= median.keys():
            each = [r["per_pixel"] for r in result.get("repeats", []) if "per_pixel" in r]
            each = each or [median["per_pixel"]]
            median["low"], median["high"] = min(each), max(each)
            out.append((row["volume"], median, list(row.get("load", []))))
    if not out:
        raise ReadmeError(
            "the run has no VTK numbers (VTK not installed?); run `python -m benchmarks costs`"
            " with VTK (pip install '.[bench]') and --json"
        )
    return out


def paragraph(run: dict[str, Any]) -> str:
    """The paragraph of ``run`` (the JSON of ``python -m benchmarks costs``), without the
    markers."""
    rows = _vtk_rows(run)
    quotes = [
        f"{m['per_pixel']:.1f}x on {volume_words(spec)} ({100 * m['covered']:.0f} % of the"
        f" image covered; {m['raw']:.1f}x per frame; {_spread(m)})"
        for spec, m, _ in rows
    ]
    listed = quotes[0] if len(quotes) == 1 else ", ".join(quotes[:-1]) + " and " + quotes[-1]
    loads = [x for _, _, load in rows for x in load]
    lo, hi = (f"{v:.0f}" for v in (min(loads), max(loads))) if loads else ("", "")
    load = f", load average {lo}" + (f"–{hi}" if hi != lo else "") if loads else ""
    w, h = run["size"]
    return (
        f"Undeformed `dvr` at {w}x{h} is {listed} as fast per covered pixel as VTK's"
        " fixed-point CPU raycaster on the same array, transfer function, sample distance and"
        f" camera (both unshaded; {run['machine']}{load}; medians of {run['repeats']} runs,"
        " with each scan's range of runs)."
        " Both raycasters skip empty space, so the ratio varies with the scan and its"
        " transfer function: `python -m benchmarks costs --volume FILE [--tf NAME]` measures"
        " a scan of yours, with the cost of deforming it, before and after a change"
        " (`docs/benchmarks.md`)."
    )


def _spread(m: dict[str, float]) -> str:
    """``runs 1.9-2.5x``, or ``every run 2.4x`` where they agree to the digit."""
    low, high = f"{m['low']:.1f}", f"{m['high']:.1f}"
    return f"every run {low}x" if low == high else f"runs {low}–{high}x"


def replace_block(readme: str, text: str) -> str:
    """``readme`` with the text between :data:`BEGIN` and :data:`END` replaced by ``text``."""
    start, end = readme.find(BEGIN), readme.find(END)
    if start < 0 or end < start:
        raise ReadmeError(f"README has no '{BEGIN}' ... '{END}' block; add the two markers")
    return readme[: start + len(BEGIN)] + "\n" + text + "\n" + readme[end:]


def current_block(readme: str) -> str:
    """The text between the markers (without the line breaks next to them)."""
    start, end = readme.find(BEGIN), readme.find(END)
    if start < 0 or end < start:
        raise ReadmeError(f"README has no '{BEGIN}' ... '{END}' block; add the two markers")
    return readme[start + len(BEGIN) : end].strip("\n")


def load_run(path: Path) -> dict[str, Any]:
    """The JSON of a costs run; one-line errors for a missing or malformed file."""
    try:
        run = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ReadmeError(f"{path}: cannot read it ({exc})") from None
    missing = [k for k in RUN_KEYS if not isinstance(run, dict) or k not in run]
    if missing:
        raise ReadmeError(
            f"{path}: not the --json of `python -m benchmarks costs` (no {', '.join(missing)})"
        )
    return run


def add_bench_readme_parser(bsub: Any) -> None:
    """Add ``readme`` to the ``python -m benchmarks`` sub-commands."""
    p = add_bench_parser(bsub, "readme", "rewrite README.md's benchmark paragraph", __doc__)
    p.add_argument("run", nargs="?", default=str(RUN_JSON), help="costs --json output")
    p.add_argument("--readme", default=str(ROOT / "README.md"), help="the README to rewrite")
    p.add_argument("--check", action="store_true", help="exit 1 if the paragraph would change")
    p.set_defaults(func=cmd_readme)


def cmd_readme(args: argparse.Namespace) -> int:
    """``python -m benchmarks readme``: see the module docstring."""
    from voxwarp.core.files import atomic_write_text
    from voxwarp.errors import InputError

    path = Path(args.readme)
    try:
        text = paragraph(load_run(Path(args.run)))
        old = path.read_text(encoding="utf-8")
        new = replace_block(old, text)
    except ReadmeError as exc:
        raise InputError(str(exc)) from None
    if args.check:
        same = new == old
        print(f"{path}: the paragraph is {'current' if same else 'out of date'}", file=sys.stderr)
        return 0 if same else 1
    atomic_write_text(path, new)
    print(text)
    return 0
