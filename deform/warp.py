"""Warps: the one interface between deformation models and the raycaster.

About this technique
--------------------
A *warp* maps a point ``p`` of the deformed (displayed) space to the point ``q`` of
the original volume whose value is seen at ``p``: the raycaster marches its rays in
deformed space and samples the unchanged volume texture at ``warp(p)``, so the volume
is never resampled. On the GPU a warp is a GLSL file defining

.. code-block:: glsl

    vec3 warp(vec3 p);            // deformed world (mm) -> original world (mm)
    mat3 warp_jacobian(vec3 p);   // d warp / d p
    mat3 warp_jacobian_at(vec3 p, vec3 q);   // optional: d warp / d p given q = warp(p)

plus its uniforms and textures. Shading normals are carried into deformed space by
the Jacobian: for ``f_def(p) = f(warp(p))``, ``grad f_def = J^T grad f``.

A scene holds a *chain* of warps ``[w0, w1, ...]`` applied in order,
``q = ... w1(w0(p))`` — nested deformations compose like scene-graph transforms.
Uniform names in a warp's GLSL file carry the prefix ``WARP_``; :func:`compose_glsl`
renames ``WARP_`` to ``w{i}_`` and ``warp``/``warp_jacobian``/``warp_jacobian_at`` to
``w{i}_warp``/``w{i}_warp_jacobian``/``w{i}_warp_jacobian_at`` for the i-th warp, so two
warps of one kind never clash.

Each warp also has a CPU reference (:meth:`Warp.apply`, :meth:`Warp.jacobian`) used by
tests, picking and bounds computation.
"""

from __future__ import annotations

import importlib
import math
import re
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from voxwarp import shaders
from voxwarp.errors import VoxwarpError


class WarpError(VoxwarpError, ValueError):
    """A warp was given invalid parameters (message names the fix)."""


class ForwardMapError(WarpError):
    """A forward map found no solution at some points (the warp folds or tears there).

    Attributes
    ----------
    points : numpy.ndarray
        The best estimates (N, 3) at every point, solved or not.
    failed : numpy.ndarray
        (N,) bool: the points whose residual stayed above the tolerance.
    """

    def __init__(self, message: str, points: np.ndarray, failed: np.ndarray) -> None:
        super().__init__(message)
        self.points = points
        self.failed = failed


#: A chain that moves a point farther than this (mm) does not carry it (see
#: :func:`chain_apply_carried`): beyond a half float, as ``node_grid``'s limit; vacated
#: points go farther.
FAR_MM = 6.0e4

_REGISTRY: dict[str, type[Warp]] = {}
#: the warp kinds voxwarp ships and the modules that register them: loaded when a scene
#: names one, so that reading a warp entry never depends on what was imported before
_BUILT_IN: dict[str, str] = {
    "offset_field": "voxwarp.deform.elements.offset_field",
    "wires": "voxwarp.deform.wires.warp",
    "lattice": "voxwarp.deform.lattice.warp",
    "displacement_field": "voxwarp.deform.fields.displacement",
}


def _load_built_in(kind: str) -> None:
    module = _BUILT_IN.get(kind)
    if module is not None and kind not in _REGISTRY:
        importlib.import_module(module)


def register_warp(cls: type[Warp]) -> type[Warp]:
    """Class decorator: make a warp kind loadable by :func:`warp_from_dict`."""
    _REGISTRY[cls.kind] = cls
    return cls


def warp_class(d: Mapping[str, Any]) -> type[Warp]:
    """The warp class a scene-JSON warp entry names (loading a built-in kind's module)."""
    if not isinstance(d, Mapping) or "type" not in d:
        raise WarpError(f"a warp entry must be an object with a 'type' key; got {d!r:.80}")
    kind = d["type"]
    if isinstance(kind, str):
        _load_built_in(kind)
    if not isinstance(kind, str) or kind not in _REGISTRY:
        raise WarpError(f"unknown warp type {kind!r}; known types: {known_warps()}")
    return _REGISTRY[kind]


def warp_from_dict(d: Mapping[str, Any]) -> Warp:
    """Rebuild a warp from its :meth:`Warp.to_dict` form (scene JSON)."""
    return warp_class(d).from_dict(d)


def known_warps() -> list[str]:
    """Names of the warp kinds :func:`warp_from_dict` reads (built-in and registered)."""
    return sorted({*_REGISTRY, *_BUILT_IN})


