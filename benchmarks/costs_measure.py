"""One repeat of each row of ``python -m benchmarks costs``, measured in a worker process
(:mod:`benchmarks.costs_worker`) against whichever ``voxwarp`` it imports.

:class:`Lab` keeps what the repeats share (a headless context, the volumes, the models
and their warms-ups) and :meth:`Lab.measure` runs one repeat of one row: a dict of named
positive numbers (a ratio against a reference measured in the same repeat, or seconds).
Only long-standing public API is used, so the same code measures older revisions too.
"""

from __future__ import annotations

import gc
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

#: image size of the frames (full, quick); the big volume's edge (full, quick)
IMAGE: tuple[tuple[int, int], tuple[int, int]] = ((512, 512), (64, 64))
BIG_EDGE: tuple[int, int] = (512, 32)
#: the quick mode's volume edge; the wire head's edge (full, quick)
QUICK_EDGE = 32
HEAD_EDGE: tuple[int, int] = (256, 32)
#: the element models: grid edge, drag (mm, along x), ChainMail relaxation steps
GRID = 16
DRAG_MM = 15.0
RELAX_STEPS = 16
#: the GUI's default window (``bench interactive``), and quick's
WINDOW: tuple[tuple[int, int], tuple[int, int]] = ((750, 830), (64, 64))
#: frames per side of one repeat of a frame ratio (full, quick)
FRAMES: tuple[int, int] = (3, 1)


def resample(volume: Any, edge: int) -> Any:
    """``volume`` trilinearly resampled to ``edge``³ voxels over the same box (its dtype
    kept, Fortran order as ``Volume`` keeps it)."""
    from scipy.ndimage import zoom

    from voxwarp.core.volume import Volume

    data = np.asarray(volume.data)
    factors = [edge / n for n in data.shape]
    out = zoom(data, factors, order=1, output=data.dtype)
    spacing = np.asarray(volume.spacing) * np.asarray(data.shape) / np.asarray(out.shape)
    origin = np.asarray(volume.origin) - 0.5 * np.asarray(volume.spacing) + 0.5 * spacing
    name = f"{volume.name} at {edge}³"
    return Volume(np.asfortranarray(out), tuple(spacing), tuple(origin), name=name)


def _set(renderer: Any, **settings: Any) -> None:
    """Set the renderer settings this revision has (older ones may lack some)."""
    for name, value in settings.items():
        if hasattr(renderer, name):
            setattr(renderer, name, value)


class Lab:
    """What the repeats of one worker share; ``quick`` gives the tiny sizes;
    ``transfer_function`` (a preset name or file) replaces every volume's default."""

    def __init__(self, quick: bool, transfer_function: str | None = None) -> None:
        self.quick = bool(quick)
        self.transfer_function = transfer_function
        self.size = IMAGE[self.quick]
        self.frames = FRAMES[self.quick]
        self._cache: dict[Any, Any] = {}
        self._r: Any = None

    def close(self) -> None:
        """Release the context and everything cached."""
        big = self._cache.pop("big renderer", None)
        if big is not None:
            big.release()
        self._cache.clear()
        if self._r is not None:
            self._r.release()
            self._r = None

    def cached(self, key: Any, make: Callable[[], Any]) -> Any:
        """``make()``, made once per ``key`` for the worker's life."""
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    @property
    def r(self) -> Any:
        """The renderer of the frame rows (steady state: skip maps built at once)."""
        if self._r is None:
            from voxwarp.render.offscreen import OffscreenRenderer

            self._r = OffscreenRenderer(*self.size)
            _set(self._r.renderer, warped_skip_maps="always", cell_skip_maps="always")
        return self._r

    def volume(self, spec: str) -> tuple[Any, Any]:
        """The volume of ``spec`` (``sample:NAME`` or a file; quick: resampled to
        :data:`QUICK_EDGE`³) and its transfer function (the lab's, else a sample's
        suggested one, else None: the modality's default)."""

        def load() -> tuple[Any, Any]:
            from voxwarp.inputs import load_input
            from voxwarp.io.samples import suggested_transfer_function

            vol = load_input(spec)
            if self.quick:
                vol = resample(vol, QUICK_EDGE)
            if self.transfer_function:
                return vol, self.transfer_function
            name = spec.split(":", 1)[1] if spec.startswith("sample:") else None
            return vol, (None if name is None else suggested_transfer_function(name))

        return self.cached(("volume", spec), load)

    def scene(self, spec: str, **kwargs: Any) -> Any:
        """The 512² dvr scene of ``spec`` (perspective, the volume filling the image)."""
        from voxwarp.bench.render import bench_camera
        from voxwarp.scene import Scene

        vol, tf = self.volume(spec)
        return Scene(vol, mode="dvr", transfer_function=tf, camera=bench_camera(vol), **kwargs)

    # ------------------------------------------------------------------ rows
    def measure(self, row: str, spec: str) -> dict[str, float]:
        """One repeat of ``row`` on ``spec`` (see :data:`MEASURES`)."""
        return MEASURES[row](self, spec)

    def frame_ratio(self, ref: Any, test: Any) -> dict[str, float]:
        """Frames of ``ref`` and ``test`` alternated: medians and ``ratio`` test / ref."""
        times: dict[str, list[float]] = {"ref": [], "test": []}
        for _ in range(self.frames):
            for key, scene in (("ref", ref), ("test", test)):
                times[key] += self.r.time_frames(scene, frames=1, warmup=0)
        ref_ms, ms = statistics.median(times["ref"]), statistics.median(times["test"])
        return {"ratio": ms / ref_ms, "ms": ms, "reference_ms": ref_ms}

    def warped(self, spec: str, kind: str) -> tuple[Any, Any]:
        """The undeformed scene and the scene through model ``kind``'s warp (cached; two
        warm-up frames each, which build their skip maps)."""

        def make() -> tuple[Any, Any]:
            base = self.scene(spec)
            warp = MODELS[kind](self, base.volume)
            test = base.copy(warps=[warp])
            for scene in (base, test):
                self.r.time_frames(scene, frames=1, warmup=2)
            return base, test

        return self.cached(("warped", spec, kind), make)


