"""``voxwarp demo wires`` (Journal of WSCG 2006, Figure 12 and Table 1).

The fish bent by the bundled spine wires with the attribute field at 1:1 ... 1:4096, build
times, the share of field voxels and of ray samples that need no mapping ("ignored")
(:mod:`voxwarp.teaching.wire_measure`); the paper's Tables 1-3 measured its way are
``python -m benchmarks wire-tables`` in a checkout. Run by
:func:`voxwarp.teaching.demos.run_demo`; the helpers it shares with the other demos are in
:mod:`voxwarp.teaching.sheets`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.deform.wires.propagation import opencl_device_name
from voxwarp.io.samples import load_sample
from voxwarp.scene import Scene
from voxwarp.teaching import DEMO_TITLES, sheets, wires_fig12
from voxwarp.teaching.wire_measure import (
    DEFAULT_SCALES,
    FISH_WIRES,
    FRAMED_VIEW,
    RENDER_SCALE,
    classify_samples,
    field_error,
    field_points,
    framed_camera,
    load_wires,
    padded_fish,
    time_field_builds,
)

#: every ERROR_STRIDE-th voxel per axis is a point where the coarse fields' mappings are
#: compared with the 1:1 field's (:func:`~voxwarp.teaching.wire_measure.field_error`)
ERROR_STRIDE = 2


# ====================================================================== wires
def demo_wires(
    s: sheets.DemoSettings, out: Path, log: Callable[[str], None]
) -> tuple[list[Path], dict[str, Any], list[sheets.TourStep]]:
    from voxwarp.deform.wires.field import WireFieldWarp

    vol = padded_fish() if s.wire_padded else sheets.fish_volume(s)
    wires, spec = load_wires(FISH_WIRES)
    size = s.wire_size
    # the pictures from above (+z: the sideways bend in the image plane, the tail fin
    # turned edge-on by the twist); the ray statistics and the render cost from the view
    # of ``python -m benchmarks wires`` (FRAMED_VIEW), so that they compare with its report
    cam = framed_camera(vol, wires, size, view=sheets.FISH_VIEW)
    stats_cam = framed_camera(vol, wires, size)
    tf = sheets.FISH_TF
    rows: list[dict[str, Any]] = []
    renders: list[tuple[str, np.ndarray]] = []
    render_cost: dict[str, Any] = {}
    with sheets.offscreen_renderer(size) as r:
        gl = sheets.gl_renderer(r)
        base = Scene(vol, transfer_function=tf, camera=cam, jitter=False)
        stats_base = base.copy(camera=stats_cam)
        renders.append(("undeformed", sheets.render_rgb(r, base, size)))
        first: np.ndarray | None = None
        reference: Any = None  # the 1:1 field's warp, the oracle of the coarse ones
        points = field_points(vol, ERROR_STRIDE)
        warps: list[Any] = []
        for scale in DEFAULT_SCALES:
            row, wd = time_field_builds(vol, wires, scale, s.wire_repeats)
            warp = wd.warp()
            reference = warp if reference is None else reference
            warps.append(warp)
            scene = base.copy(warps=[warp])
            stats_scene = stats_base.copy(warps=[warp])
            stats = classify_samples(stats_scene, stats_cam, size, warp, s.wire_subsample)
            img = sheets.render_rgb(r, scene, size)
            renders.append((f"1:{scale**3}", img))
            if first is None:
                first = img
            differ = np.abs(img.astype(np.int16) - first.astype(np.int16)).max(axis=-1) > 24
            rows.append(
                {
                    "scale": scale,
                    "ratio": f"1:{scale**3}",
                    **row,
                    "samples": stats["samples"],
                    "samples_ignored": stats["identity"],
                    "samples_vacated": stats["vacated"],
                    "samples_swept": stats["swept"],
                    "percent_ignored_samples": 100.0 * stats["identity"] / max(stats["samples"], 1),
                    "pixels_differing_from_1to1": 100.0 * float(differ.mean()),
                    "error_vs_1to1": field_error(vol, reference, warp, points),
                }
            )
            log(
                f"wires 1:{scale**3}: built in {row['build_s']:.3f} s,"
                f" {row['percent_ignored_voxels']:.2f} % of field voxels and"
                f" {rows[-1]['percent_ignored_samples']:.2f} % of ray samples ignored"
            )
            if scale == RENDER_SCALE:
                warm = 2 if not s.quick else 1
                deformed = r.time_frames(stats_scene, frames=s.wire_frames, warmup=warm)
                plain = r.time_frames(stats_base, frames=s.wire_frames, warmup=warm)
                render_cost = {
                    "scale": scale,
                    "deformed_ms": float(np.median(deformed)),
                    "undeformed_ms": float(np.median(plain)),
                    "frames": s.wire_frames,
                }
                render_cost["ratio"] = render_cost["deformed_ms"] / render_cost["undeformed_ms"]
        # Figure 12 close up: the bent tail through each field (after the timings: same size)
        zcam = wires_fig12.tail_camera(wires, size, sheets.FISH_VIEW)
        zooms = [
            (row["ratio"], sheets.render_rgb(r, base.copy(camera=zcam, warps=[w]), size))
            for row, w in zip(rows, warps, strict=True)
        ]
    numbers: dict[str, Any] = {
        "storage": _wire_storage(vol, wires),
        "volume": vol.name,
        "volume_shape": vol.shape,
        "wire_file": "sample_volumes/fish_spine_wires.json",
        "image": size,
        "transfer_function": tf,
        "ray_subsample": s.wire_subsample,
        "error_stride": ERROR_STRIDE,
        "spacing": tuple(float(v) for v in vol.spacing),
        "view": sheets.FISH_VIEW,
        "stats_view": FRAMED_VIEW,
        "rows": rows,
        "render_cost": render_cost,
        "opencl_device": opencl_device_name(),
        "gl_renderer": gl,
    }
    fig = sheets.new_figure(16.0, 11.0, DEMO_TITLES["wires"])
    grid = fig.add_gridspec(3, 1, height_ratios=[1.0, 1.0, 1.15])
    for row_i in range(2):
        sub = grid[row_i].subgridspec(1, 3)
        for j in range(3):
            idx = row_i * 3 + j
            title, img = renders[idx]
            if idx == 0:
                label = "(a) undeformed fish"
            else:
                rw = rows[idx - 1]
                fs = "x".join(map(str, rw["field_shape"]))
                label = f"({'abcdef'[idx]}) field {title} ({fs}), built in {rw['build_s']:.3f} s"
                if idx > 1:
                    diff = rw["pixels_differing_from_1to1"]
                    mm = rw["error_vs_1to1"]["object_mm"]
                    label += (
                        f"\n{diff:.2f} % of the pixels differ from the 1:1 image;"
                        f" map vs 1:1 RMS {mm['rms']:.2f}, max {mm['max']:.2f} mm"
                    )
            sheets.show_image(fig.add_subplot(sub[0, j]), img, label)
    bottom = grid[2].subgridspec(1, 2, width_ratios=[1.0, 1.35])
    _plot_ignored(fig.add_subplot(bottom[0, 0]), numbers)
    _table_wires(fig.add_subplot(bottom[0, 1]), numbers)
    path = sheets.save_figure(fig, out / "wires.png")
    zoom_path = wires_fig12.zoom_sheet(zooms, rows, out / "wires_fig12.png")

    # the tour's scenes: the bundled fish (its default shape), the wire file at each scale
    fish = load_sample("fish")
    tcam = framed_camera(fish, wires, size)
    entry = {"type": "wires", **{k: v for k, v in spec.items() if k in ("wires", "masks")}}
    tour = [
        sheets.TourStep(
            "Wires",
            "A wire is a curve laid through an object (the base wire, along the fish's spine)"
            " and a modified copy the user bends, twists and scales. Each cross-section of the"
            " object normal to the base wire is shown on the plane normal to the modified wire"
            " at the same fraction of its length.",
            sheets.snap(Scene(fish, transfer_function=tf, camera=tcam, jitter=False)),
            "a",
        ),
    ]
    for i, scale in enumerate(DEFAULT_SCALES):
        warp = WireFieldWarp.from_dict({**entry, "field_scale": scale})
        tour.append(
            sheets.TourStep(
                f"Attribute field 1:{scale**3}",
                "Every ray sample looks up a field that says whether it is swept, by which"
                " wire and at which fraction t, or can be ignored (no mapping needed)."
                f" Here the field has one voxel per {scale}³ volume voxels"
                f" ({rows[i]['percent_ignored_voxels']:.1f} % of its voxels ignored,"
                f" built in {rows[i]['build_s']:.3f} s on this machine). Coarser fields"
                " build faster but blur the edges of the swept object.",
                sheets.snap(
                    Scene(fish, transfer_function=tf, camera=tcam, jitter=False, warps=[warp])
                ),
                "abcdef"[i + 1],
            )
        )
    tour.append(
        sheets.TourStep(
            "Samples ignored",
            "Most samples of a ray never touch the bent object: they read the field once and"
            " go on unmapped (panel g, the wire paper's Table 1). The share shrinks as the"
            " field gets coarser, because a coarse voxel that touches the object counts as"
            " swept as a whole.",
            None,
            "g",
        )
    )
    return [path, zoom_path], numbers, tour


def _wire_storage(vol: Any, wires: Sequence[Any]) -> list[dict[str, Any]]:
    """Bytes per field voxel of each layout and the plane masks' memory (section 7.2 and
    7.1) for the fish's field at the render scale."""
    from voxwarp.deform.wires.field import LAYOUTS, WireDeformer

    rows = []
    for layout in LAYOUTS:
        wd = WireDeformer(vol, wires, field_scale=RENDER_SCALE, layout=layout)
        st = wd.build()
        rows.append(
            {
                "layout": layout,
                "field_shape": list(st.field_shape),
                "bytes_per_voxel": wd.field.nbytes / st.voxels,
                "field_bytes": wd.field.nbytes,
                "mask_bytes": st.mask_bytes_total,
            }
        )
    return rows


