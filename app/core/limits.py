"""Limits on every number that sizes an allocation or a loop, in one place.

A number read from a file, a scene JSON or the command line can ask for far more memory
or time than the machine has (a sample ``shape`` of 3000³ is 101 GiB; ``--relax
100000000`` runs for days). Each such number has a documented limit here
(docs/reference/limits.md lists them), checked **before** anything is allocated or
looped, and a value over it raises a one-line :class:`voxwarp.errors.VoxwarpError`
naming the value, the limit and the fix.

The limits of the lower layers live with their code (those layers cannot import this
one): the sample phantoms' ``MAX_SAMPLE_VOXELS`` and ``MAX_SAMPLE_AXIS`` in
:mod:`voxwarp.sample_volumes.generators`, the wires' ``MAX_WIRE_POINTS``,
``MAX_FIELD_VOXELS``, ``MAX_MASK_PIXELS`` and ``MAX_REACH_DIAGONALS`` in
:mod:`voxwarp.deform.wires.constants`, and the element grid's ``MAX_ELEMENTS_PER_AXIS`` in
:mod:`voxwarp.deform.elements.grid`.

Loading a volume is bounded by a **memory budget**: by default
:data:`DEFAULT_MEMORY_FRACTION` of the physical memory, else what
``load_volume(..., memory_budget=...)`` or ``--memory-budget`` says. Each reader checks
the voxel bytes its header states against the budget before it reads them
(:func:`check_load_bytes`).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

from voxwarp.errors import VolumeError

#: Most triangles a mesh generator (``box_mesh_tessellated``, ``uv_sphere``, ...) makes.
MAX_MESH_TRIANGLES = 1 << 21
#: Most ``--relax`` steps of ``render --chainmail`` (each smooths the whole grid).
MAX_RELAX_STEPS = 1000
#: Most time steps ``render --massspring`` runs (``--steps``, also the ``--settle`` cap).
MAX_MASSSPRING_STEPS = 100_000
#: Largest ``--drag`` offset (mm): the range of the half-float displacement texture
#: (equal to :data:`voxwarp.deform.node_grid.MAX_DISPLACEMENT_MM`).
MAX_DRAG_MM = 60000.0
#: Range of a scene's ``zoom`` (1 frames the volume; > 1 magnifies).
MIN_ZOOM = 1e-3
MAX_ZOOM = 1e3
#: Range of a voxel or pixel size given on the command line (mm): below a nanometre or
#: above a kilometre no scan is meant, and such numbers overflow the grids they size.
MIN_SPACING_MM = 1e-6
MAX_SPACING_MM = 1e6
#: Default memory budget of loading a volume: this fraction of the physical memory.
DEFAULT_MEMORY_FRACTION = 0.5
#: The budget when the physical memory cannot be read (bytes).
FALLBACK_MEMORY_BUDGET = 4 << 30

_SIZE_UNITS = {"": 1, "B": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def physical_memory() -> int | None:
    """Bytes of physical memory (``os.sysconf``, else ``/proc/meminfo``), or ``None``."""
    try:
        pages, page_size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
        if pages > 0 and page_size > 0:
            return int(pages) * int(page_size)
    except (AttributeError, OSError, ValueError):
        pass
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemTotal:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def default_memory_budget() -> int:
    """:data:`DEFAULT_MEMORY_FRACTION` of the physical memory, in bytes."""
    total = physical_memory()
    if total is None:
        return FALLBACK_MEMORY_BUDGET
    return int(total * DEFAULT_MEMORY_FRACTION)


def format_bytes(n: float) -> str:
    """``n`` bytes as a short text with a binary unit (``"1.5 GiB"``)."""
    for unit, size in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{int(n)} bytes"


def parse_size(text: Any, what: str = "memory budget") -> float:
    """A byte count from ``"2G"``, ``"512M"``, ``"1.5T"``, ``"1000000"`` or a number;
    ``"unlimited"`` / ``math.inf`` means no limit. Raises :class:`VolumeError`."""
    if isinstance(text, bool):
        raise VolumeError(f"{what} must be a size such as 2G or 512M; got {text!r}.")
    if isinstance(text, int | float):
        value = float(text)
    elif isinstance(text, str) and text.strip().lower() in ("unlimited", "none", "inf"):
        return math.inf
    else:
        m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*([KMGT]?)(?:i?B)?\s*", str(text), re.IGNORECASE)
        if m is None:
            raise VolumeError(
                f"{what} must be a size such as 2G, 512M or a byte count; got {str(text)[:40]!r}."
            )
        value = float(m.group(1)) * _SIZE_UNITS[m.group(2).upper()]
    if math.isnan(value) or value <= 0:
        raise VolumeError(f"{what} must be a positive size such as 2G; got {text!r}.")
    return value


def size_arg(text: str) -> float:
    """argparse type of ``--memory-budget SIZE`` (``2G``, ``512M``, ``unlimited``)."""
    import argparse

    try:
        return parse_size(text, "--memory-budget")
    except VolumeError as exc:
        raise argparse.ArgumentTypeError(str(exc).rstrip(".")) from exc


def spacing_in_range(mm: float) -> bool:
    """Whether ``mm`` is a voxel size voxwarp takes: finite, in
    :data:`MIN_SPACING_MM`..:data:`MAX_SPACING_MM`."""
    return math.isfinite(mm) and MIN_SPACING_MM <= mm <= MAX_SPACING_MM


def spacing_mm(text: str, what: str = "--spacing") -> float:
    """argparse type of a voxel size in mm: finite, in
    :data:`MIN_SPACING_MM`..:data:`MAX_SPACING_MM`."""
    import argparse

    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not spacing_in_range(v):
        raise argparse.ArgumentTypeError(
            f"{what} {text!r}: a voxel size must be a number of mm from {MIN_SPACING_MM:g}"
            f" to {MAX_SPACING_MM:g}"
        )
    return v


#: The budget of the load in progress (set by :func:`memory_budget`; ``None``: unset).
_BUDGET: ContextVar[float | None] = ContextVar("voxwarp_memory_budget", default=None)
#: The process-wide budget (:func:`set_memory_budget`, e.g. from ``--memory-budget``).
_PROCESS_BUDGET: list[float | None] = [None]


def set_memory_budget(budget: Any) -> None:
    """Make ``budget`` (bytes or a size text; ``None``: back to the default) the memory
    budget of every later load in this process (the command line's ``--memory-budget``)."""
    _PROCESS_BUDGET[0] = None if budget is None else parse_size(budget)


@contextmanager
def memory_budget(budget: Any) -> Iterator[float]:
    """Make ``budget`` (bytes or a size text) the memory budget of the readers while the
    block runs; ``None`` keeps the budget in force. Yields it in bytes."""
    value = current_memory_budget() if budget is None else parse_size(budget)
    token = _BUDGET.set(value)
    try:
        yield value
    finally:
        _BUDGET.reset(token)


def current_memory_budget() -> float:
    """The memory budget readers check against now (bytes): the one a
    :func:`memory_budget` block sets, else :func:`set_memory_budget`'s, else
    :func:`default_memory_budget`."""
    for value in (_BUDGET.get(), _PROCESS_BUDGET[0]):
        if value is not None:
            return value
    return float(default_memory_budget())


def over_budget(shape: Sequence[int], itemsize: int) -> tuple[str, str] | None:
    """``(need, budget)`` as text when ``shape`` items of ``itemsize`` bytes exceed the
    memory budget, else ``None``; the caller words the error."""
    count = 1
    for n in shape:
        count *= max(int(n), 0)
    need = count * int(itemsize)
    budget = current_memory_budget()
    return (format_bytes(need), format_bytes(budget)) if need > budget else None


def check_load_bytes(shape: Sequence[int], itemsize: int, what: str) -> None:
    """Raise :class:`VolumeError` if voxels of ``shape`` and ``itemsize`` bytes each would
    exceed the memory budget; call it before reading them."""
    over = over_budget(shape, itemsize)
    if over is not None:
        dims = "x".join(str(int(n)) for n in shape)
        raise VolumeError(
            f"{what}: {dims} voxels need {over[0]}, over the memory budget of"
            f" {over[1]}; raise it with --memory-budget SIZE (load_volume(...,"
            " memory_budget=...)) if the machine has the memory, or crop the file first."
        )
