"""``voxwarp samples``: the bundled samples, one ``sample:NAME`` and its kind a line.

Volumes first, then the bundled JSON files (scenes, animations, wire files, lattice
files), each usable as ``sample:NAME`` wherever voxwarp expects that kind of file:
``voxwarp render sample:fish --wires sample:fish_spine_wires``,
``voxwarp animate sample:fish_swim_anim``.
"""

from __future__ import annotations

import argparse
from typing import Any

from voxwarp.io.samples import FILE_KINDS, sample_files, sample_names

#: how each kind is headed and used
_HEADINGS: dict[str, str] = {
    "volume": "volumes (INPUT of render, slice, gui, ...)",
    "scene": "scenes (INPUT of render, slice, export-volume, export-field, gui)",
    "animation": "animations (voxwarp animate SCENE; INPUT of render too)",
    "wires": "wire files (--wires)",
    "lattice": "lattice files (--lattice)",
}


def add_parser(sub: Any) -> None:
    """Add ``samples`` to the ``voxwarp`` sub-commands (``sub``: their sub-parsers object)."""
    ps = sub.add_parser(
        "samples",
        help="list bundled samples (volumes, scenes, animations, wire and lattice files)",
        description="Lists the bundled samples by kind, each as sample:NAME, the name"
        " any voxwarp command accepts in place of a file of that kind.",
    )
    ps.set_defaults(func=cmd_samples)


def cmd_samples(args: argparse.Namespace) -> int:
    """``voxwarp samples``: list bundled samples, grouped by kind."""
    groups: dict[str, list[str]] = {"volume": sample_names()}
    for name, kind in sample_files().items():
        groups.setdefault(kind, []).append(name)
    width = max(len(n) for names in groups.values() for n in names) + len("sample:")
    for kind in ("volume", *FILE_KINDS):
        for name in groups.get(kind, []):
            print(f"{'sample:' + name:<{width}}  {_HEADINGS[kind]}")
    return 0
