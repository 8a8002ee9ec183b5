"""Meshes that follow the volume's warp chain: vertices baked on the CPU.

A scene's warps map deformed points to original ones (``chain_apply``); meshes live in
the original world (they are drawn on the anatomy), so to move with the volume a vertex
goes the other way, through the chain's forward map
(:func:`voxwarp.deform.warp.chain_forward_lenient`). Normals follow the Jacobian: for a surface
``f(x) = 0`` of the original space seen in deformed space as ``f(A(p)) = 0`` (A the
chain), the normal is ``J_A(p)^T n`` (:func:`voxwarp.deform.warp.chain_jacobian`).

:func:`warped_geometry` bakes one instance (its own matrix or lattice first, then the
chain) and caches the result per mesh object, instance transform and the chain's warps
and revisions, so an unchanged scene is not baked again each frame. Only the
:class:`~voxwarp.deform.warp.Warp` interface is used, whatever the families.
"""

from __future__ import annotations

import warnings
import weakref
from collections import OrderedDict
from collections.abc import Hashable, Sequence

import numpy as np

from voxwarp.core.mesh import MeshInstance
from voxwarp.deform.identity import token
from voxwarp.deform.warp import Warp, chain_forward_lenient, chain_jacobian, fold_affine
from voxwarp.errors import MeshError


class MeshWarpWarning(UserWarning):
    """Some vertices of a mesh could not be moved through the warp chain exactly."""


#: baked instances kept (least recently used dropped first)
CACHE_SIZE = 32

_CACHE: OrderedDict[Hashable, tuple[weakref.ref, np.ndarray, np.ndarray]] = OrderedDict()


def moves_meshes(warps: Sequence[Warp]) -> bool:
    """True when the chain moves anything: non-empty and not only identity maps."""
    for w in warps:
        if not (w.is_affine and np.allclose(w.affine_matrix(), np.eye(4), atol=0.0)):
            return True
    return False


def affine_forward(warps: Sequence[Warp]) -> np.ndarray | None:
    """The chain's forward 4x4 matrix (original -> deformed) when every warp is affine,
    else None (an all-affine chain goes into the instance matrix, no baking)."""
    m = fold_affine(warps)
    return None if m is None else np.linalg.inv(m)


def geometry_key(instance: MeshInstance, warps: Sequence[Warp]) -> Hashable:
    """What a baked instance depends on: the mesh object, its transform and box, and
    each warp's identity and revision."""
    t = instance.transform
    if t is None or isinstance(t, np.ndarray):
        tkey: Hashable = instance.matrix().tobytes()
    else:
        lo, hi = instance.box
        tkey = (token(t), lo.tobytes(), hi.tobytes())
    return (token(instance.mesh), tkey, tuple((token(w), w.revision) for w in warps))


def warped_geometry(
    instance: MeshInstance, warps: Sequence[Warp]
) -> tuple[np.ndarray, np.ndarray, Hashable]:
    """World positions (N, 3) and unit normals (N, 3) of an instance's vertices moved
    by the chain's forward map, and the cache key they are stored under.

    Each vertex goes to the point the volume's inverse (``chain_apply``) maps to it.
    Where the chain has no such point (outside every support, e.g. content pushed out of
    an unpadded element grid; a tear such as the edge of a displacement field's grid) or
    folds (``det J <= 0``) those vertices keep the best estimate and one
    :class:`MeshWarpWarning` line names the mesh and counts them; the rest is exact.
    """
    key = geometry_key(instance, warps)
    hit = _CACHE.get(key)
    if hit is not None and hit[0]() is instance.mesh:
        _CACHE.move_to_end(key)
        return hit[1], hit[2], key
    world, normals = _placed(instance)
    p, failed, message = chain_forward_lenient(warps, world)
    j = chain_jacobian(warps, p)
    _warn_uncarried(instance.name, failed, np.linalg.det(j) <= 0.0, message)
    n = np.einsum("nji,nj->ni", j, normals)  # J^T n
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    p.setflags(write=False)
    n.setflags(write=False)
    _CACHE[key] = (weakref.ref(instance.mesh), p, n)
    while len(_CACHE) > CACHE_SIZE:
        _CACHE.popitem(last=False)
    return p, n, key


def _warn_uncarried(name: str, failed: np.ndarray, folded: np.ndarray, message: str) -> None:
    """One :class:`MeshWarpWarning` line naming the mesh and counting the vertices the
    chain cannot carry: no forward map (outside every support, a tear) or a fold
    (``det J <= 0`` at the vertex's deformed point)."""
    bad = failed | folded
    if not np.any(bad):
        return
    why = []
    if np.any(failed):
        why.append(f"{int(failed.sum())} without a point the volume's inverse maps to them")
    if np.any(folded & ~failed):
        why.append(f"{int((folded & ~failed).sum())} in a fold (det J <= 0)")
    detail = f" ({message})" if message else " (the warp chain folds there)"
    warnings.warn(
        f"mesh {name!r}: {int(bad.sum())} of {len(bad)} vertices have no forward map and"
        f" keep their nearest estimate: {', '.join(why)}{detail}",
        MeshWarpWarning,
        stacklevel=4,
    )


def _placed(instance: MeshInstance) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and normals placed by the instance's own matrix or lattice (CPU; the
    normals as the vertex shader carries them, :meth:`MeshInstance.world_normals`)."""
    v = instance.mesh.vertices.astype(np.float64)
    return instance.local_to_world(v), instance.world_normals(v)


def warped_bounds(
    instances: Sequence[MeshInstance], warps: Sequence[Warp]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Box of the instances moved by the chain (None without instances)."""
    if not instances:
        return None
    pts = [warped_geometry(inst, warps)[0] for inst in instances]
    return (
        np.min([p.min(axis=0) for p in pts], axis=0),
        np.max([p.max(axis=0) for p in pts], axis=0),
    )


def mesh_instances_bounds(
    instances: Sequence[MeshInstance], warps: Sequence[Warp] = ()
) -> tuple[np.ndarray, np.ndarray] | None:
    """Union of the instances' :meth:`~voxwarp.core.mesh.MeshInstance.world_bounds`
    (None without any).

    ``warps``: a scene's warp chain; the box then holds the meshes moved by its forward
    map (:func:`warped_bounds`), as they are drawn.
    """
    if not instances:
        return None
    if moves_meshes(warps):
        return warped_bounds(instances, warps)
    boxes = [inst.world_bounds() for inst in instances]
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise MeshError("mesh instance bounds are not finite (a lattice with NaN nodes?)")
    return lo, hi


__all__ = [
    "affine_forward",
    "geometry_key",
    "mesh_instances_bounds",
    "moves_meshes",
    "warped_bounds",
    "warped_geometry",
]
