"""The study behind :class:`~voxwarp.deform.elements.offset_field.OffsetFieldWarp`'s default
inverse iterations: how far ``q = apply(p)`` lands from a true original point, per inverse
mode and iteration count, for a large drag (docs/benchmarks.md, section
'voxwarp.deform.elements.offset_field: inverse accuracy and cost').

CPU only, a few seconds; from the checkout's root, ``python -m benchmarks.offset_inverse``
prints the table for the defaults.

:func:`gaussian_drag_field` (a dragged node with smoothly relaxed neighbours) is also the
tests' smooth offset field.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp.deform.elements.offset_field import OffsetFieldWarp


def gaussian_drag_field(
    shape: Sequence[int],
    node: Sequence[int],
    displacement: Sequence[float],
    sigma: float,
) -> np.ndarray:
    """A dragged node with smoothly relaxed neighbours: ``d * exp(-|i - node|² / 2σ²)``.

    Parameters
    ----------
    shape
        Node counts ``(nx, ny, nz)``.
    node
        Index of the dragged node.
    displacement
        Its displacement (mm), applied in full at ``node``.
    sigma
        Width of the Gaussian fall-off, in nodes.

    Returns
    -------
    numpy.ndarray
        ``(nx, ny, nz, 3)`` displacements in mm.
    """
    idx = np.stack(np.meshgrid(*(np.arange(n) for n in shape), indexing="ij"), axis=-1)
    d2 = np.sum((idx - np.asarray(node)) ** 2, axis=-1)
    return np.exp(-d2 / (2.0 * sigma**2))[..., None] * np.asarray(displacement, float)


def inverse_error_table(
    n: int = 16,
    drag: float = 1.5,
    sigma: float = 2.0,
    iterations: Sequence[int] = (1, 2, 4, 5, 6, 8, 16),
    baked_iterations: Sequence[int] = (0, 1, 2, 3),
    points: int = 20000,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """Residual of the inverse for a large drag: the study behind the default iterations.

    An ``n³`` grid with node spacing 1 mm; the interior node ``(n//2,)*3`` moves by
    ``drag`` spacings along +x and every node by the Gaussian (``sigma`` nodes) of
    :func:`gaussian_drag_field`. Deformed points ``p`` are drawn uniformly (``seed``) in
    the box of half-width ``3 sigma + drag`` spacings around the dragged node's rest
    position (clipped to the grid), and the residual ``|field_forward(apply(p)) - p|`` is
    measured for ``"approx"`` and for ``"exact"`` and ``"baked"`` with each iteration
    count. docs/benchmarks.md shows the table for the defaults.

    Parameters
    ----------
    n, drag, sigma
        Grid size, drag distance (node spacings) and fall-off width (nodes).
    iterations
        Iteration counts of ``"exact"`` to measure.
    baked_iterations
        Correction counts of ``"baked"`` to measure (0: the baked seed alone).
    points, seed
        Number of sample points and the RNG seed.

    Returns
    -------
    list of dict
        Rows ``{"inverse", "iterations", "max", "mean", "max_grad"}``: residuals in
        units of the node spacing, and the largest ``|du/dX|`` entry of the field.
    """
    shape = (n, n, n)
    centre = (n // 2,) * 3
    u = gaussian_drag_field(shape, centre, (drag, 0.0, 0.0), sigma)
    lo, hi = np.zeros(3), np.full(3, n - 1.0)
    half = 3.0 * sigma + drag
    rng = np.random.default_rng(seed)
    c = np.asarray(centre, float)
    p = rng.uniform(np.maximum(c - half, lo), np.minimum(c + half, hi), (points, 3))
    base = OffsetFieldWarp(lo, hi, u)
    _, grad = base._interpolate(p, gradient=True)
    max_grad = float(np.max(np.abs(grad)))
    rows: list[dict[str, Any]] = []
    variants = [("approx", 1)] + [("exact", int(k)) for k in iterations]
    variants += [("baked", int(k)) for k in baked_iterations]
    for mode, k in variants:
        w = OffsetFieldWarp(lo, hi, u, inverse=mode, iterations=max(k, 1))
        if mode == "baked" and k == 0:
            q = p - w._interpolate(p, field=w.baked_inverse())
        else:
            q = w.apply(p)
        err = np.linalg.norm(w.field_forward(q) - p, axis=1)
        rows.append(
            {
                "inverse": mode,
                "iterations": k,
                "max": float(err.max()),
                "mean": float(err.mean()),
                "max_grad": max_grad,
            }
        )
    return rows


def format_error_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """Markdown table of :func:`inverse_error_table` rows (residuals / node spacing)."""
    lines = ["| inverse | max / h | mean / h |", "|---|---|---|"]
    for r in rows:
        name = "approx" if r["inverse"] == "approx" else f"{r['inverse']} k={r['iterations']}"
        lines.append(f"| {name} | {r['max']:.3g} | {r['mean']:.3g} |")
    return "\n".join(lines)


__all__ = ["format_error_table", "gaussian_drag_field", "inverse_error_table"]


if __name__ == "__main__":
    print(format_error_table(inverse_error_table()))
