"""What the wires demo measures, shared with the lab's ``python -m benchmarks wires``.

The padded fish and its wire file, a camera that frames the object with the space its
wires move it into (:func:`framed_camera`), the samples a raycast takes
(:func:`ray_samples`, which the lab's ray statistics use too), and the demo's small
measurements: field builds at one scale (:func:`time_field_builds`) and how the field
classifies the ray samples (:func:`classify_samples`: identity, vacated or swept, the
wire paper's Table 1). The lab (``benchmarks/wires.py``) imports these; the installed
package never imports the lab.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.core.volume import Volume
from voxwarp.inputs import read_wire_file
from voxwarp.io.samples import bundled_dir, load_sample

#: field scales of the paper's Figure 12 (per-axis reduction: 1:1 ... 1:4096 voxels)
DEFAULT_SCALES: tuple[int, ...] = (1, 2, 4, 8, 16)
#: view (azimuth, elevation) of the ``framed`` camera: from -y and above, so that the
#: fish's sideways bend and its tail's twist both show
FRAMED_VIEW: tuple[float, float] = (-90.0, 45.0)
#: the fish's generated shape and the padded cube edge
FISH_SHAPE: tuple[int, int, int] = (256, 128, 107)
PADDED_EDGE = 256
#: field scale of the render (the wire file's)
RENDER_SCALE = 2
#: every STATS_SUBSAMPLE-th pixel in x and y is traced for the ray statistics
STATS_SUBSAMPLE = 4
#: air (HU) padding the fish
AIR_HU = -1000

_SAMPLES_DIR = bundled_dir()
FISH_WIRES = _SAMPLES_DIR / "fish_spine_wires.json"
TUBES_WIRES = _SAMPLES_DIR / "tubes_twist_wires.json"


def padded_fish(shape: Sequence[int] = FISH_SHAPE, edge: int = PADDED_EDGE) -> Volume:
    """The sample fish at ``shape``, padded with air to ``edge`` voxels per axis.

    Padding is split evenly before and after each axis (the odd voxel after), and the
    origin moves by the padding before, so every fish voxel keeps its mm position and the
    bundled wire files apply.
    """
    fish = load_sample("fish", shape=tuple(int(n) for n in shape))
    pads = []
    for n in fish.shape:
        extra = max(int(edge) - n, 0)
        pads.append((extra // 2, extra - extra // 2))
    data = np.pad(fish.data, pads, constant_values=AIR_HU)
    sp = np.asarray(fish.spacing)
    origin = np.asarray(fish.origin) - np.array([p[0] for p in pads]) * sp
    name = (
        f"fish {'x'.join(map(str, fish.shape))} padded with air to {'x'.join(map(str, data.shape))}"
    )
    return Volume(
        data, fish.spacing, tuple(origin), name=name, source="sample:fish", units=fish.units
    )


def load_wires(path: Path) -> tuple[list[Any], dict[str, Any]]:
    """The wires of a wire file and its whole JSON object."""
    from voxwarp.deform.wires.field import Wire

    spec = read_wire_file(path)
    return [Wire.from_dict(w) for w in spec["wires"]], spec


def camera_rays(
    camera: Any, size: tuple[int, int], subsample: int = STATS_SUBSAMPLE
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins, unit directions and far distances of the rays through every
    ``subsample``-th pixel centre, as the raycaster computes them (near to far plane)."""
    w, h = size
    px, py = np.meshgrid(
        np.arange(0, w, subsample) + 0.5, np.arange(0, h, subsample) + 0.5, indexing="xy"
    )
    ndc = np.stack([px.ravel() / w * 2 - 1, py.ravel() / h * 2 - 1], axis=1)
    inv = np.linalg.inv(camera.view_projection(w / h))
    ones = np.ones(len(ndc))
    a = np.c_[ndc, -ones, ones] @ inv.T
    b = np.c_[ndc, ones, ones] @ inv.T
    ro = a[:, :3] / a[:, 3:]
    far = b[:, :3] / b[:, 3:]
    t_far = np.linalg.norm(far - ro, axis=1)
    return ro, (far - ro) / t_far[:, None], t_far


