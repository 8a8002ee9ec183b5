"""Write the trilinear-lattice demo scenes to sample_volumes/lattice_<name>.json.

The animated ones (``lattice_accessories_anim.json``) carry an ``"animation"`` entry for
``voxwarp animate``.

Run from the repository root: ``.venv/bin/python scripts/make_lattice_demos.py``. The
scenes are built by :mod:`voxwarp.teaching.lattice_scenes`; render one with
``voxwarp render sample:lattice_torus_tubes -o tubes.png``.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

from voxwarp.core.files import atomic_write_text
from voxwarp.teaching.lattice_scenes import ANIMATED, DEMOS

OUT = Path(__file__).resolve().parents[1] / "sample_volumes"


def main() -> None:
    """Build every demo scene and save it (atomically, through Scene.save)."""
    for name, make in DEMOS.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # HU presets on the empty carrier volume
            scene = make()
        path = OUT / f"lattice_{name}.json"
        scene.save(path)
        print(path, f"{path.stat().st_size / 1024:.0f} KiB")
    for name, make_dict in ANIMATED.items():  # scene JSON with an "animation" entry
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = make_dict()
        path = OUT / f"lattice_{name}.json"
        atomic_write_text(path, json.dumps(d, separators=(",", ":")) + "\n")
        print(path, f"{path.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