def _plot_ignored(ax: Any, n: dict[str, Any]) -> None:
    rows = n["rows"]
    labels = [r["ratio"] for r in rows]
    x = np.arange(len(rows))
    ax.plot(x, [r["percent_ignored_voxels"] for r in rows], "o-", lw=2, label="field voxels")
    ax.plot(x, [r["percent_ignored_samples"] for r in rows], "s-", lw=2, label="ray samples")
    ax.set_xticks(x, labels)
    ax.set_xlabel("attribute field : volume voxels")
    ax.set_ylabel("ignored (identity, no mapping) %")
    ax.set_title("(g) samples ignored per field scale, over the whole ray box", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax2 = ax.twinx()
    ax2.semilogy(x, [r["build_s"] for r in rows], "^--", color="tab:red", label="build time")
    ax2.set_ylabel("field build (s, log)", color="tab:red")
    ax2.tick_params(axis="y", colors="tab:red")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper right")


def _table_wires(ax: Any, n: dict[str, Any]) -> None:
    ax.axis("off")
    head = [
        "field",
        "shape",
        "build s",
        "swept",
        "vacated",
        "% voxels\nignored",
        "samples",
        "% samples\nignored",
    ]
    cells = [
        [
            r["ratio"],
            "x".join(map(str, r["field_shape"])),
            f"{r['build_s']:.3f}",
            str(r["swept"]),
            str(r["vacated"]),
            f"{r['percent_ignored_voxels']:.2f}",
            str(r["samples"]),
            f"{r['percent_ignored_samples']:.2f}",
        ]
        for r in n["rows"]
    ]
    table = ax.table(cellText=cells, colLabels=head, loc="upper center", cellLoc="right")
    table.auto_set_font_size(False)
    table.set_fontsize(9)
    table.scale(1.0, 1.6)
    for (row, _col), cell in table.get_celld().items():
        if row == 0:
            cell.set_facecolor("0.9")
            cell.set_text_props(fontweight="bold")
    rc = n["render_cost"]
    text = (
        "Coarser fields build faster, but a coarse voxel that touches the bent object is"
        " swept as a whole, so fewer samples can be ignored. Pixels 'differ' by more than"
        " 24/255 in a channel. Table 1 counted the paper's way (inside the wires' regions"
        " only) and Tables 2-3 (identity wires): `voxwarp reproduce`'s report."
    )
    if rc:
        text += (
            f" Render at 1:{rc['scale'] ** 3}: {rc['deformed_ms']:.1f} ms deformed vs"
            f" {rc['undeformed_ms']:.1f} ms undeformed = {rc['ratio']:.2f}x"
            f" ({n['image'][0]}x{n['image'][1]}, {n['gl_renderer']})."
        )
    sheets.add_note(ax, text, "lower left", 110)
    ax.set_title(
        f"(h) field builds (median of {n['rows'][0]['builds']}) and ray samples\n{n['volume']};"
        f" rays through every {n['ray_subsample']}th pixel of {n['image'][0]}x{n['image'][1]},"
        f" view {tuple(n['stats_view'])}",
        fontsize=10,
    )
