"""``python -m benchmarks wires --storage``: the wire paper's storage (section 7.2), mask memory
(section 7.1) and propagation domain (section 5.1), measured on the bundled phantoms.

For the fish (padded to 256³, ``sample_volumes/fish_spine_wires.json``) and the tubes
(``sample_volumes/tubes_twist_wires.json``), at the wire file's field scale:

1. *Storage*: one build per layout (``float``, ``packed``, ``paper``): bytes per field
   voxel, field size, the plane masks' memory (``sum_p a(p) s / 8`` per wire) and how
   far each 2-byte layout's mapping lies from the float layout's at points inside the
   swept voxels (the float layout's t is exact up to float32): median and maximum mm;
   with images on, each layout's steady dvr frame (framed camera, 512x256) over the
   undeformed one, alternated frame by frame as in the wire bench's render section.
2. *Propagation domain*: :class:`~voxwarp.deform.wires.field.WireDeformer` with
   ``propagate="region"`` (the whole box of the wires' reach; today's default build,
   the OpenCL pass where a double-precision device exists, and the same on the numpy
   path) against ``propagate="flagged"`` (the voxels the plane masks touch, the paper's
   way, numpy and a k-d tree), float layout: one untimed build of each, then
   ``repeats`` builds of each *interleaved* so that load changes hit all alike;
   medians of the total and of propagation + flags; ratios are flagged / region. The fields are
   compared voxel by voxel (swept / vacated voxels that differ) and by one dvr image of
   each (framed camera): the largest channel difference (0..255) and the share of
   pixels that differ by more than 1/255.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

#: layouts compared in the storage table
STORAGE_LAYOUTS: tuple[str, ...] = ("float", "packed", "paper")
#: builds compared: (name, WireDeformer keyword arguments); ``region`` is today's
#: default (the OpenCL pass where a double-precision device exists), ``region numpy``
#: the same domain on the numpy path that ``flagged`` also takes
MODES: tuple[tuple[str, dict[str, str]], ...] = (
    ("region", {}),
    ("region numpy", {"backend": "scipy"}),
    ("flagged", {"propagate": "flagged"}),
)
#: image of the render comparison (W, H)
IMAGE_SIZE: tuple[int, int] = (256, 128)
#: points compared per layout (inside swept voxels)
COMPARE_POINTS = 200_000
#: image of the layouts' render cost (the paper's 512x256)
RENDER_SIZE: tuple[int, int] = (512, 256)


@dataclass
class StorageRow:
    """One layout on one phantom."""

    phantom: str
    layout: str
    scale: int
    field_shape: tuple[int, int, int]
    bytes_per_voxel: float
    field_bytes: int
    mask_bytes: tuple[int, ...]
    #: |mapping - float layout's mapping| over points in swept voxels (mm)
    median_mm: float
    max_mm: float
    #: steady dvr frame (framed camera, :data:`RENDER_SIZE`) over the undeformed one,
    #: alternated frame by frame (None: not rendered)
    render_ratio: float | None = None
    frame_ms: float | None = None


@dataclass
class PropagateRow:
    """Region vs flagged propagation on one phantom (medians over interleaved builds)."""

    phantom: str
    scale: int
    repeats: int
    region_s: float
    region_numpy_s: float
    flagged_s: float
    region_stage_s: float
    region_numpy_stage_s: float
    flagged_stage_s: float
    region_backend: str
    swept: tuple[int, int]
    vacated: tuple[int, int]
    #: field voxels whose state (identity / vacated / swept) differs
    state_differs: int
    #: dvr images: largest channel difference (0..255) and % of pixels over 1/255
    image_max: float | None
    image_changed_pct: float | None

    @property
    def ratio(self) -> float:
        """Flagged total / region total (median build seconds)."""
        return self.flagged_s / self.region_s

    @property
    def numpy_ratio(self) -> float:
        """Flagged total / region total on the same (numpy) path."""
        return self.flagged_s / self.region_numpy_s

    @property
    def stage_ratio(self) -> float:
        """Flagged / region seconds of propagation + flags."""
        return self.flagged_stage_s / max(self.region_stage_s, 1e-12)

    @property
    def numpy_stage_ratio(self) -> float:
        """Flagged / region (numpy path) seconds of propagation + flags."""
        return self.flagged_stage_s / max(self.region_numpy_stage_s, 1e-12)


def phantoms() -> list[tuple[str, Any, list[Any], int]]:
    """(label, volume, wires, field scale) of the fish (padded to 256³) and the tubes."""
    from benchmarks.wires import FISH_WIRES, TUBES_WIRES, load_wires, padded_fish
    from voxwarp.io.samples import load_sample

    out = []
    wires, spec = load_wires(FISH_WIRES)
    out.append(("fish", padded_fish(), wires, int(spec.get("field_scale", 2))))
    wires, spec = load_wires(TUBES_WIRES)
    vol = load_sample(str(spec.get("sample", "tubes")))
    out.append(("tubes", vol, wires, int(spec.get("field_scale", 2))))
    return out


def storage_rows(
    label: str,
    volume: Any,
    wires: Sequence[Any],
    scale: int,
    ctx: Any = None,
    frames: int = 5,
    log: Callable[[str], None] = print,
) -> list[StorageRow]:
    """Section 1 of the module docstring on one phantom (with ``ctx``: and each
    layout's steady dvr cost, ``frames`` frames alternated with the undeformed ones)."""
    from voxwarp.deform.wires.field import WireDeformer

    warps = {}
    for layout in STORAGE_LAYOUTS:
        wd = WireDeformer(volume, wires, field_scale=scale, layout=layout)
        wd.build()
        warps[layout] = (wd, wd.warp())
    ref = warps["float"][1]
    fld = ref.field
    state, _, _ = fld.decode()
    idx = np.argwhere(state == 2)
    rng = np.random.default_rng(0)
    if len(idx) > COMPARE_POINTS:
        idx = idx[rng.choice(len(idx), COMPARE_POINTS, replace=False)]
    p = fld.lo + (idx + rng.uniform(0.0, 1.0, idx.shape)) * fld.spacing
    q_ref = ref.apply(p)
    rows = []
    for layout, (wd, warp) in warps.items():
        d = np.linalg.norm(warp.apply(p) - q_ref, axis=1) if len(p) else np.zeros(1)
        f = warp.field
        rows.append(
            StorageRow(
                phantom=label,
                layout=layout,
                scale=scale,
                field_shape=tuple(int(n) for n in f.shape),  # type: ignore[arg-type]
                bytes_per_voxel=f.nbytes / float(np.prod(f.shape)),
                field_bytes=int(f.nbytes),
                mask_bytes=tuple(wd.stats.mask_bytes),
                median_mm=float(np.median(d)),
                max_mm=float(d.max()),
            )
        )
    if ctx is not None:
        _render_costs(rows, volume, wires, [wd for wd, _ in warps.values()], ctx, frames, log)
    return rows


def _render_costs(
    rows: Sequence[StorageRow],
    volume: Any,
    wires: Sequence[Any],
    deformers: Sequence[Any],
    ctx: Any,
    frames: int,
    log: Callable[[str], None],
) -> None:
    """Each layout's steady dvr frame against the undeformed one (the wire bench's
    :func:`benchmarks.wires._render_layout`: field upload and skip maps first, then
    frames alternated with the undeformed volume)."""
    from benchmarks.wires import _prime, _render_layout, make_camera
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    tf = _sample_tf(volume)
    cam = make_camera("framed", volume, wires, RENDER_SIZE)
    base = Scene(volume, mode="dvr", transfer_function=tf, camera=cam)
    with OffscreenRenderer(*RENDER_SIZE, ctx=ctx) as r:
        r.render(base)
        for row, wd in zip(rows, deformers, strict=True):
            _prime(r, base.copy(warps=[wd.warp()]))
            rr = _render_layout(r, base, wd, RENDER_SIZE, "framed", tf, frames, log)
            row.render_ratio, row.frame_ms = rr.ratio, rr.median_ms


def _sample_tf(volume: Any) -> str:
    """The suggested transfer function of a bundled sample (the fish's otherwise)."""
    from voxwarp.io.samples import suggested_transfer_function

    source = str(getattr(volume, "source", "") or "")
    sample = source.split(":", 1)[1] if source.startswith("sample:") else "fish"
    return str(suggested_transfer_function(sample))


def propagate_row(
    label: str,
    volume: Any,
    wires: Sequence[Any],
    scale: int,
    repeats: int,
    ctx: Any = None,
    log: Callable[[str], None] = print,
) -> PropagateRow:
    """Section 2 of the module docstring on one phantom."""
    from voxwarp.deform.wires.field import WireDeformer

    wds = {m: WireDeformer(volume, wires, field_scale=scale, **kw) for m, kw in MODES}
    for wd in wds.values():
        wd.build()  # untimed: OpenCL kernels and buffers, k-d tree code paths
    totals: dict[str, list[float]] = {m: [] for m in wds}
    stages: dict[str, list[float]] = {m: [] for m in wds}
    for _ in range(max(1, int(repeats))):
        for m in wds:
            st = wds[m].build()
            totals[m].append(st.timings["total"])
            stages[m].append(st.timings["propagate"] + st.timings["flags"])
    sr, sf = wds["region"].stats, wds["flagged"].stats
    assert sr is not None
    assert sf is not None
    a, _, _ = wds["region"].field.decode()  # type: ignore[union-attr]
    b, _, _ = wds["flagged"].field.decode()  # type: ignore[union-attr]
    image_max = changed = None
    if ctx is not None:
        image_max, changed = _image_difference(volume, wires, wds, ctx)
    row = PropagateRow(
        phantom=label,
        scale=scale,
        repeats=len(totals["region"]),
        region_s=statistics.median(totals["region"]),
        region_numpy_s=statistics.median(totals["region numpy"]),
        flagged_s=statistics.median(totals["flagged"]),
        region_stage_s=statistics.median(stages["region"]),
        region_numpy_stage_s=statistics.median(stages["region numpy"]),
        flagged_stage_s=statistics.median(stages["flagged"]),
        region_backend=sr.backend,
        swept=(sr.swept, sf.swept),
        vacated=(sr.vacated, sf.vacated),
        state_differs=int(np.count_nonzero(a != b)),
        image_max=image_max,
        image_changed_pct=changed,
    )
    log(
        f"{label}: region {row.region_s:.3f} s, region numpy {row.region_numpy_s:.3f} s,"
        f" flagged {row.flagged_s:.3f} s ({row.ratio:.2f}x, {row.numpy_ratio:.2f}x);"
        f" {row.state_differs} field voxels differ"
    )
    return row


def _image_difference(
    volume: Any, wires: Sequence[Any], wds: dict[str, Any], ctx: Any
) -> tuple[float, float]:
    """Largest channel difference (0..255) and % of pixels over 1/255 between the dvr
    images of the region and flagged fields (framed camera, the sample's TF)."""
    from benchmarks.wires import make_camera
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.scene import Scene

    tf = _sample_tf(volume)
    cam = make_camera("framed", volume, wires, IMAGE_SIZE)
    base = Scene(volume, mode="dvr", transfer_function=tf, camera=cam)
    with OffscreenRenderer(*IMAGE_SIZE, ctx=ctx) as r:
        imgs = [
            np.asarray(r.render(base.copy(warps=[wds[m].warp()])), dtype=np.float64)
            for m in ("region", "flagged")
        ]
    diff = np.abs(imgs[0] - imgs[1])
    if imgs[0].max() <= 1.0:  # float images: to 0..255
        diff = diff * 255.0
    per_pixel = diff[..., :3].max(axis=-1)
    return float(per_pixel.max()), float(100.0 * np.mean(per_pixel > 1.0))


def markdown(storage: Sequence[StorageRow], modes: Sequence[PropagateRow], command: str) -> str:
    """The report (two tables) headed by ``command``."""
    lines = [
        f"Command: `{command}`",
        "",
        "### Storage (paper section 7.2) and mask memory (section 7.1)",
        "",
        "One build per layout at the wire file's field scale. mask bytes: kept planes x"
        " K² / 8 per wire (one bit per mask pixel). |Δ| vs float: distance between the"
        " layout's mapped point and the float layout's, at random points in swept voxels.",
        "",
        "| phantom | scale | field | layout | bytes/voxel | field MB | mask bytes per wire |"
        " mask bytes total | median abs delta vs float mm | max abs delta vs float mm |"
        f" dvr {RENDER_SIZE[0]}x{RENDER_SIZE[1]} / undeformed | frame ms |",
        "|---|---:|---|---|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in storage:
        ratio = "—" if r.render_ratio is None else f"{r.render_ratio:.2f}x"
        ms = "—" if r.frame_ms is None else f"{r.frame_ms:.0f}"
        lines.append(
            f"| {r.phantom} | {r.scale} | {'x'.join(map(str, r.field_shape))} | {r.layout} |"
            f" {r.bytes_per_voxel:g} | {r.field_bytes / 1e6:.2f} |"
            f" {', '.join(map(str, r.mask_bytes))} | {sum(r.mask_bytes)} |"
            f" {r.median_mm:.4f} | {r.max_mm:.3f} | {ratio} | {ms} |"
        )
    lines += [
        "",
        "### Propagation domain: region box vs flagged voxels (paper section 5.1)",
        "",
        "Float layout; medians of interleaved builds (region, region numpy, flagged, ...)"
        " after one untimed build of each. region = today's default build (backend column:"
        " the OpenCL pass where available); region numpy = the same domain on the numpy"
        " path, which flagged also takes. ratio = flagged / region (below 1: flagged is"
        " faster); numpy ratio = flagged / region numpy. stage = propagation + flags."
        " Field voxels and images compare region with flagged. image: dvr at"
        f" {IMAGE_SIZE[0]}x{IMAGE_SIZE[1]} (framed camera), largest channel difference"
        " (0..255) and % of pixels differing by more than 1/255.",
        "",
        "| phantom | scale | builds | region s | region numpy s | flagged s | ratio |"
        " numpy ratio | stage ratio | numpy stage ratio | region backend |"
        " swept (region / flagged) | vacated | field voxels differing | image max diff |"
        " image pixels changed % |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---|---|---:|---:|---:|",
    ]
    for m in modes:
        img = "—" if m.image_max is None else f"{m.image_max:.0f}"
        pct = "—" if m.image_changed_pct is None else f"{m.image_changed_pct:.3f}"
        lines.append(
            f"| {m.phantom} | {m.scale} | {m.repeats} | {m.region_s:.3f} |"
            f" {m.region_numpy_s:.3f} | {m.flagged_s:.3f} | {m.ratio:.2f} |"
            f" {m.numpy_ratio:.2f} | {m.stage_ratio:.2f} | {m.numpy_stage_ratio:.2f} |"
            f" {m.region_backend} |"
            f" {m.swept[0]} / {m.swept[1]} | {m.vacated[0]} / {m.vacated[1]} |"
            f" {m.state_differs} | {img} | {pct} |"
        )
    return "\n".join(lines) + "\n"


def bench_storage(
    repeats: int = 5,
    images: bool = True,
    frames: int = 5,
    ctx: Any = None,
    log: Callable[[str], None] = print,
) -> tuple[list[StorageRow], list[PropagateRow]]:
    """Both sections on every phantom of :func:`phantoms`; ``images``: also time each
    layout's dvr (``frames`` frames) and compare the propagation modes' images (on
    ``ctx``, by default a standalone EGL context)."""
    if images and ctx is None:
        from voxwarp.render.context import create_context

        ctx = create_context()
    elif not images:
        ctx = None
    storage: list[StorageRow] = []
    modes: list[PropagateRow] = []
    for label, vol, wires, scale in phantoms():
        storage += storage_rows(label, vol, wires, scale, ctx, frames, log)
        modes.append(propagate_row(label, vol, wires, scale, repeats, ctx, log))
    return storage, modes