def content_box(volume: Volume) -> tuple[np.ndarray, np.ndarray]:
    """Box (mm) of the voxels above air: > -500 HU for CT volumes, else above a tenth of
    the value range; the whole volume box when none is."""
    data = volume.data
    if volume.units == "HU":
        threshold = -500.0
    else:
        lo, hi = float(data.min()), float(data.max())
        threshold = lo + 0.1 * (hi - lo)
    mask = data > threshold
    if not mask.any():
        return volume.bounds
    sp, org = np.asarray(volume.spacing), np.asarray(volume.origin)
    first, last = np.zeros(3), np.zeros(3)
    for a in range(3):
        hit = np.nonzero(mask.any(axis=tuple(b for b in range(3) if b != a)))[0]
        first[a], last[a] = hit[0], hit[-1]
    return org + first * sp - sp / 2, org + last * sp + sp / 2


def framed_camera(
    volume: Volume,
    wires: Sequence[Any],
    size: tuple[int, int],
    view: tuple[float, float] = FRAMED_VIEW,
    fill: float = 0.95,
    fov: float = 30.0,
) -> Any:
    """A perspective camera from ``view`` whose image the object fills: the box of
    :func:`content_box` grown by each modified wire's region of influence (where the
    wires move the object to), zoomed to ``fill`` of the image's width or height."""
    lo, hi = content_box(volume)
    for w in wires:
        pts = w.modified.evaluate(np.linspace(0.0, 1.0, 257))
        r = w.radius * float(w.scale[:, 1].max())
        lo, hi = np.minimum(lo, pts.min(0) - r), np.maximum(hi, pts.max(0) + r)
    return Camera.framing(lo, hi, view, size, fill=fill, fov=fov)


@dataclass
class RaySamples:
    """The samples of a raycast, as :func:`ray_samples` lays them out: ``chunks`` yields
    their points (N, 3) in mm, about ``chunk`` at a time, ray by ray."""

    rays: int
    rays_hitting: int
    step_mm: float
    chunks: Iterator[np.ndarray]


def ray_samples(
    scene: Any,
    camera: Any,
    size: tuple[int, int],
    subsample: int = STATS_SUBSAMPLE,
    chunk: int = 1_000_000,
) -> RaySamples:
    """The sample points of the rays through every ``subsample``-th pixel of ``scene``
    seen by ``camera`` (no jitter), where the raycaster marches them: from the ray box's
    entry (or the near plane) to its exit (or the far plane), one sample distance apart."""
    ro, rd, t_far = camera_rays(camera, size, subsample)
    lo, hi = (np.asarray(v, dtype=np.float64) for v in scene.ray_bounds())
    step = float(scene.sample_distance_mm)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / rd
        ta, tb = (lo - ro) * inv, (hi - ro) * inv
    t_in = np.nanmax(np.minimum(ta, tb), axis=1)
    t_out = np.nanmin(np.maximum(ta, tb), axis=1)
    t_lattice = np.maximum(t_in, 0.0)
    t1 = np.minimum(t_out, t_far)
    j = 0.5  # no jitter
    diag = float(np.linalg.norm(hi - lo))
    max_steps = int(min(diag / step + 4, 1_000_000))
    n = np.where(t1 > t_lattice, np.ceil((t1 - t_lattice) / step - j), 0)
    n = np.clip(n, 0, max_steps).astype(np.int64)

    def chunks() -> Iterator[np.ndarray]:
        cum = np.cumsum(n)
        start = 0
        while start < len(n):
            end = int(np.searchsorted(cum, cum[start] - n[start] + chunk, side="right"))
            sel = np.arange(start, max(end, start + 1))
            start = int(sel[-1]) + 1
            ns = n[sel]
            total = int(ns.sum())
            if total == 0:
                continue
            ray = np.repeat(sel, ns)
            k = np.arange(total) - np.repeat(np.cumsum(ns) - ns, ns)
            t = t_lattice[ray] + (k + j) * step
            yield ro[ray] + t[:, None] * rd[ray]

    return RaySamples(len(n), int(np.count_nonzero(n)), step, chunks())


def classify_samples(
    scene: Any, camera: Any, size: tuple[int, int], warp: Any, subsample: int = STATS_SUBSAMPLE
) -> dict[str, int]:
    """How the wire field ``warp`` classifies the ray samples of ``scene`` (the wire
    paper's Table 1 over the whole ray box): ``samples``, ``identity`` (no mapping
    needed: ignored), ``vacated`` and ``swept``."""
    counts = np.zeros(3, dtype=np.int64)
    for p in ray_samples(scene, camera, size, subsample).chunks:
        state, _, _ = warp._lookup(p)
        counts += np.bincount(state, minlength=3)[:3]
    identity, vacated, swept = (int(c) for c in counts)
    return {
        "samples": identity + vacated + swept,
        "identity": identity,
        "vacated": vacated,
        "swept": swept,
    }


