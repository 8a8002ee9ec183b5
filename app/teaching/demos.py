"""Teaching demos: ``voxwarp demo NAME`` writes a figure sheet per deformation model.

Each demo measures something on this machine, draws it with matplotlib (the Agg canvas,
no pyplot, no GUI toolkit) into one multi-panel PNG sheet, and returns the numbers it
shows (:class:`DemoResult`). ``voxwarp reproduce`` (:mod:`voxwarp.teaching.reproduce`) runs them all
and puts their numbers beside the papers'.

One module per demo holds its measurements, sheet and tour (``massspring_demo``,
``chainmail_demo``, ``compare_demo``, ``wires_demo``, ``lattice_demo``,
``registration_demo``); :mod:`voxwarp.teaching.sheets` holds what they share. This module
is the entry point: :func:`run_demo` and the registry :data:`RUNNERS` (the names and
titles, :data:`DEMOS` and :data:`DEMO_TITLES`, are :mod:`voxwarp.teaching`'s, so that the
command line lists them without loading the demos).

* ``massspring`` (Knoche 2008, 3.5): explicit vs semi-implicit Euler at the same time
  step: energy over time, the largest energy growth over a range of steps (where each
  integrator becomes unstable), and renders of the fish bent by a drag.
* ``chainmail`` (Gibson 1997; Schill et al. 1998; Knoche 2008, Figure 13): the order in
  which one drag moves the elements (Gibson's sponsors as arrows; the enhanced variant's
  priority queue), then the element grid after 0, 1 and 4 relaxation steps, the
  smoothness energy per step, and the fish rendered after 0, 1 and 4 steps.
* ``compare`` (Knoche 2008, Figures 12-13): mass-spring and ChainMail on the same grid
  and the same drag, side by side, and the CPU and GPU solvers' timings at small sizes
  (:mod:`voxwarp.teaching.measure`; GPU = the moderngl backends on the EGL context,
  labelled with its GL renderer).
* ``wires`` (Journal of WSCG 2006, Figure 12 and Table 1): the fish bent by the bundled
  spine wires with the attribute field at 1:1 ... 1:4096, build times, the share of
  field voxels and of ray samples that need no mapping ("ignored")
  (:mod:`voxwarp.teaching.wire_measure`); the paper's Tables 1-3 measured its way are
  ``python -m benchmarks wire-tables`` in a checkout.
* ``lattice`` (GRAPP 2010, Figures 1 and 5, section 6): renders of a bent volume, of the
  lattice-wrapped torus of the paper's Figure 1 and of both normal methods; the frame
  rates of the paper's own scenes (its table), linear against trilinear
  (:mod:`voxwarp.teaching.grapp_measure`), with their frames on a second sheet; the
  fuller study against 4x4 matrices is the lab's, ``python -m benchmarks lattice`` in a
  checkout.
* ``registration`` (no paper; :mod:`voxwarp.teaching.registration_demo`): colin27 deformed
  by known Gaussian bumps, registered back with SimpleITK demons, the moving image
  rendered through the recovered field beside the fixed one (``registration`` extra).

``quick=True`` shrinks every measurement (small volumes, images and grids, one repeat) so
that a demo runs in seconds: the test suite runs every demo that way. With ``tour=True``
a demo also writes ``NAME_tour.json`` (:data:`~voxwarp.teaching.tour.TOUR_FORMAT`, see
:func:`~voxwarp.teaching.sheets.write_tour`): the
steps of a guided walk through the model for the desktop GUI, each with a title, a text
for a student and a scene JSON to show.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from voxwarp.core.extras import require
from voxwarp.errors import VoxwarpError
from voxwarp.teaching import DEMO_TITLES, DEMOS
from voxwarp.teaching.chainmail_demo import demo_chainmail
from voxwarp.teaching.compare_demo import demo_compare
from voxwarp.teaching.lattice_demo import demo_lattice
from voxwarp.teaching.massspring_demo import demo_massspring
from voxwarp.teaching.registration_demo import demo_registration
from voxwarp.teaching.sheets import FULL, QUICK, DemoSettings, TourStep, jsonable, write_tour
from voxwarp.teaching.wires_demo import demo_wires

__all__ = ["DEMOS", "DEMO_TITLES", "RUNNERS", "DemoError", "DemoResult", "DemoRunner", "run_demo"]


class DemoError(VoxwarpError):
    """An unknown demo name (the message lists the demos)."""


@dataclass
class DemoResult:
    """What :func:`run_demo` wrote and measured.

    Attributes
    ----------
    name
        The demo (one of :data:`DEMOS`).
    figures
        The figure sheet(s), PNG.
    numbers
        The numbers the sheet shows (JSON-ready: plain lists, dicts, floats; infinities
        and NaNs as None).
    seconds
        Wall time of the demo.
    tour
        The tour file (``NAME_tour.json``) when asked for, else None.
    """

    name: str
    figures: list[Path]
    numbers: dict[str, Any]
    seconds: float = 0.0
    tour: Path | None = None

    @property
    def figure(self) -> Path:
        """The (first) figure sheet."""
        return self.figures[0]


def _demo_registration(
    settings: DemoSettings, out: Path, say: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[TourStep]]:
    """``registration``: see :mod:`voxwarp.teaching.registration_demo`."""
    return demo_registration(settings.quick, out, say)


#: a demo's runner: ``(settings, out_dir, log) -> (figure sheets, numbers, tour steps)``
DemoRunner = Callable[
    [DemoSettings, Path, Callable[[str], None]],
    tuple[list[Path], dict[str, Any], list[TourStep]],
]
#: the runner of each demo of :data:`DEMOS`
RUNNERS: dict[str, DemoRunner] = {
    "massspring": demo_massspring,
    "chainmail": demo_chainmail,
    "wires": demo_wires,
    "lattice": demo_lattice,
    "compare": demo_compare,
    "registration": _demo_registration,
}


# ====================================================================== entry point
def run_demo(
    name: str,
    out_dir: str | os.PathLike,
    *,
    quick: bool = False,
    log: Callable[[str], None] | None = None,
    tour: bool = False,
) -> DemoResult:
    """Run the teaching demo ``name`` and write its figure sheet ``out_dir/NAME.png``.

    Parameters
    ----------
    name
        One of :data:`DEMOS`.
    out_dir
        Folder of the sheet (created when missing).
    quick
        Shrink every measurement so that the demo takes seconds (tests).
    log
        Progress messages go here (default: nowhere).
    tour
        Also write ``out_dir/NAME_tour.json`` and the scenes it shows under
        ``out_dir/NAME_tour/`` (see :func:`~voxwarp.teaching.sheets.write_tour`).

    Returns
    -------
    DemoResult
        The sheet's path and the numbers it shows.

    Raises
    ------
    DemoError
        When ``name`` is not a demo.
    """
    if name not in DEMOS:
        raise DemoError(f"unknown demo {name!r}; the demos are: {', '.join(DEMOS)}")
    require("teach", f"voxwarp demo {name}")
    say = log or (lambda _s: None)
    settings = QUICK if quick else FULL
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    run = RUNNERS[name]
    with warnings.catch_warnings():
        # numpy overflow of the blown-up explicit integrator is the point, not a bug
        warnings.simplefilter("ignore", RuntimeWarning)
        figures, numbers, steps = run(settings, out, say)
    numbers = jsonable(numbers)
    numbers["quick"] = settings.quick
    tour_path = None
    if tour:
        tour_path = write_tour(out, name, DEMO_TITLES[name], figures[0], steps)
    seconds = time.perf_counter() - t0
    numbers["seconds"] = seconds
    say(f"demo {name}: {', '.join(str(f) for f in figures)} ({seconds:.1f} s)")
    return DemoResult(name, figures, numbers, seconds, tour_path)
