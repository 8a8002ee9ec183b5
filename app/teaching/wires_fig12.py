"""The wire paper's Figure 12 close up: the bent tail of the fish through the attribute
field at each scale (1:1 ... 1:4096), and where each picture differs from the 1:1 one.

The paper's coarse fields look blocky (trilinear interpolation across the field's large
gaps); :func:`tail_camera` frames the part of the object the wire moves most, so that
edges and blocks would show, and :func:`zoom_sheet` puts the pictures above their
differences from the 1:1 picture (amplified :data:`DIFF_GAIN` times). The measurement
beside it is :func:`voxwarp.teaching.wire_measure.field_error`. Used by
:mod:`voxwarp.teaching.wires_demo`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.camera import Camera
from voxwarp.teaching import sheets

#: the last fraction of the modified wire the close-up frames (where the tail bends)
TAIL_FROM = 0.6
#: the differences from the 1:1 picture are shown this many times brighter
DIFF_GAIN = 4


def tail_camera(wires: Sequence[Any], size: tuple[int, int], view: Any) -> Camera:
    """A camera from ``view`` framing the modified wires' last :data:`TAIL_FROM` part
    grown by their regions of influence (the object the wires move most)."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for w in wires:
        pts = w.modified.evaluate(np.linspace(TAIL_FROM, 1.0, 129))
        r = w.radius * float(w.scale[:, 1].max())
        lo, hi = np.minimum(lo, pts.min(0) - r), np.maximum(hi, pts.max(0) + r)
    return Camera.framing(lo, hi, view, size, fill=0.95, fov=30.0)


def content_crop(images: Sequence[np.ndarray], margin: float = 0.06) -> tuple[slice, slice]:
    """Rows and columns holding what any of ``images`` shows (a channel above 8/255),
    grown by ``margin`` of the image size; the whole image when all are empty."""
    shown = np.zeros(images[0].shape[:2], dtype=bool)
    for img in images:
        shown |= img.max(axis=-1) > 8
    if not shown.any():
        return slice(None), slice(None)
    h, w = shown.shape
    rows, cols = np.nonzero(shown.any(axis=1))[0], np.nonzero(shown.any(axis=0))[0]
    my, mx = int(margin * h), int(margin * w)
    return (
        slice(max(rows[0] - my, 0), min(rows[-1] + my + 1, h)),
        slice(max(cols[0] - mx, 0), min(cols[-1] + mx + 1, w)),
    )


def difference(img: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``|img - reference|`` per pixel (largest channel), times :data:`DIFF_GAIN`,
    as uint8 grey."""
    d = np.abs(img.astype(np.int16) - reference.astype(np.int16)).max(axis=-1)
    return np.clip(d * DIFF_GAIN, 0, 255).astype(np.uint8)


def zoom_sheet(
    zooms: Sequence[tuple[str, np.ndarray]], rows: Sequence[dict[str, Any]], out: Path
) -> Path:
    """The close-ups (one per field scale, ``(ratio, image)``, 1:1 first) over their
    differences from the 1:1 close-up, each labelled with the field's mapping error
    (``rows[i]["error_vs_1to1"]``), cropped to what they show; written to ``out``."""
    fig = sheets.new_figure(
        16.0, 6.2, "Wire paper Fig. 12 close up: the bent tail per attribute field scale"
    )
    axes = fig.subplots(2, len(zooms))
    crop = content_crop([img for _, img in zooms])
    zooms = [(ratio, img[crop]) for ratio, img in zooms]
    reference = zooms[0][1]
    for i, ((ratio, img), row) in enumerate(zip(zooms, rows, strict=True)):
        e = row["error_vs_1to1"]["object_mm"]
        sheets.show_image(axes[0, i], img, f"field {ratio}")
        if i == 0:
            axes[1, i].axis("off")
            sheets.add_note(
                axes[1, i],
                f"Below the pictures: |difference| from the 1:1 picture, x{DIFF_GAIN}."
                " Mapping error over the object against the 1:1 field: RMS / max mm.",
                "upper left",
                34,
            )
            continue
        d = difference(img, reference)
        label = (
            f"{ratio}: {100.0 * float((d > 24 * DIFF_GAIN).mean()):.2f} % px > 24/255;"
            f" {e['rms']:.3f} / {e['max']:.2f} mm"
        )
        axes[1, i].imshow(d, cmap="magma", vmin=0, vmax=255, interpolation="nearest")
        axes[1, i].set_title(label, fontsize=9)
        axes[1, i].set_xticks([])
        axes[1, i].set_yticks([])
    return sheets.save_figure(fig, out)