class Warp(ABC):
    """Base class of all warps (see the module docstring)."""

    #: registry name, used in scene JSON
    kind: ClassVar[str] = ""
    #: GLSL file in :mod:`shaders` defining ``warp`` and ``warp_jacobian``
    glsl_file: ClassVar[str] = ""

    # ---------------------------------------------------------------- CPU side
    @abstractmethod
    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map deformed-space points (N, 3) in mm to original-space points (N, 3)."""

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """Jacobians (N, 3, 3) of :meth:`apply`; default by central differences."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        out = np.empty((p.shape[0], 3, 3))
        for a in range(3):
            e = np.zeros(3)
            e[a] = eps
            out[:, :, a] = (self.apply(p + e) - self.apply(p - e)) / (2 * eps)
        return out

    #: Tolerance (mm) of the numerical forward map of :meth:`forward`: the residual
    #: ``|apply(forward(x)) - x|`` it iterates down to.
    forward_tolerance: ClassVar[float] = 1e-4
    #: Newton steps :meth:`forward` takes at most.
    forward_steps: ClassVar[int] = 30
    #: Scene-JSON keys of :meth:`to_dict` whose values are file paths: a scene stores them
    #: relative to its own folder and resolves them before :meth:`from_dict`.
    file_keys: ClassVar[tuple[str, ...]] = ()

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original -> deformed: the point ``p`` with ``apply(p) = x``, for (N, 3) points.

        This moves meshes and handles with the volume (the raycaster needs only
        :meth:`apply`). The default solves ``apply(p) = x`` by Newton steps with
        :meth:`jacobian`, from ``p_0 = 2 x - apply(x)``, until the residual is below
        :attr:`forward_tolerance` mm; families with a closed form override it. A point
        that does not converge (the warp folds there) raises :class:`WarpError`
        naming how many points failed and the largest residual.
        """
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return solve_forward(self, x, 2.0 * x - self.apply(x))

    @property
    def is_affine(self) -> bool:
        """True when the warp is an affine map (the raycaster then folds it into the ray)."""
        return False

    @property
    def bounds_displacement(self) -> bool:
        """True when :meth:`displacement_range` gives intervals (cheap to ask; the
        base class gives none)."""
        return False

    @property
    def revision(self) -> int:
        """Counter that changes whenever the warp's mapping changes in place (e.g. an
        offset field's :meth:`update`); caches of derived data (skip maps) key on it."""
        return 0

    def affine_matrix(self) -> np.ndarray:
        """4x4 matrix of the warp (deformed -> original) when :attr:`is_affine`."""
        raise WarpError(f"{type(self).__name__} is not affine")

    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Box in deformed space that contains every point mapped into [lo, hi].

        The raycaster marches only inside this box. The default assumes the warp moves
        nothing outside the original box.
        """
        return np.asarray(lo, float), np.asarray(hi, float)

    def displacement_range(
        self, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Per box and axis, an interval ``[a, b]`` holding ``apply(p) - p`` for p in the box.

        Parameters
        ----------
        lo, hi
            (N, 3) corners of N axis-aligned boxes in deformed space (mm).

        Returns
        -------
        (a, b) or None
            Two (N, 3) arrays (mm), ``a <= apply(p) - p <= b`` componentwise for every p
            in box i; ``None`` when the warp cannot bound its displacement (the
            default). The raycaster uses them to carry empty-space skipping into
            deformed space: a deformed-space point samples original content only
            within that interval of offsets (see
            :func:`voxwarp.render.skipping.maps.warped_cell_visibility`). Signed intervals matter: a
            smooth field moves a region mostly one way, so the content a sample can
            reach is a shifted window, not a ball.
        """
        return None

    def support_bricks(self, lo: np.ndarray, hi: np.ndarray, tol: float) -> np.ndarray:
        """Which of N deformed-space boxes the warp may move a point of by more than
        ``tol`` mm (per axis): an (N,) bool mask, its *support* in bricks.

        ``lo``, ``hi``: (N, 3) box corners (mm). The default marks a box unless its
        :meth:`displacement_range` lies within ``[-tol, tol]``, and every box when the
        warp gives no interval; a family with a tighter answer (an offset field's moved
        cells) overrides it. Points outside the marked boxes sample the volume where a
        straight ray does (within ``tol``), so the raycaster marches straight there
        (:func:`voxwarp.deform.support.chain_support`).
        """
        n = np.atleast_2d(lo).shape[0]
        r = self.displacement_range(lo, hi)
        if r is None:
            return np.ones(n, dtype=bool)
        reach = np.maximum(np.abs(np.asarray(r[0], float)), np.abs(np.asarray(r[1], float)))
        return np.asarray(reach.max(axis=1) > tol)

    def carried(self, points: np.ndarray) -> np.ndarray | None:
        """Which of the (N, 3) deformed points the warp maps to content: an (N,) bool
        mask, or ``None`` when it carries every point (the default).

        A point it does not carry shows nothing (a rigid wire's vacated space);
        :func:`chain_apply_carried` gathers the masks of a chain, and exporters mark
        those points instead of writing the value :meth:`apply` gives there.
        """
        return None

    def apply_carried(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """:meth:`apply` and :meth:`carried` of the same (N, 3) points at once.

        The default calls both; a warp whose two share work (a wire's field lookup)
        overrides it so that :func:`chain_apply_carried` (field exports) does it once.
        """
        return self.apply(points), self.carried(points)

    def export_resolution(self) -> float | None:
        """The finest length (mm) on which the map's derivative changes, for a field
        export's default node spacing (``voxwarp export-field``): an element or
        control-point spacing; ``math.inf`` for a map trilinear interpolation holds at
        any spacing (affine); ``None`` (the default) when the map has detail down to the
        volume's voxels (wires, imported fields): the export keeps the voxel grid."""
        return None

    # ---------------------------------------------------------------- GPU side
    def uniforms(self) -> dict[str, Any]:
        """Uniform values by unprefixed name (``WARP_name`` in GLSL -> ``name``)."""
        return {}

    def glsl_constants(self) -> dict[str, Any]:
        """Compile-time constants by unprefixed name (``const`` ``WARP_NAME`` in GLSL).

        ``int``, ``float`` or ``bool`` values become ``const`` declarations; a ``str``
        becomes a macro (``#define WARP_NAME text``, e.g. an unrolled loop body).
        :meth:`signature` must change with them (programs are cached per signature).
        """
        return {}

    def textures(self, ctx: Any) -> dict[str, Any]:
        """moderngl textures by unprefixed sampler name; created on first use on ``ctx``."""
        return {}

    def release(self) -> None:  # noqa: B027 - optional hook
        """Free GPU resources; idempotent."""

    def release_context(self, ctx: Any) -> None:  # noqa: B027 - optional hook
        """Free what :meth:`textures` keeps on ``ctx`` alone (``ctx`` current) and forget
        it, so a later use uploads again; idempotent. A warp that caches GL objects per
        context overrides it and registers with :func:`voxwarp.deform.gl_holders.hold`,
        so the pooled context's last renderer frees them when it closes."""

    def bind_volume(self, volume: Any) -> None:  # noqa: B027 - optional hook
        """Give the warp the original volume it deforms (called by scene loading).

        Warps whose GPU data derive from the volume's values (the wire field classifies
        objects by value) build them here; the others ignore it.
        """

    def signature(self) -> str:
        """Identifies the GLSL variant (programs are cached per chain signature)."""
        return self.kind

    # ---------------------------------------------------------------- serialisation
    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description, with ``"type": kind``."""

    @classmethod
    @abstractmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Warp:
        """Inverse of :meth:`to_dict`."""


@register_warp
class IdentityWarp(Warp):
    """The identity map: ``warp(p) = p``. Used as an oracle in tests."""

    kind = "identity"
    glsl_file = "warp_identity.glsl"

    def export_resolution(self) -> float:
        """Infinite: the identity needs no nodes between the box's."""
        return math.inf

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Return the points unchanged (as float64 (N, 3))."""
        return np.atleast_2d(np.asarray(points, dtype=np.float64)).copy()

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Return the points unchanged."""
        return self.apply(points)

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """Identity matrices."""
        n = np.atleast_2d(points).shape[0]
        return np.broadcast_to(np.eye(3), (n, 3, 3)).copy()

    @property
    def is_affine(self) -> bool:
        """Always True."""
        return True

    def affine_matrix(self) -> np.ndarray:
        """The 4x4 identity."""
        return np.eye(4)

    @property
    def bounds_displacement(self) -> bool:
        """Always True."""
        return True

    def displacement_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[0, 0]``: the identity moves nothing."""
        z = np.zeros((np.atleast_2d(lo).shape[0], 3))
        return z, z.copy()

    def to_dict(self) -> dict[str, Any]:
        """``{"type": "identity"}``."""
        return {"type": self.kind}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> IdentityWarp:
        """Build from ``{"type": "identity"}``."""
        return cls()


def _as_matrix4(m: Any, what: str) -> np.ndarray:
    try:
        a = np.asarray(m, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise WarpError(f"{what} must be a 4x4 (or 3x4) matrix of numbers") from exc
    if a.shape == (3, 4):
        a = np.vstack([a, [0, 0, 0, 1]])
    if a.shape != (4, 4):
        raise WarpError(f"{what} must be a 4x4 (or 3x4) matrix; got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise WarpError(f"{what} has NaN/Inf entries")
    if not np.allclose(a[3], [0, 0, 0, 1]):
        raise WarpError(f"{what}: the last row must be (0, 0, 0, 1) for an affine map")
    if abs(np.linalg.det(a[:3, :3])) < 1e-12:
        raise WarpError(f"{what} is singular (determinant 0); an affine warp must be invertible")
    return a


@register_warp
class AffineWarp(Warp):
    """An affine deformation given by a 4x4 matrix.

    Parameters
    ----------
    matrix
        The *forward* transform, original -> deformed, in world mm: the object appears
        moved by this matrix. The GLSL warp applies its inverse (deformed -> original).

    Attributes
    ----------
    forward_matrix, inverse : numpy.ndarray
        The 4x4 forward (original -> deformed) matrix and its inverse.
    """

    kind = "affine"
    glsl_file = "warp_affine.glsl"

    def __init__(self, matrix: Any) -> None:
        self.forward_matrix = _as_matrix4(matrix, "AffineWarp matrix")
        self.inverse = np.linalg.inv(self.forward_matrix)

    @classmethod
    def translation(cls, offset: Sequence[float]) -> AffineWarp:
        """Move the object by ``offset`` (mm)."""
        m = np.eye(4)
        m[:3, 3] = np.asarray(offset, float).reshape(3)
        return cls(m)

    @classmethod
    def scaling(
        cls, factors: float | Sequence[float], center: Sequence[float] = (0, 0, 0)
    ) -> AffineWarp:
        """Scale the object by ``factors`` (one or three) about ``center``."""
        f = np.broadcast_to(np.asarray(factors, float), (3,))
        return cls(_about(np.diag([*f, 1.0]), center))

    @classmethod
    def rotation(
        cls, axis: Sequence[float], degrees: float, center: Sequence[float] = (0, 0, 0)
    ) -> AffineWarp:
        """Rotate the object by ``degrees`` about ``axis`` through ``center`` (right-handed)."""
        r = rotation_matrix(axis, degrees)
        m = np.eye(4)
        m[:3, :3] = r
        return cls(_about(m, center))

    def export_resolution(self) -> float:
        """Infinite: trilinear interpolation reproduces an affine map at any spacing."""
        return math.inf

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Deformed -> original: the inverse matrix applied to (N, 3) points."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return p @ self.inverse[:3, :3].T + self.inverse[:3, 3]

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original -> deformed: the forward matrix applied to (N, 3) points."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return p @ self.forward_matrix[:3, :3].T + self.forward_matrix[:3, 3]

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """The constant linear part of the inverse."""
        n = np.atleast_2d(points).shape[0]
        return np.broadcast_to(self.inverse[:3, :3], (n, 3, 3)).copy()

    @property
    def is_affine(self) -> bool:
        """Always True."""
        return True

    def affine_matrix(self) -> np.ndarray:
        """The deformed -> original matrix (inverse of the forward matrix)."""
        return self.inverse.copy()

    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Box around the forward image of the 8 corners of [lo, hi]."""
        c = box_corners(lo, hi)
        f = c @ self.forward_matrix[:3, :3].T + self.forward_matrix[:3, 3]
        return f.min(axis=0), f.max(axis=0)

    @property
    def bounds_displacement(self) -> bool:
        """Always True."""
        return True

    def displacement_range(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact: ``(A p + t - p)_i`` is linear in p, so its extremes over a box lie at
        corners; per axis, the smallest and largest of the 8 corners' offsets."""
        lo, hi = np.atleast_2d(lo).astype(float), np.atleast_2d(hi).astype(float)
        m = self.inverse[:3, :3] - np.eye(3)
        a = np.full(lo.shape, np.inf)
        b = np.full(lo.shape, -np.inf)
        for corner in range(8):
            pick = np.array([(corner >> k) & 1 for k in range(3)], dtype=bool)
            d = np.where(pick, hi, lo) @ m.T + self.inverse[:3, 3]
            np.minimum(a, d, out=a)
            np.maximum(b, d, out=b)
        return a, b

    def uniforms(self) -> dict[str, Any]:
        """``matrix``: the deformed -> original 4x4 matrix (column-major for GL)."""
        return {"matrix": self.inverse}

    def to_dict(self) -> dict[str, Any]:
        """``{"type": "affine", "matrix": 4x4 nested list}`` (forward matrix)."""
        return {"type": self.kind, "matrix": self.forward_matrix.tolist()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> AffineWarp:
        """Build from ``{"type": "affine", "matrix": [[...], ...]}``."""
        if "matrix" not in d:
            raise WarpError("an affine warp entry needs a 'matrix' (4x4 nested list)")
        return cls(d["matrix"])


def rotation_matrix(axis: Sequence[float], degrees: float) -> np.ndarray:
    """3x3 right-handed rotation by ``degrees`` about ``axis`` (Rodrigues' formula)."""
    a = np.asarray(axis, float).reshape(3)
    n = np.linalg.norm(a)
    if n == 0:
        raise WarpError("rotation axis must be non-zero")
    x, y, z = a / n
    t = np.radians(degrees)
    c, s, cc = np.cos(t), np.sin(t), 1 - np.cos(t)
    return np.array(
        [
            [c + x * x * cc, x * y * cc - z * s, x * z * cc + y * s],
            [y * x * cc + z * s, c + y * y * cc, y * z * cc - x * s],
            [z * x * cc - y * s, z * y * cc + x * s, c + z * z * cc],
        ]
    )


def _about(m: np.ndarray, center: Sequence[float]) -> np.ndarray:
    c = np.asarray(center, float).reshape(3)
    t1, t2 = np.eye(4), np.eye(4)
    t1[:3, 3] = -c
    t2[:3, 3] = c
    return t2 @ m @ t1


def box_corners(lo: Sequence[float], hi: Sequence[float]) -> np.ndarray:
    """The 8 corners (8, 3) of the axis-aligned box [lo, hi]."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    idx = np.array([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=float)
    return lo + idx * (hi - lo)


def solve_forward(warp: Warp, x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The points ``p`` with ``warp.apply(p) = x`` by Newton steps with
    :meth:`Warp.jacobian` from the seed ``p`` ((N, 3), updated in place), at most
    :attr:`Warp.forward_steps`, then :func:`check_forward` (a :class:`ForwardMapError`
    for points left above :attr:`Warp.forward_tolerance`)."""
    for _ in range(warp.forward_steps):
        r = warp.apply(p) - x
        bad = ~(np.linalg.norm(r, axis=1) <= warp.forward_tolerance)
        if not np.any(bad):
            return p
        j = warp.jacobian(p[bad])
        ok = np.abs(np.linalg.det(j)) > 1e-12
        step = np.zeros((int(bad.sum()), 3))
        step[ok] = np.linalg.solve(j[ok], r[bad][ok][..., None])[..., 0]
        step[~ok] = r[bad][~ok]
        p[bad] -= step
    return check_forward(warp, p, x)


def check_forward(warp: Warp, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Return ``p`` if ``warp.apply(p)`` is within the warp's forward tolerance of ``x``;
    otherwise raise :class:`ForwardMapError` saying where the forward map failed (it
    carries the estimates, for :func:`chain_forward_lenient`)."""
    err = np.linalg.norm(warp.apply(p) - x, axis=1)
    bad = ~(err <= warp.forward_tolerance)
    if np.any(bad):
        worst = int(np.nanargmax(np.where(np.isfinite(err), err, np.inf)))
        p = np.where(np.isfinite(p), p, x)  # an estimate everywhere, for lenient callers
        raise ForwardMapError(
            f"the {warp.kind} warp has no forward map at {int(bad.sum())} of {len(x)} points"
            f" (largest residual {float(err[worst]):.3g} mm at"
            f" {np.round(x[worst], 2).tolist()}): the deformation folds or tears there (e.g."
            " at the edge of a displacement field's grid); smooth it or keep meshes out of"
            " that region",
            p,
            bad,
        )
    return p


def chain_forward(warps: Sequence[Warp], points: np.ndarray) -> np.ndarray:
    """Original -> deformed through a chain: the forward maps, last warp first.

    The inverse of :func:`chain_apply`: ``chain_apply(warps, chain_forward(warps, x))``
    is ``x`` within the warps' forward tolerances. Meshes and handles follow the volume
    through it. Raises :class:`ForwardMapError` where a warp has no forward map; see
    :func:`chain_forward_lenient` to keep the best estimates instead.
    """
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))
    for w in reversed(list(warps)):
        p = w.forward(p)
    return p


def chain_forward_lenient(
    warps: Sequence[Warp], points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, str]:
    """:func:`chain_forward` that keeps going where a warp has no forward map.

    Returns the moved points (the best estimates where unsolved), an (N,) bool mask of
    the points some warp could not solve, and the first failure's one-line message
    (empty when every point was solved). A mesh vertex at a displacement field's edge,
    where ITK's field stops, is the common case.
    """
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))
    failed = np.zeros(len(p), dtype=bool)
    message = ""
    for w in reversed(list(warps)):
        try:
            p = w.forward(p)
        except ForwardMapError as exc:
            p, failed = exc.points, failed | exc.failed
            message = message or str(exc)
    return p, failed, message


def chain_jacobian(warps: Sequence[Warp], points: np.ndarray) -> np.ndarray:
    """Jacobians (N, 3, 3) of :func:`chain_apply` by the chain rule (deformed points)."""
    q = np.atleast_2d(np.asarray(points, dtype=np.float64))
    out = np.broadcast_to(np.eye(3), (len(q), 3, 3)).copy()
    for w in warps:
        out = w.jacobian(q) @ out
        q = w.apply(q)
    return out


def chain_apply(warps: Sequence[Warp], points: np.ndarray) -> np.ndarray:
    """CPU reference of a warp chain: ``q = w_{n-1}(... w_0(p))``."""
    q = np.atleast_2d(np.asarray(points, dtype=np.float64))
    for w in warps:
        q = w.apply(q)
    return q


def chain_apply_carried(warps: Sequence[Warp], points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`chain_apply` and an (N,) bool mask of the points the chain carries.

    A point is not carried when some warp's :meth:`Warp.carried` says so at the point
    that warp receives, or when the chain sends it to NaN or farther than :data:`FAR_MM`
    (where a vacated point is sent).
    """
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))
    q, ok = p, np.ones(len(p), dtype=bool)
    for w in warps:
        q, mask = w.apply_carried(q)
        if mask is not None:
            ok &= np.asarray(mask, dtype=bool)
    with np.errstate(invalid="ignore"):
        ok &= np.all(np.abs(q - p) < FAR_MM, axis=1)
    return q, ok


def chain_deformed_bounds(
    warps: Sequence[Warp], lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Deformed-space box of a chain: bounds pushed back through the warps, last first."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    for w in reversed(list(warps)):
        lo, hi = w.deformed_bounds(lo, hi)
    return lo, hi


def chain_displacement_range(
    warps: Sequence[Warp], lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Per box and axis, an interval holding how far a chain moves any point of the box.

    Warp ``i`` sees the box moved by the intervals of warps ``0 .. i-1`` (the points it
    receives lie there); the chain's interval is their sum. ``None`` when some warp
    gives no interval. ``lo``, ``hi``: (N, 3) box corners in deformed mm; returns two
    (N, 3) arrays ``(a, b)``.
    """
    lo, hi = np.atleast_2d(lo).astype(float), np.atleast_2d(hi).astype(float)
    a, b = np.zeros(lo.shape), np.zeros(lo.shape)
    for w in warps:
        r = w.displacement_range(lo + a, hi + b)
        if r is None:
            return None
        a, b = a + np.asarray(r[0], float), b + np.asarray(r[1], float)
    return a, b


def fold_affine(warps: Sequence[Warp]) -> np.ndarray | None:
    """One 4x4 deformed -> original matrix for an all-affine chain, else ``None``."""
    m = np.eye(4)
    for w in warps:
        if not w.is_affine:
            return None
        m = w.affine_matrix() @ m
    return m


_PREFIX = re.compile(r"\bWARP_")
#: a warp file without ``warp_jacobian_at(p, q)``: its Jacobian at p (q unused)
_DEFAULT_AT = "mat3 w{0}_warp_jacobian_at(vec3 p, vec3 q) {{ return w{0}_warp_jacobian(p); }}\n"
_FN = re.compile(r"\bwarp(_jacobian(?:_at)?)?\b(?=\s*\()")


def _constants_glsl(constants: Mapping[str, Any]) -> str:
    lines = []
    for name, value in constants.items():
        if isinstance(value, str):
            lines.append(f"#define WARP_{name} {value}")
        elif isinstance(value, bool | np.bool_):
            lines.append(f"const bool WARP_{name} = {'true' if value else 'false'};")
        elif isinstance(value, int | np.integer):
            lines.append(f"const int WARP_{name} = {int(value)};")
        elif isinstance(value, float | np.floating):
            lines.append(f"const float WARP_{name} = {float(value)!r};")
        else:
            raise WarpError(f"GLSL constant {name} must be bool, int, float or str; got {value!r}")
    return "".join(line + "\n" for line in lines)


def compose_glsl(warps: Sequence[Warp], loader: Callable[[str], str] = shaders.read) -> str:
    """GLSL text defining ``warp_chain(p)``, ``warp_chain_jacobian(p)``, both at once
    (``warp_chain_and_jacobian(p, out J)``) and ``warp_chain_kept_jacobian()``.

    Each warp's file is inserted with its names prefixed ``w{i}_``; the chain's
    Jacobian is the product ``J_{n-1}(q_{n-1}) ... J_0(p)`` (chain rule), each factor
    from ``w{i}_warp_jacobian_at(p_i, q_i)`` at the warp's input ``p_i`` and output
    ``q_i`` (a file may define ``warp_jacobian_at(p, q)``, the Jacobian given the
    warped point, to save warping again; otherwise it is ``warp_jacobian(p)``).
    ``warp_chain`` keeps each warp's input in ``warp_chain_p{i}``, so
    ``warp_chain_kept_jacobian()`` is the Jacobian at the point it last warped
    without a second walk through the chain (the raycaster's shading).
    """
    parts: list[str] = []
    for i, w in enumerate(warps):
        src = _constants_glsl(w.glsl_constants()) + loader(w.glsl_file)
        src = _PREFIX.sub(f"w{i}_", src)
        src = _FN.sub(lambda m, i=i: f"w{i}_warp{m.group(1) or ''}", src)
        if not re.search(rf"mat3\s+w{i}_warp_jacobian_at\s*\(", src):
            src += _DEFAULT_AT.format(i)
        parts.append(f"// ---- warp {i}: {w.kind}\n{src}")
    n = len(warps)
    body = [f"vec3 warp_chain_p{i};" for i in range(n + 1)] if n else []
    body += ["vec3 warp_chain(vec3 p) {"]
    for i in range(n):
        body += [f"    warp_chain_p{i} = p;", f"    p = w{i}_warp(p);"]
    body += [f"    warp_chain_p{n} = p;"] if n else []
    body += ["    return p;", "}", "vec3 warp_chain_and_jacobian(vec3 p, out mat3 J) {"]
    body += ["    J = mat3(1.0);"]
    for i in range(n):
        body += [f"    {{ vec3 q = w{i}_warp(p); J = w{i}_warp_jacobian_at(p, q) * J; p = q; }}"]
    body += ["    return p;", "}", "mat3 warp_chain_jacobian(vec3 p) {", "    mat3 J;"]
    body += ["    warp_chain_and_jacobian(p, J);", "    return J;", "}"]
    body += ["mat3 warp_chain_kept_jacobian() {", "    mat3 J = mat3(1.0);"]
    for i in range(n):
        body += [f"    J = w{i}_warp_jacobian_at(warp_chain_p{i}, warp_chain_p{i + 1}) * J;"]
    body += ["    return J;", "}"]
    return "\n".join([*parts, *body]) + "\n"
