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
        shown = ", ".join(f"{v:.6g}" for v in size)
        raise FieldError(
            f"{where}: grid size [{shown}] must be positive whole numbers; fix FixedParameters"
        )
    return [int(v) for v in size]


#: Linear ITK transforms voxwarp reads from text files -> (Parameters count, accepted
#: FixedParameters counts) in 3-D. ITK trusts these counts: a short Parameters line
#: corrupted its heap (found by tests/fuzz/test_fuzz_readers.py).
LINEAR_COUNTS: dict[str, tuple[int, tuple[int, ...]]] = {
    "AffineTransform": (12, (3,)),
    "MatrixOffsetTransformBase": (12, (3,)),
    "Euler3DTransform": (6, (3, 4)),
    "VersorRigid3DTransform": (6, (3,)),
    "VersorTransform": (3, (3,)),
    "QuaternionRigidTransform": (7, (3,)),
    "Similarity3DTransform": (7, (3,)),
    "ScaleSkewVersor3DTransform": (15, (3,)),
    "ScaleVersor3DTransform": (9, (3,)),
    "ComposeScaleSkewVersor3DTransform": (12, (3,)),
    "ScaleTransform": (3, (3,)),
    "ScaleLogarithmicTransform": (3, (3,)),
    "TranslationTransform": (3, (0,)),
    "IdentityTransform": (0, (0,)),
}


def _base_and_dim(name: str, where: str) -> str:
    """The transform's class name without ``_double_3_3``; one line unless 3-D."""
    dims = _DIM.search(name)
    base = _DIM.sub("", name)
    for precision in ("_double", "_float"):
        base = base.removesuffix(precision)
    if dims and dims.groups() != ("3", "3"):
        raise FieldError(f"{where} is {dims[1]}-D; voxwarp reads 3-D transforms only")
    return base


def check_linear(base: str, params: list[float], n_fixed: int, where: str) -> None:
    """Refuse a linear transform whose Parameters/FixedParameters counts differ from
    :data:`LINEAR_COUNTS`, or whose Parameters are not finite."""
    n_params, fixed_counts = LINEAR_COUNTS[base]
    if len(params) != n_params or n_fixed not in fixed_counts:
        raise FieldError(
            f"{where}: {len(params)} Parameters and {n_fixed} FixedParameters; a {base} has"
            f" {n_params} and {' or '.join(map(str, fixed_counts))}: the file is damaged"
        )
    if not all(math.isfinite(v) for v in params):
        raise FieldError(f"{where}: its Parameters hold NaN or infinity; the file is damaged")


def check_block(name: str, params: str | None, fixed: str | None, where: str) -> None:
    """Check one transform of a text file (its name and raw Parameters/FixedParameters
    values) before ITK builds it; composites hold no numbers of their own."""
    base = _base_and_dim(name, where)
    if base == "CompositeTransform":
        return
    if params is None or fixed is None:
        raise FieldError(f"{where} lacks its Parameters or FixedParameters line; it is damaged")
    fixed_values = _numbers(fixed, f"{where} FixedParameters")
    if base in GRID_TRANSFORMS:
        check_grid(base, fixed_values, len(params.split()), where)
    elif base in LINEAR_COUNTS:
        check_linear(base, _numbers(params, f"{where} Parameters"), len(fixed_values), where)
    else:
        raise FieldError(
            f"{where}: voxwarp reads these ITK transforms from text files: linear ones"
            f" ({', '.join(sorted(LINEAR_COUNTS))}), BSplineTransform and"
            " DisplacementFieldTransform; convert it to an AffineTransform or a"
            " displacement field"
        )


def check_grid(base: str, fixed: list[float], n_params: int | None, where: str) -> None:
    """Refuse a grid transform ``base`` whose FixedParameters imply a grid over the
    memory budget, or whose Parameters count (``n_params``) does not fit the grid."""
    dim = 3
    size = _grid(fixed, dim, where)
    nodes = math.prod(size)
    shown = "x".join(f"{v:.6g}" for v in size)
    if nodes.bit_length() > 64:
        raise FieldError(f"{where}: its {base} grid of {shown} nodes is over 2^64; it is damaged")
    over = _limits.over_budget((nodes, dim), COEFFICIENT_BYTES)
    if over is not None:
        raise FieldError(
            f"{where}: its {base} grid of {shown} nodes needs {over[0]}"
            f" of coefficients, over the memory budget of {over[1]}; the file is damaged or"
            " not meant for this machine (raise --memory-budget SIZE only if it is genuine)"
        )
    if n_params is not None and n_params != nodes * dim:
        raise FieldError(
            f"{where}: Parameters holds {n_params:,} numbers but its {base} grid of"
            f" {shown} nodes needs {nodes * dim:,}; the file is damaged"
        )


def check_transform_text(path: Path) -> None:
    """Check every transform of the ITK text file ``path`` (``#Insight Transform File``)
    with :func:`check_block` before SimpleITK reads it; non-text files are left alone."""
    with open(path, "rb") as fh:
        head = fh.read(64)
    if not head.lstrip().startswith(b"#Insight Transform File"):
        return
    blocks: list[dict[str, str]] = []
    for raw in path.read_bytes().decode("ascii", "replace").splitlines():
        key, sep, value = raw.partition(":")
        key = key.strip()
        if sep and key == "Transform":
            blocks.append({"name": value.strip()})
        elif sep and key in ("Parameters", "FixedParameters") and blocks:
            blocks[-1][key] = value
    for block in blocks:
        name = block["name"]
        check_block(
            name, block.get("Parameters"), block.get("FixedParameters"), f"{path.name} ({name})"
        )