# ---------------------------------------------------------------------- models
def _centre(shape: Any) -> tuple[int, int, int]:
    return (shape[0] // 2, shape[1] // 2, shape[2] // 2)


def chainmail_local(lab: Lab, vol: Any) -> Any:
    """16³ ChainMail (default shell anchor and region of influence), the middle element
    dragged :data:`DRAG_MM` along x, :data:`RELAX_STEPS` relaxation steps."""
    from voxwarp.deform import ChainMail, ElementGrid

    cm = ChainMail(ElementGrid(vol, shape=GRID), relax_steps=RELAX_STEPS)
    cm.move(_centre(cm.grid.shape), (DRAG_MM, 0.0, 0.0))
    return cm.warp()


def chainmail_identity(lab: Lab, vol: Any) -> Any:
    """The same 16³ ChainMail with nothing moved (an identity warp)."""
    from voxwarp.deform import ChainMail, ElementGrid

    return ChainMail(ElementGrid(vol, shape=GRID)).warp()


def massspring_settled(lab: Lab, vol: Any) -> Any:
    """16³ mass-spring, corners fixed, the middle element dragged :data:`DRAG_MM` along x
    and settled (everything moves)."""
    from voxwarp.deform import ElementGrid, MassSpring

    ms = MassSpring(ElementGrid(vol, shape=GRID, anchor="corners"), integrator="semi-implicit")
    ms.move(_centre(ms.grid.shape), (DRAG_MM, 0.0, 0.0))
    ms.settle(max_steps=500 if lab.quick else 20000, tol=1e-3)
    return ms.warp()


#: warp kind -> (lab, volume) -> its warp
MODELS: dict[str, Callable[[Lab, Any], Any]] = {
    "chainmail_local": chainmail_local,
    "chainmail_identity": chainmail_identity,
    "massspring_settled": massspring_settled,
}


def _warp_row(kind: str) -> Callable[[Lab, str], dict[str, float]]:
    def run(lab: Lab, spec: str) -> dict[str, float]:
        return lab.frame_ratio(*lab.warped(spec, kind))

    return run


# ---------------------------------------------------------------------- VTK
def vtk_per_pixel(lab: Lab, spec: str) -> dict[str, float]:
    """Undeformed unshaded dvr against VTK's fixed-point raycaster on the same array,
    transfer function, sample distance and camera: VTK ms per covered pixel over ours
    (``per_pixel``), VTK ms over ours (``raw``) and the shares of the image covered."""
    from benchmarks import vtk as bench_vtk
    from voxwarp.bench.render import covered_fraction

    if not bench_vtk.vtk_available():
        raise RuntimeError("VTK is not installed (pip install '.[bench]')")
    scene = lab.scene(spec, shading=False, background=(0.0, 0.0, 0.0, 0.0))
    ours = lab.r.time_frames(scene, frames=lab.frames, warmup=1)
    covered = covered_fraction(lab.r.render(scene))
    res = bench_vtk.render_vtk(
        np.asarray(scene.volume.data),
        scene.volume.spacing,
        scene.volume.origin,
        list(scene.transfer_function.points),
        mapper="fixed_point",
        mode="dvr",
        sample_distance_mm=scene.sample_distance_mm,
        opacity_unit_distance_mm=scene.opacity_reference_mm,
        size=lab.size,
        camera=_vtk_camera(scene),
        frames=lab.frames,
        warmup=1,
        rgba=True,
    )
    vtk_covered = covered_fraction(res.image)
    ms = statistics.median(ours)
    raw = res.median_ms / ms
    per_pixel = raw * covered / vtk_covered if covered > 0 and vtk_covered > 0 else raw
    return {
        "per_pixel": per_pixel,
        "raw": raw,
        "ms": ms,
        "vtk_ms": res.median_ms,
        "covered": covered,
        "vtk_covered": vtk_covered,
    }


def _vtk_camera(scene: Any) -> Any:
    from benchmarks import vtk as bench_vtk

    return bench_vtk.camera_spec(scene.resolved_camera())


# ---------------------------------------------------------------------- wire field
def wire_build(lab: Lab, spec: str) -> dict[str, float]:
    """Seconds of the wire attribute field build on the MRI head upsampled to 256³
    (one Bézier wire of radius 40 mm, ``benchmarks.wires.HEAD_WIRE``) at 1:8 and 1:1;
    ``spec`` is not used (the row's volume is always the head). Also the CPU seconds of
    the process (all its threads, OpenCL's included: steadier than wall time on a
    loaded machine)."""
    from benchmarks.wires import HEAD_WIRE, head_volume
    from voxwarp.deform.wires.field import Wire, WireDeformer

    def make() -> dict[int, Any]:
        head = head_volume(HEAD_EDGE[lab.quick])
        builds = {s: WireDeformer(head, [Wire(**HEAD_WIRE)], field_scale=s) for s in (2, 1)}
        for wd in builds.values():
            wd.build()  # untimed: kernels, buffers
        return builds

    builds = lab.cached("wires", make)
    out = {}
    for scale, key in ((2, "1_8"), (1, "1_1")):
        t, cpu = time.perf_counter(), time.process_time()
        builds[scale].build()
        out[f"s_{key}"] = time.perf_counter() - t
        out[f"cpu_{key}"] = time.process_time() - cpu
    return out


# ---------------------------------------------------------------------- big volume
def big_volume(lab: Lab, spec: str) -> dict[str, float]:
    """The volume resampled to 512³: a new ``Volume`` of the array to its first image
    (shaders compiled beforehand), over the median steady frame (``first_steady``), and
    the process' peak resident memory during that first frame beyond the array's bytes
    (``memory``, times the array's bytes; on llvmpipe the textures live in process
    memory), on a renderer with the default settings."""
    from benchmarks.scale import PeakRSS
    from voxwarp.bench.render import bench_camera
    from voxwarp.core.volume import Volume
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    edge = BIG_EDGE[lab.quick]
    vol, tf = lab.volume(spec)
    big = lab.cached(("big", spec), lambda: resample(vol, edge))
    r = lab.cached("big renderer", lambda: OffscreenRenderer(*lab.size, ctx=lab.r.ctx))
    tiny = Scene(resample(vol, 8), mode="dvr", transfer_function=tf)
    gc.collect()
    r.render(tiny)  # compiles; evicts the textures of dead volumes
    data = np.asarray(big.data)
    with PeakRSS() as peak:
        t = time.perf_counter()
        new = Volume(data, big.spacing, big.origin, name=big.name)
        scene = Scene(new, mode="dvr", transfer_function=tf, camera=bench_camera(new))
        r.render(scene)
        first = time.perf_counter() - t
    r.render(scene)  # the second frame may build cell maps
    steady = statistics.median(r.time_frames(scene, frames=lab.frames, warmup=0)) / 1000
    del scene, new
    mib = data.nbytes / 2**20
    memory = peak.mib / mib if peak.mib >= 0 else float("nan")
    return {"first_steady": first / steady, "memory": memory, "first_s": first}


# ---------------------------------------------------------------------- the GUI
def gui_drag(lab: Lab, spec: str) -> dict[str, float]:
    """``bench interactive`` at the default window: frames per second of the adaptive
    orbit while a ChainMail and a mass-spring edit are in place (its bundled CT;
    ``spec`` is not used)."""
    from voxwarp.bench.interactive import bench_interactive

    report = bench_interactive(
        size=WINDOW[lab.quick], frames=lab.frames, families=("chainmail", "massspring")
    )
    fps = {r.family: float(r.adaptive_fps) for r in report.rows}
    return {"chainmail_fps": fps["chainmail"], "massspring_fps": fps["massspring"]}


#: row key -> (lab, volume spec) -> one repeat's numbers
MEASURES: dict[str, Callable[[Lab, str], dict[str, float]]] = {
    "chainmail_local": _warp_row("chainmail_local"),
    "chainmail_identity": _warp_row("chainmail_identity"),
    "massspring_settled": _warp_row("massspring_settled"),
    "vtk_per_pixel": vtk_per_pixel,
    "wire_build": wire_build,
    "big_volume": big_volume,
    "gui_drag": gui_drag,
}
