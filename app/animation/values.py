"""Key values of animation tracks: the animation's error, value checks and interpolation.

Shared by :mod:`voxwarp.animation.tracks` and the per-family target handlers of
:mod:`voxwarp.animation.targets`; :mod:`~voxwarp.animation.tracks` re-exports the public
names.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp.errors import VoxwarpError


class AnimationError(VoxwarpError, ValueError):
    """An animation entry is invalid or does not fit its scene (names the fix)."""


def number(x: Any, what: str) -> float:
    """A finite number (``what`` names it in the error)."""
    if isinstance(x, bool) or not isinstance(x, int | float):
        raise AnimationError(f"{what} must be a number; got {x!r:.60}")
    v = float(x)
    if not math.isfinite(v):
        raise AnimationError(f"{what} must be finite; got {x!r}")
    return v


def array(x: Any, what: str, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """A finite float64 array; ``shape`` entries None match any length."""
    if isinstance(x, str | bytes | Mapping) or x is None:
        raise AnimationError(f"{what} must be numbers; got {x!r:.60}")
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise AnimationError(f"{what} must be numbers; got {x!r:.60}") from exc
    if shape is not None and (
        a.ndim != len(shape)
        or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=True))
    ):
        want = "x".join("N" if s is None else str(s) for s in shape) or "a single number"
        raise AnimationError(f"{what} must have shape {want}; got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise AnimationError(f"{what} has NaN/Inf entries")
    return a


def key_weights(
    frames: Sequence[float], frame: float, interpolation: str = "linear"
) -> tuple[int, int, float]:
    """Where ``frame`` falls among key ``frames``: ``(i, j, t)`` with the value
    ``(1 - t) v_i + t v_j``.

    Parameters
    ----------
    frames
        Strictly increasing key frames.
    frame
        The frame to evaluate (any number; clamped to the first/last key).
    interpolation
        ``"linear"`` or ``"smooth"`` (smoothstep-eased ``t``; see
        :mod:`voxwarp.animation.tracks`).

    Returns
    -------
    tuple
        ``(i, j, t)``; ``t == 0`` exactly on a key (then ``i`` is that key).
    """
    f = np.asarray(frames, dtype=np.float64)
    x = float(frame)
    if x <= f[0]:
        return 0, 0, 0.0
    if x >= f[-1]:
        return len(f) - 1, len(f) - 1, 0.0
    j = int(np.searchsorted(f, x, side="right"))
    i = j - 1
    t = (x - f[i]) / (f[j] - f[i])
    if interpolation == "smooth":
        t = t * t * (3.0 - 2.0 * t)
    return i, j, float(t)


def interpolate(
    keys: Sequence[tuple[float, Any]], frame: float, interpolation: str = "linear"
) -> np.ndarray:
    """Blend array values of ``[(frame, value), ...]`` keys at ``frame``.

    Parameters
    ----------
    keys
        ``(frame, value)`` pairs, frames strictly increasing, values arrays of one shape.
    frame
        Frame to evaluate.
    interpolation
        ``"linear"`` or ``"smooth"``.

    Returns
    -------
    numpy.ndarray
        float64 array of the values' shape (the key's own value on a key; never outside
        the range of the two keys around ``frame``, component by component).
    """
    i, j, t = key_weights([k[0] for k in keys], frame, interpolation)
    a = np.asarray(keys[i][1], dtype=np.float64)
    if t == 0.0:
        return a.copy()
    b = np.asarray(keys[j][1], dtype=np.float64)
    # a + t (b - a) is exact for equal keys; the clip keeps rounding inside the keys'
    # range (a transfer function's 1.0 never becomes 1.0000000000000002)
    return np.clip(a + t * (b - a), np.minimum(a, b), np.maximum(a, b))
