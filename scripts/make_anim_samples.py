"""Write the bundled animated scenes ``sample_volumes/*_anim.json`` (``voxwarp animate``).

All refer to the generated sample ``fish`` by name (default shape), so they stay small:

* ``fish_swim_anim.json``: a wire along the spine, its modified curve swaying side to
  side in a travelling wave (one swim cycle over 24 frames, keys every 2 frames, linear);
* ``fish_chainmail_poke_anim.json``: a soft 3D ChainMail grid on a fixed "table" (its
  bottom layer); three elements on the back are pressed 9 mm into the fish (smooth) and
  let go, while the camera turns a little;
* ``fish_lattice_bend_anim.json``: the 12x4x2 lattice of ``fish_lattice_bend.json``
  bending the tail to one side, then the other, then straight again (smooth), with the
  transfer function fading the soft tissue in;
* ``fish_massspring_jiggle_anim.json``: a mass-spring grid; the tail is dragged sideways,
  then let go at frame 10 and swings back and forth (light damping).

Usage: ``.venv/bin/python scripts/make_anim_samples.py [--check]`` (``--check``: only
report whether the files are up to date).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from voxwarp.animation.tracks import Animation, Track  # noqa: E402
from voxwarp.core.volume import Volume  # noqa: E402
from voxwarp.deform.elements.chainmail import ChainMail  # noqa: E402
from voxwarp.deform.elements.grid import ElementGrid  # noqa: E402
from voxwarp.deform.elements.massspring import MassSpring  # noqa: E402
from voxwarp.deform.lattice.trilinear import TrilinearGrid  # noqa: E402
from voxwarp.deform.lattice.warp import LatticeWarp  # noqa: E402
from voxwarp.deform.wires.field import Wire, WireDeformer  # noqa: E402
from voxwarp.io.samples import load_sample  # noqa: E402
from voxwarp.scene import Scene  # noqa: E402

OUT = ROOT / "sample_volumes"
BACKGROUND = (0.08, 0.1, 0.14, 1.0)


def _r(a: np.ndarray, digits: int = 3) -> list:
    """Rounded nested lists (small, stable files)."""
    return np.round(np.asarray(a, dtype=np.float64), digits).tolist()


def _scene_dict(scene: Scene, description: str, animation: Animation) -> dict:
    d = {"description": description, **scene.to_dict()}
    d["animation"] = Animation.from_dict(animation.to_dict()).to_dict()
    return d


def swim(vol: Volume) -> dict:
    """The fish swims: a travelling wave along a wire on its spine."""
    x = np.linspace(30.0, 91.0, 9)
    z = np.interp(x, [20.4, 48.5, 82.3, 91.0], [19.0, 20.2, 18.8, 18.6])
    yc = 23.75
    base = np.stack([x, np.full_like(x, yc), z], axis=1)
    s = (x - x[0]) / (x[-1] - x[0])  # 0 at the wire's start (behind the head), 1 at the tail
    frames, amplitude = 24, 7.0

    def wave(f: float) -> list:
        pts = base.copy()
        phase = 2 * math.pi * f / frames  # one cycle over the animation: it loops
        pts[:, 1] = yc + amplitude * s**2 * np.sin(phase - 2 * math.pi * 0.75 * s)
        return _r(pts)

    keys = [(k, wave(k)) for k in [*range(0, frames - 1, 2), frames - 1]]
    wire = Wire(base, base.copy(), radius=16.0, beta=(-900.0, 4000.0), name="spine", sides="rigid")
    deformer = WireDeformer(vol, [wire], field_scale=2)
    deformer.build()
    scene = Scene(
        vol,
        transfer_function="ct-soft",
        view=(-90.0, 70.0),
        warps=[deformer.warp()],
        zoom=1.7,
        background=BACKGROUND,
    )
    anim = Animation(frames, 24.0, [Track("wires[0].modified", keys, "linear")])
    return _scene_dict(
        scene,
        "The fish swims: a wire along its spine sways side to side in a travelling wave"
        " (one cycle over 24 frames, loops). Sample 'fish'; `voxwarp animate` this file.",
        anim,
    )


def chainmail_poke(vol: Volume) -> dict:
    """An element above the back is pressed into the fish and released."""
    grid = ElementGrid(vol, shape=(13, 7, 7))
    grid.set_material(stiffness=0.2)  # soft: a link compresses to 0.6 of its rest length
    bottom = np.zeros(grid.shape, dtype=bool)
    bottom[:, :, 0] = True
    grid.fix(bottom)  # the fish lies on a table
    cm = ChainMail(grid, relax_steps=0)
    scene = Scene(
        vol,
        transfer_function="ct-soft",
        view=(-90.0, 15.0),
        warps=[cm.warp()],
        zoom=1.6,
        background=BACKGROUND,
    )
    poked = [[6, 3, 5], [5, 3, 5], [7, 3, 5]]  # on the back, inside the grid
    drag = Track(
        "elements.drag",
        [(0, [0.0, 0.0, 0.0]), (10, [0.0, 0.0, -9.0]), (16, [0.0, 0.0, -9.0]), (23, None)],
        "smooth",
        elements=poked,
    )
    camera = Track(
        "camera",
        [(0, {"view": [-90.0, 15.0], "zoom": 1.6}), (23, {"view": [-60.0, 30.0], "zoom": 1.6})],
        "smooth",
    )
    anim = Animation(24, 24.0, [drag, camera], relax_steps=2)
    d = _scene_dict(
        scene,
        "3D ChainMail: three elements on the fish's back are pressed 9 mm down into it"
        " (the body lies on a fixed table) and let go at the last frame (the dent stays:"
        " ChainMail has no elastic memory), while the camera turns. Sample 'fish'.",
        anim,
    )
    cm.close()
    return d


def lattice_bend(vol: Volume) -> dict:
    """The bundled lattice bend, to one side, the other, and back."""
    spec = json.loads((OUT / "fish_lattice_bend.json").read_text(encoding="utf-8"))
    bent = np.asarray(spec["grid"]["nodes"], dtype=np.float64)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in vol.bounds)
    yc = 0.5 * (lo[1] + hi[1])
    mirrored = bent[:, ::-1].copy()  # reverse j so the mirrored lattice keeps its handedness
    mirrored[..., 1] = 2 * yc - mirrored[..., 1]
    u = np.stack(
        np.meshgrid(*(np.linspace(0.0, 1.0, n) for n in bent.shape[:3]), indexing="ij"), -1
    )
    rest = lo + u * (hi - lo)
    # saved at rest: `voxwarp render` shows the straight fish, the camera is fitted to it
    warp = LatticeWarp(TrilinearGrid(rest), (lo, hi))
    tf_bone = [
        [-1000, 0, 0, 0, 0],
        [-100, 0.75, 0.45, 0.3, 0.0],
        [40, 0.85, 0.35, 0.3, 0.0],
        [300, 0.9, 0.75, 0.55, 0.25],
        [2000, 1.0, 1.0, 1.0, 0.85],
    ]
    tf_soft = [
        [-1000, 0, 0, 0, 0],
        [-100, 0.75, 0.45, 0.3, 0.0],
        [40, 0.85, 0.35, 0.3, 0.08],
        [300, 0.9, 0.75, 0.55, 0.25],
        [2000, 1.0, 1.0, 1.0, 0.85],
    ]
    scene = Scene(
        vol,
        transfer_function=tf_bone,
        view="+z",
        warps=[warp],
        zoom=1.5,
        background=BACKGROUND,
    )
    nodes = Track(
        "lattice.nodes",
        [(0, "rest"), (8, _r(bent)), (16, _r(mirrored)), (23, "rest")],
        "smooth",
    )
    tf = Track("transfer_function", [(0, tf_bone), (12, tf_soft)], "smooth")
    anim = Animation(24, 24.0, [nodes, tf])
    return _scene_dict(
        scene,
        "A 12x4x2 lattice bends the back of the fish to one side, then the other, and"
        " straightens it again, while the soft tissue fades in. Sample 'fish'.",
        anim,
    )


def massspring_jiggle(vol: Volume) -> dict:
    """The tail is dragged sideways and let go: it swings back and forth."""
    grid = ElementGrid(vol, shape=(11, 5, 5))
    head = np.zeros(grid.shape, dtype=bool)
    head[:2] = True
    grid.fix(head)  # the head end holds still
    grid.set_material(damping=0.1)  # light damping: the tail swings before it calms
    ms = MassSpring(grid, integrator="semi-implicit", spring_constant=200.0)
    scene = Scene(
        vol,
        transfer_function="ct-soft",
        view="+z",
        warps=[ms.warp()],
        zoom=1.7,
        background=BACKGROUND,
    )
    tail = [[10, j, k] for j in range(1, 4) for k in range(1, 4)]
    drag = Track(
        "elements.drag",
        [(0, [0.0, 0.0, 0.0]), (9, [0.0, 10.0, 0.0]), (10, None)],
        "smooth",
        elements=tail,
    )
    anim = Animation(36, 24.0, [drag], steps_per_frame=10)
    d = _scene_dict(
        scene,
        "Mass-spring: the tail is dragged 10 mm sideways over 9 frames and let go at"
        " frame 10; the springs swing it back and forth (10 steps of 26 ms per frame)."
        " Sample 'fish'.",
        anim,
    )
    ms.close()
    return d


SAMPLES = {
    "fish_swim_anim.json": swim,
    "fish_chainmail_poke_anim.json": chainmail_poke,
    "fish_lattice_bend_anim.json": lattice_bend,
    "fish_massspring_jiggle_anim.json": massspring_jiggle,
}


def main(argv: list[str]) -> int:
    check = "--check" in argv
    vol = load_sample("fish")
    stale = []
    for name, make in SAMPLES.items():
        text = json.dumps(make(vol), indent=1) + "\n"
        path = OUT / name
        if check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(name)
            continue
        path.write_text(text, encoding="utf-8")
        print(f"{path} ({len(text) / 1024:.0f} KB)")
    if check and stale:
        print(f"out of date: {', '.join(stale)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