def time_field_builds(
    volume: Volume, wires: Sequence[Any], scale: int, repeats: int
) -> tuple[dict[str, Any], Any]:
    """Build the wires' attribute field (float layout) at ``scale`` ``1 + repeats`` times,
    the first untimed (OpenCL kernels and buffers of this grid size): the timed builds'
    median and min seconds, the field's counts, and the deformer."""
    from voxwarp.deform.wires.field import WireDeformer

    wd = WireDeformer(volume, wires, field_scale=scale, layout="float")
    wd.build()
    totals = []
    for _ in range(max(1, int(repeats))):
        st = wd.build()
        totals.append(st.timings["total"])
    row = {
        "field_shape": tuple(int(n) for n in st.field_shape),
        "build_s": statistics.median(totals),
        "build_min_s": min(totals),
        "builds": len(totals),
        "swept": st.swept,
        "vacated": st.vacated,
        "ignored": st.ignored,
        "voxels": st.voxels,
        "percent_ignored_voxels": 100.0 * st.ignored / max(st.voxels, 1),
        "backend": st.backend,
    }
    return row, wd


def field_points(volume: Volume, stride: int) -> np.ndarray:
    """World points (N, 3) mm at every ``stride``-th voxel centre of ``volume`` along
    each axis: where :func:`field_error` compares the fields."""
    idx = [np.arange(0, n, max(1, int(stride))) for n in volume.shape]
    ijk = np.stack(np.meshgrid(*idx, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.asarray(volume.index_to_world(ijk), dtype=np.float64)


def object_threshold(volume: Volume) -> float:
    """The value above which a voxel is the object, not air: -500 HU for CT volumes,
    else a tenth of the way up the value range (as :func:`content_box`)."""
    if volume.units == "HU":
        return -500.0
    lo, hi = float(volume.data.min()), float(volume.data.max())
    return lo + 0.1 * (hi - lo)


def _values(volume: Volume, points: np.ndarray) -> np.ndarray:
    """The volume trilinear at world ``points`` (its minimum outside, and at FAR)."""
    from scipy import ndimage

    ijk = np.asarray(volume.world_to_index(points), dtype=np.float64)
    data = np.asarray(volume.data, dtype=np.float32)
    return ndimage.map_coordinates(data, ijk.T, order=1, cval=float(data.min()))


def _stats_mm(err: np.ndarray) -> dict[str, float]:
    if not err.size:
        return {"max": 0.0, "rms": 0.0, "p99": 0.0}
    return {
        "max": float(err.max()),
        "rms": float(np.sqrt(np.mean(err**2))),
        "p99": float(np.percentile(err, 99)),
    }


def field_error(volume: Volume, reference: Any, warp: Any, points: np.ndarray) -> dict[str, Any]:
    """How far the wire warp ``warp`` (a coarse attribute field) maps ``points`` of the
    deformed ``volume`` from where ``reference`` (the 1:1 field) maps them, in mm.

    Compared are the points either field moves (swept or vacated) whose value through
    either mapping is the object's (above :func:`object_threshold`): ``object_points``;
    the share of them the fields classify differently (identity, vacated, swept:
    ``percent_reclassified``) or whose value differs by more than 5 % of the value range
    (``percent_value_off``); the distance between the two mapped points over those
    neither vacates (``object_mm``: max, rms, p99) and over those both sweep
    (``swept_mm``: the error of the coarse field's interpolated wire parameter t).
    """
    s_ref, _, _ = reference._lookup(points)
    s_new, _, _ = warp._lookup(points)
    moved = (s_ref != 0) | (s_new != 0)
    p, a, b = points[moved], s_ref[moved], s_new[moved]
    qa, qb = reference.apply(p), warp.apply(p)
    va, vb = _values(volume, qa), _values(volume, qb)
    obj = (va > object_threshold(volume)) | (vb > object_threshold(volume))
    err = np.linalg.norm(qa - qb, axis=1)
    span = float(volume.data.max()) - float(volume.data.min())
    n = int(obj.sum())
    return {
        "object_points": n,
        "percent_reclassified": 100.0 * float(np.count_nonzero(obj & (a != b))) / max(n, 1),
        "percent_value_off": 100.0
        * float(np.count_nonzero(obj & (np.abs(va - vb) > 0.05 * span)))
        / max(n, 1),
        "object_mm": _stats_mm(err[obj & (a != 1) & (b != 1)]),
        "swept_mm": _stats_mm(err[obj & (a == 2) & (b == 2)]),
    }
