"""The default levels of the threshold modes: ``iso``'s iso value, ``flm``'s threshold.

Both start from the **object/background split** of the volume's histogram
(:func:`object_split`): Otsu's threshold (the split that maximises the variance between
the two classes) of the values inside the field of view, clipped to their 0.5-99.5
percentiles so a few extreme voxels (metal, hot pixels) do not pull it. Below the split
lie the background's air and noise; the level never goes there, so neither the noise of
an MRI's background nor the air of a CT trips the first-local-maximum test or draws a
speckled surface. For integer data the split sits half-way between the last value of
the background class and the first of the object's (``2.5`` between 2 and 3), so an
iso surface does not hug one quantised value.

Then, per modality (:func:`voxwarp.core.modality_detection.detect_modality` and the
file's own Modality tag):

* **CT** (Hounsfield units, or a file tagged CT with other units, like the bundled
  ``sample:stent``): the level follows the transfer function, as a CT's values say
  which tissue they are: ``iso`` where its opacity first reaches a quarter of its
  maximum (bone for ``ct-bone``), ``flm`` the lowest value it shows; raised to the split
  when the transfer function starts below it.
* **MR and other data**: the split itself: the object's outer surface (the skin of a
  head MRI) for ``iso``, and the first local maximum inside the object for ``flm``.

Set them with ``Scene(iso_value=...)`` / ``Scene(flm_threshold=...)`` or ``voxwarp
render --iso VALUE`` / ``--flm-threshold VALUE`` (data units); ``voxwarp render`` prints
the level it used and why in its one stderr line (:meth:`Level.text`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from voxwarp.core.modality import inside_values
from voxwarp.core.modality_detection import detect_modality, volume_cache
from voxwarp.core.transfer_function import TransferFunction
from voxwarp.core.volume import Volume
from voxwarp.deform.histogram import otsu

#: The threshold modes and the scene attribute that holds their level.
LEVEL_ATTRIBUTES: dict[str, str] = {"iso": "iso_value", "flm": "flm_threshold"}
#: Percentiles of the values inside the field of view the split's histogram spans.
SPLIT_PERCENTILES: tuple[float, float] = (0.5, 99.5)
#: Bins of the split's histogram.
SPLIT_BINS = 256
#: ``iso`` on a CT: where the transfer function's opacity first reaches this share of
#: its maximum.
ISO_OPACITY_SHARE = 0.25


class Level(NamedTuple):
    """A level a threshold mode uses: ``value`` (data units) and ``source``, why."""

    value: float
    source: str

    def text(self, mode: str) -> str:
        """E.g. ``iso 49.5 (the histogram's object/background split; set with --iso)``."""
        what, flag = ("iso", "--iso") if mode == "iso" else ("threshold", "--flm-threshold")
        if self.source == "given":
            return f"{what} {self.value:.4g} (given)"
        return f"{what} {self.value:.4g} ({self.source}; set with {flag})"


def otsu_split(values: np.ndarray, bins: int = SPLIT_BINS) -> float:
    """Otsu's threshold of ``values``: the split of a ``bins``-bin histogram that
    maximises the between-class variance, placed half-way between the largest value
    below it and the smallest value above it (so integer data split at ``k + 0.5``).
    A constant array returns its value."""
    v = np.asarray(values, dtype=np.float64).ravel()
    lo, hi = float(v.min()), float(v.max())
    if not hi > lo:
        return lo
    edge = otsu(v, bins).edge
    below, above = v[v < edge], v[v >= edge]
    if below.size == 0 or above.size == 0:
        return edge
    return 0.5 * (float(below.max()) + float(above.min()))


def object_split(volume: Volume) -> float:
    """The object/background split of ``volume``'s histogram (see the module docstring;
    cached per volume)."""
    cache = volume_cache(volume)
    if "object_split" not in cache:
        values = inside_values(volume).astype(np.float64)
        lo, hi = np.percentile(values, SPLIT_PERCENTILES)
        cache["object_split"] = otsu_split(np.clip(values, lo, hi))
    return float(cache["object_split"])  # type: ignore[arg-type]


def follows_transfer_function(volume: Volume) -> bool:
    """Whether the default levels of ``volume`` follow its transfer function (a CT: in
    Hounsfield units, or tagged CT by its file) rather than the split alone."""
    return detect_modality(volume).hu or (volume.modality or "").strip().upper() == "CT"


def tf_iso_value(tf: TransferFunction) -> float | None:
    """Where ``tf``'s opacity first reaches :data:`ISO_OPACITY_SHARE` of its maximum;
    None when it shows nothing."""
    amax = float(np.asarray(tf.points)[:, 4].max())
    if amax <= 0:
        return None
    v = np.linspace(*tf.value_range, 4096)
    return float(v[np.argmax(tf(v)[:, 3] >= ISO_OPACITY_SHARE * amax)])


def default_level(volume: Volume, tf: TransferFunction, mode: str) -> Level:
    """The default level of threshold ``mode`` (``"iso"`` or ``"flm"``) for ``volume``
    drawn with ``tf`` (see the module docstring)."""
    split = object_split(volume)
    split_level = Level(split, "the histogram's object/background split")
    if not follows_transfer_function(volume):
        return split_level
    own = tf_iso_value(tf) if mode == "iso" else tf.first_visible_value()
    if own is None or own < split:
        return split_level
    what = "opacity a quarter of its maximum" if mode == "iso" else "its lowest visible value"
    return Level(own, f"tf {tf.name}: {what}, above the object/background split {split:.4g}")
