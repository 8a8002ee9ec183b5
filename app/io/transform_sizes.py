"""Sizes an ITK transform file implies, checked before SimpleITK allocates them.

ITK reads a ``.tfm``/``.txt`` transform by allocating what its ``FixedParameters``
say: a B-spline or displacement-field transform's grid of ``size`` nodes, 3 float64
coefficients each. A 150-byte file claiming a 100000³ grid made ITK abort the whole
process (SIGABRT, nothing printed). :func:`check_transform_text` parses those numbers
itself and refuses, with an estimate, a grid over the memory budget, a grid whose
``Parameters`` count does not match, and sizes that are not positive integers.
ITK ``.h5`` and ``.mat`` files are binary and are left to the size check of the file.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from voxwarp.core import limits as _limits
from voxwarp.errors import FieldError

#: Transforms whose FixedParameters start with a grid size (ITK's layout: size,
#: origin, spacing, direction).
GRID_TRANSFORMS = ("BSplineTransform", "DisplacementFieldTransform")
#: Bytes per coefficient ITK allocates (double).
COEFFICIENT_BYTES = 8
_DIM = re.compile(r"_(\d)_(\d)$")


def _numbers(value: str, what: str) -> list[float]:
    try:
        out = [float(v) for v in value.split()]
    except ValueError as exc:
        raise FieldError(f"{what}: {exc}; write numbers only") from exc
    if not all(math.isfinite(v) for v in out):
        raise FieldError(f"{what} holds NaN or infinity; write finite numbers")
    return out


def _grid(fixed: list[float], dim: int, where: str) -> list[int]:
    """The node counts at the head of a grid transform's FixedParameters."""
    if len(fixed) < dim * (3 + dim):
        raise FieldError(
            f"{where}: FixedParameters has {len(fixed)} numbers; a {dim}-D grid transform"
            f" has {dim * (3 + dim)} (size, origin, spacing, direction)"
        )
    size = fixed[:dim]
    if not all(v >= 1 and v == int(v) for v in size):
        raise FieldError(
            f"{where}: grid size {size} must be positive whole numbers; fix FixedParameters"
        )
    return [int(v) for v in size]


def check_grid(name: str, fixed: list[float], n_params: int | None, where: str) -> None:
    """Refuse a grid transform ``name`` whose FixedParameters imply a grid over the
    memory budget, or whose Parameters count (``n_params``) does not fit the grid."""
    base, dims = _DIM.sub("", name.split("_double")[0].split("_float")[0]), _DIM.search(name)
    if base not in GRID_TRANSFORMS:
        return
    dim = int(dims.group(1)) if dims else 3
    size = _grid(fixed, dim, where)
    nodes = math.prod(size)
    over = _limits.over_budget((nodes, dim), COEFFICIENT_BYTES)
    if over is not None:
        raise FieldError(
            f"{where}: its {base} grid of {'x'.join(map(str, size))} nodes needs {over[0]}"
            f" of coefficients, over the memory budget of {over[1]}; the file is damaged or"
            " not meant for this machine (raise --memory-budget SIZE only if it is genuine)"
        )
    if n_params is not None and n_params != nodes * dim:
        raise FieldError(
            f"{where}: Parameters holds {n_params:,} numbers but its {base} grid of"
            f" {'x'.join(map(str, size))} nodes needs {nodes * dim:,}; the file is damaged"
        )


def check_transform_text(path: Path) -> None:
    """Check every transform of the ITK text file ``path`` (``#Insight Transform File``)
    with :func:`check_grid` before SimpleITK reads it; non-text files are left alone."""
    with open(path, "rb") as fh:
        head = fh.read(64)
    if not head.lstrip().startswith(b"#Insight Transform File"):
        return
    text = path.read_bytes().decode("ascii", "replace")
    name, params = "", None
    for raw in text.splitlines():
        key, sep, value = raw.partition(":")
        key = key.strip()
        if not sep:
            continue
        if key == "Transform":
            name, params = value.strip(), None
        elif key == "Parameters":
            params = len(value.split())
        elif key == "FixedParameters" and name:
            where = f"{path.name} ({name})"
            check_grid(name, _numbers(value, f"{where} FixedParameters"), params, where)
