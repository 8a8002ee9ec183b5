"""A scene graph whose nodes carry 4x4 matrices or trilinear lattices, composed per leaf.

About this technique
--------------------
Knuth, Kohlhammer and Kuijper, "Embedding hierarchical deformation within a realtime
scene graph" (GRAPP 2010) put free-form deformation into an ordinary scene graph: every
node carries a *transform*, either a 4x4 matrix or a grid of trilinear cells (the
lattice of section 3, :class:`voxwarp.deform.lattice.trilinear.TrilinearGrid`), and a *bounding box*
that maps the node's content into the unit cube on which the lattice is defined
(section 4). Before rendering, the transforms are propagated from the world down to
every geometry leaf, which receives ONE composed transform (section 4.1); the vertex
shader then applies that single transform (a matrix product, or one trilinear lookup in
the lattice's node texture, section 5) in constant time however deep the leaf sits in
the hierarchy (the evaluation of section 6 measures exactly this).

Semantics implemented here:

* A node's transform maps its *local* coordinates into its *parent's* coordinates; the
  root's parent is the world. ``None`` is the identity.
* A 4x4 (affine) matrix acts on local coordinates directly: ``x_parent = M [x; 1]``.
* A :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid` acts on the box-normalised coordinates
  ``u = (x - lo) / (hi - lo)`` of the node's box ``(lo, hi)`` (the node's content box,
  in its local coordinates) and returns parent coordinates: ``x_parent = G(u)``. A grid
  transform therefore needs a box (:class:`~voxwarp.deform.warp.WarpError` otherwise).
* The composed transform of a node with geometry (a *leaf*; it may still have children)
  maps the leaf's local points to world coordinates:

  - if every transform on the root-to-leaf path is a matrix (or ``None``), it is the
    4x4 product ``M_root @ ... @ M_leaf``: linear chains stay matrices;
  - otherwise it is a :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid` over the leaf's
    box-unit cube, built by pushing the leaf's grid node points through the chain,
    child side first. This is the paper's composition ``G o L`` (section 4.1) applied
    pairwise: L's grid points are mapped into G's box-unit coordinates and then through
    G, at the higher of the two resolutions; a 4x4 under a grid becomes a grid sampled
    at the grid's resolution. The result's resolution is the finest met on the path
    (per axis), raised to ``resolution`` when that is given.

  The composed grid is exact at its nodes (each node point went through the exact
  chain) and trilinear in between, so its error shrinks as the resolution grows; a
  chain of identity lattices composes to the identity exactly (to rounding), whatever
  its depth.

* Content outside a grid node's box is outside its lattice: :func:`compose_scene`
  refuses (``strict=True``, the default) when a leaf's node points fall outside the box
  of a grid node above it, naming the box to enlarge; ``strict=False`` hands such points
  to the grid as they are, which extends its border cells' trilinear polynomials beyond
  the unit cube (:class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid`'s extrapolation).

Each node has at most one parent: adding a node twice, or into its own subtree, raises
:class:`~voxwarp.deform.warp.WarpError`, and :meth:`SceneNode.walk` detects cycles made behind
:meth:`SceneNode.add`'s back (``children.append``).

Composition is done per leaf from scratch (``O(nodes x depth)``); shared path prefixes
are not cached.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp.deform.lattice.trilinear import TrilinearGrid, TrilinearTransform
from voxwarp.deform.warp import WarpError

__all__ = ["ComposedTransform", "SceneNode", "compose_path", "compose_scene"]

Box = tuple[np.ndarray, np.ndarray]

#: how far (in box-unit coordinates) a point may lie outside a grid node's box
#: before :func:`compose_scene` calls it outside the lattice (rounding only)
INSIDE_TOL = 1e-9


# --------------------------------------------------------------------------- validation
def _label(name: str) -> str:
    return repr(name) if name else "(unnamed)"


def _as_box(box: Any, name: str) -> Box | None:
    """Validate a box given as ``(lo, hi)``; returns two float64 (3,) arrays or None."""
    if box is None:
        return None
    try:
        arr = np.array([np.asarray(box[0], dtype=np.float64), np.asarray(box[1], dtype=np.float64)])
        if len(box) != 2:
            raise ValueError
    except (TypeError, ValueError, IndexError, KeyError):
        raise WarpError(
            f"box of node {_label(name)} must be (lo, hi) with 3 coordinates each; got "
            f"{box!r:.80}; pass box=((x0, y0, z0), (x1, y1, z1))"
        ) from None
    if arr.shape != (2, 3):
        raise WarpError(
            f"box of node {_label(name)} must be (lo, hi) with 3 coordinates each; got "
            f"shape {arr.shape}; pass box=((x0, y0, z0), (x1, y1, z1))"
        )
    if not np.all(np.isfinite(arr)):
        raise WarpError(
            f"box of node {_label(name)} has non-finite coordinates {arr.tolist()}; "
            "pass finite lo and hi"
        )
    lo, hi = arr[0].copy(), arr[1].copy()
    bad = np.flatnonzero(lo >= hi)
    if bad.size:
        axes = ", ".join("xyz"[a] for a in bad)
        raise WarpError(
            f"box of node {_label(name)} has lo >= hi on axis {axes} (lo={lo.tolist()}, "
            f"hi={hi.tolist()}); pass lo < hi on every axis (a box of positive size)"
        )
    return lo, hi


def _grid_from_cell(t: TrilinearTransform) -> TrilinearGrid:
    """One-cell grid of a single trilinear transform (corner index x + 2 y + 4 z)."""
    corners = np.asarray(t.corners, dtype=np.float64)
    return TrilinearGrid(corners.reshape(2, 2, 2, 3).transpose(2, 1, 0, 3))


def _as_transform(transform: Any, name: str) -> np.ndarray | TrilinearGrid | None:
    """Validate a node transform: None, an affine 4x4, a TrilinearGrid (or a single cell)."""
    if transform is None or isinstance(transform, TrilinearGrid):
        return transform
    if isinstance(transform, TrilinearTransform):
        return _grid_from_cell(transform)
    try:
        m = np.array(transform, dtype=np.float64)
    except (TypeError, ValueError):
        raise WarpError(
            f"transform of node {_label(name)} must be None, a 4x4 matrix or a "
            f"TrilinearGrid; got {type(transform).__name__}"
        ) from None
    if m.shape != (4, 4):
        raise WarpError(
            f"transform of node {_label(name)} must be None, a 4x4 matrix or a "
            f"TrilinearGrid; got an array of shape {m.shape}; pass a 4x4 affine matrix"
        )
    if not np.all(np.isfinite(m)):
        raise WarpError(
            f"transform of node {_label(name)} has non-finite entries; pass a finite 4x4 matrix"
        )
    if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-12):
        raise WarpError(
            f"transform of node {_label(name)} is not affine (last row {m[3].tolist()}); "
            "pass a 4x4 whose last row is (0, 0, 0, 1)"
        )
    m[3] = (0.0, 0.0, 0.0, 1.0)
    return m


def _as_cells(resolution: Any) -> np.ndarray | None:
    """Validate ``resolution``: None, an int or three ints >= 1 (cells per axis)."""
    if resolution is None:
        return None
    vals = list(resolution) if isinstance(resolution, (list, tuple, np.ndarray)) else [resolution]
    if len(vals) == 1:
        vals = vals * 3
    ok = len(vals) == 3 and all(
        isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) and v >= 1
        for v in vals
    )
    if not ok:
        raise WarpError(
            f"resolution must be an int >= 1 or three ints >= 1 (cells per axis); got "
            f"{resolution!r:.60}; pass e.g. resolution=8 or (8, 8, 4)"
        )
    return np.array([int(v) for v in vals])


def _points(x: Any) -> tuple[np.ndarray, tuple[int, ...]]:
    """(N, 3) float64 view of points given as (..., 3); also their leading shape."""
    p = np.asarray(x, dtype=np.float64)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise WarpError(f"points must have shape (N, 3) or (..., 3); got {p.shape}")
    return p.reshape(-1, 3), p.shape[:-1]


# --------------------------------------------------------------------------- scene nodes
class SceneNode:
    """A scene-graph node: a transform into the parent's coordinates, a box, content.

    Parameters
    ----------
    name
        Label used in error messages and saved by :meth:`to_dict`.
    transform
        ``None`` (the identity), a 4x4 affine matrix acting on local coordinates, or a
        :class:`~voxwarp.deform.lattice.trilinear.TrilinearGrid` acting on the box-normalised
        coordinates ``u = (x - lo) / (hi - lo)`` (a single
        :class:`~voxwarp.deform.lattice.trilinear.TrilinearTransform` is taken as a one-cell
        grid). Either way the result is in the parent's coordinates.
    box
        ``(lo, hi)``: the node's content box in its local coordinates, ``lo < hi`` on
        every axis. Required with a grid transform; for a node with geometry under a grid
        it is the box over which the composed lattice is built.
    geometry
        Opaque content (a mesh, a volume, a file name, ...). Nodes with geometry are the
        leaves :func:`compose_scene` composes a transform for.
    children
        Nodes added with :meth:`add`, in order.

    Raises
    ------
    WarpError
        On an invalid box or transform, or a grid transform without a box.
    """

    def __init__(
        self,
        name: str = "",
        transform: np.ndarray | TrilinearGrid | TrilinearTransform | None = None,
        box: Any = None,
        geometry: Any = None,
        children: Sequence[SceneNode] = (),
    ) -> None:
        self.name = str(name)
        self._box = _as_box(box, self.name)
        self._transform = _as_transform(transform, self.name)
        self._check_grid_box(self._transform, self._box)
        self.geometry = geometry
        self.children: list[SceneNode] = []
        self.parent: SceneNode | None = None
        for child in children:
            self.add(child)

    def __repr__(self) -> str:
        kind = (
            "identity"
            if self._transform is None
            else "grid" + "x".join(map(str, self._transform.shape))
            if isinstance(self._transform, TrilinearGrid)
            else "matrix"
        )
        return f"SceneNode({self.name!r}, {kind}, children={len(self.children)})"

    # ------------------------------------------------------------ transform and box
    def _check_grid_box(self, transform: Any, box: Box | None) -> None:
        if isinstance(transform, TrilinearGrid) and box is None:
            raise WarpError(
                f"node {_label(self.name)} has a TrilinearGrid transform but no box; the grid "
                "acts on u = (x - lo) / (hi - lo): pass box=(lo, hi), its content box in local "
                "coordinates"
            )

    @property
    def transform(self) -> np.ndarray | TrilinearGrid | None:
        """``None`` (identity), a 4x4 affine matrix, or a TrilinearGrid (needs :attr:`box`)."""
        return self._transform

    @transform.setter
    def transform(self, value: np.ndarray | TrilinearGrid | TrilinearTransform | None) -> None:
        t = _as_transform(value, self.name)
        self._check_grid_box(t, self._box)
        self._transform = t

    @property
    def box(self) -> Box | None:
        """``(lo, hi)`` content box in local coordinates (two float64 (3,) arrays) or None."""
        return self._box

    @box.setter
    def box(self, value: Any) -> None:
        b = _as_box(value, self.name)
        self._check_grid_box(self._transform, b)
        self._box = b

    @property
    def is_linear(self) -> bool:
        """True when the transform is ``None`` or a matrix (a grid is never "linear" here,
        even an affine one: the kind of the composed transform follows the node kinds)."""
        return not isinstance(self._transform, TrilinearGrid)

    def local_matrix(self) -> np.ndarray:
        """The 4x4 local -> parent matrix (identity for ``None``).

        Raises
        ------
        WarpError
            For a grid transform.
        """
        if self._transform is None:
            return np.eye(4)
        if isinstance(self._transform, TrilinearGrid):
            raise WarpError(
                f"node {_label(self.name)} has a grid transform, not a matrix; use apply() "
                "or compose_scene() instead of local_matrix()"
            )
        return self._transform.copy()

    def to_unit(self, x: Any) -> np.ndarray:
        """Box-normalised coordinates ``(x - lo) / (hi - lo)`` of local points (..., 3)."""
        if self._box is None:
            raise WarpError(f"node {_label(self.name)} has no box; pass box=(lo, hi)")
        lo, hi = self._box
        return (np.asarray(x, dtype=np.float64) - lo) / (hi - lo)

    def apply(self, x: Any) -> np.ndarray:
        """Map local points (..., 3) into the parent's coordinates (exactly, this node only)."""
        p, lead = _points(x)
        t = self._transform
        if t is None:
            out = p.copy()
        elif isinstance(t, TrilinearGrid):
            out = np.asarray(t(self.to_unit(p)), dtype=np.float64)
        else:
            out = p @ t[:3, :3].T + t[:3, 3]
        return out.reshape(*lead, 3)

    def local_jacobian(self, x: Any) -> np.ndarray:
        """Jacobians ``d parent / d local`` (N, 3, 3) of :meth:`apply` at points (N, 3)."""
        p, _ = _points(x)
        t = self._transform
        if t is None:
            return np.broadcast_to(np.eye(3), (p.shape[0], 3, 3)).copy()
        if isinstance(t, TrilinearGrid):
            lo, hi = self._box  # type: ignore[misc]
            return np.asarray(t.jacobian(self.to_unit(p)), dtype=np.float64) / (hi - lo)
        return np.broadcast_to(t[:3, :3], (p.shape[0], 3, 3)).copy()

    # ------------------------------------------------------------ hierarchy
    def ancestors(self) -> list[SceneNode]:
        """Parent, grandparent, ... up to the root (empty for a root)."""
        out: list[SceneNode] = []
        seen = {id(self)}
        node = self.parent
        while node is not None:
            if id(node) in seen:
                raise WarpError(
                    f"the parent links above node {_label(self.name)} form a cycle; rebuild "
                    "the hierarchy with add()/remove()"
                )
            seen.add(id(node))
            out.append(node)
            node = node.parent
        return out

    def add(self, child: SceneNode) -> SceneNode:
        """Append ``child`` to :attr:`children` and return it (so chains can be built inline).

        Raises
        ------
        WarpError
            If ``child`` is not a SceneNode, is this node or one of its ancestors (a
            cycle), or already has a parent (a node is added once; add a copy instead).
        """
        if not isinstance(child, SceneNode):
            raise WarpError(
                f"add() takes a SceneNode; got {type(child).__name__}; wrap the content "
                "in SceneNode(geometry=...)"
            )
        if child is self or any(a is child for a in self.ancestors()):
            raise WarpError(
                f"adding node {_label(child.name)} under {_label(self.name)} would make a "
                "cycle (it is that node or one of its ancestors); add a new node instead"
            )
        if child.parent is not None:
            raise WarpError(
                f"node {_label(child.name)} is already a child of {_label(child.parent.name)}; "
                "a node has one parent: remove it there first (parent.remove(node)) or add a "
                "new node"
            )
        self.children.append(child)
        child.parent = self
        return child

    def remove(self, child: SceneNode) -> SceneNode:
        """Detach ``child`` from this node and return it."""
        for i, c in enumerate(self.children):
            if c is child:
                del self.children[i]
                child.parent = None
                return child
        raise WarpError(
            f"node {_label(getattr(child, 'name', ''))} is not a child of {_label(self.name)}; "
            "remove it from its own parent"
        )

    def _walk_paths(self) -> Iterator[tuple[SceneNode, ...]]:
        """Root-to-node paths in depth-first pre-order, children in order."""
        seen: set[int] = set()
        stack: list[tuple[SceneNode, ...]] = [(self,)]
        while stack:
            path = stack.pop()
            node = path[-1]
            if id(node) in seen:
                raise WarpError(
                    f"node {_label(node.name)} is reached twice below {_label(self.name)} (a "
                    "cycle, or one node under two parents through children.append); use add(), "
                    "which allows one parent per node, and new nodes for repeated content"
                )
            seen.add(id(node))
            yield path
            for child in reversed(node.children):
                if not isinstance(child, SceneNode):
                    raise WarpError(
                        f"node {_label(node.name)} has a child of type {type(child).__name__}; "
                        "children must be SceneNode objects (use add())"
                    )
                stack.append((*path, child))

    def walk(self) -> Iterator[tuple[SceneNode, int]]:
        """Yield ``(node, depth)`` for this node (depth 0) and its subtree, depth first.

        Raises
        ------
        WarpError
            If a node is reached twice (a cycle or a shared node).
        """
        for path in self._walk_paths():
            yield path[-1], len(path) - 1

    # ------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form of this subtree.

        Keys: ``name``; ``transform`` (``None``, ``{"matrix": 4x4 lists}`` or
        ``{"grid": TrilinearGrid.to_dict()}``); ``box`` (``None`` or ``[lo, hi]``);
        ``geometry`` (only when it is a ``str`` or path: saved as that reference string;
        other content is omitted); ``children`` (a list of such dicts).
        """
        for _ in self.walk():  # refuse cycles before recursing
            pass
        return self._to_dict()

    def _to_dict(self) -> dict[str, Any]:
        t = self._transform
        if t is None:
            td: dict[str, Any] | None = None
        elif isinstance(t, TrilinearGrid):
            td = {"grid": t.to_dict()}
        else:
            td = {"matrix": t.tolist()}
        d: dict[str, Any] = {
            "name": self.name,
            "transform": td,
            "box": None if self._box is None else [self._box[0].tolist(), self._box[1].tolist()],
        }
        if isinstance(self.geometry, (str, os.PathLike)):
            d["geometry"] = os.fspath(self.geometry)
        d["children"] = [c._to_dict() for c in self.children]
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SceneNode:
        """Rebuild a subtree from :meth:`to_dict`'s form (geometry comes back as its string)."""
        if not isinstance(d, Mapping):
            raise WarpError(f"a scene node entry must be an object; got {type(d).__name__}")
        allowed = {"name", "transform", "box", "geometry", "children"}
        unknown = sorted(set(d) - allowed)
        if unknown:
            raise WarpError(
                f"unknown keys {unknown} in scene node {d.get('name', '')!r}; allowed keys: "
                f"{sorted(allowed)}"
            )
        name = str(d.get("name", ""))
        td = d.get("transform")
        transform: Any
        if td is None:
            transform = None
        elif isinstance(td, Mapping) and set(td) == {"matrix"}:
            transform = td["matrix"]
        elif isinstance(td, Mapping) and set(td) == {"grid"}:
            transform = TrilinearGrid.from_dict(td["grid"])
        else:
            raise WarpError(
                f"transform of scene node {_label(name)} must be null, {{'matrix': 4x4}} or "
                f"{{'grid': {{...}}}}; got {td!r:.80}"
            )
        children = d.get("children", [])
        if not isinstance(children, Sequence) or isinstance(children, (str, bytes)):
            raise WarpError(f"children of scene node {_label(name)} must be a list of objects")
        node = cls(name=name, transform=transform, box=d.get("box"), geometry=d.get("geometry"))
        for c in children:
            node.add(cls.from_dict(c))
        return node


# --------------------------------------------------------------------------- composition
class ComposedTransform:
    """The single local -> world transform of one geometry leaf (paper section 4.1).

    Exactly one of :attr:`matrix` and :attr:`grid` is set. Built by
    :func:`compose_scene` / :func:`compose_path`.

    Attributes
    ----------
    node
        The leaf.
    box
        ``(lo, hi)`` of the leaf's content in its local coordinates (its :attr:`SceneNode.box`;
        ``None`` only for a matrix result of a leaf without a box).
    matrix
        4x4 local -> world matrix when every transform on the path is a matrix, else None.
    grid
        TrilinearGrid from the leaf's box-unit cube to world, else None.
    path
        The nodes from the root to the leaf.
    """

    def __init__(
        self,
        node: SceneNode,
        box: Box | None,
        matrix: np.ndarray | None = None,
        grid: TrilinearGrid | None = None,
        path: Sequence[SceneNode] = (),
    ) -> None:
        if (matrix is None) == (grid is None):
            raise WarpError("a ComposedTransform holds exactly one of matrix and grid")
        if grid is not None and box is None:
            raise WarpError(
                f"the composed grid of node {_label(node.name)} needs the leaf's box; pass box"
            )
        self.node = node
        self.box = box
        self.matrix = matrix
        self.grid = grid
        self.path: tuple[SceneNode, ...] = tuple(path) if path else (node,)

    def __repr__(self) -> str:
        kind = "matrix" if self.grid is None else "grid " + "x".join(map(str, self.grid.shape))
        return f"ComposedTransform({self.node.name!r}, {kind}, depth={len(self.path) - 1})"

    @property
    def is_linear(self) -> bool:
        """True when the composed transform is a matrix."""
        return self.grid is None

    def to_unit(self, x: Any) -> np.ndarray:
        """Leaf-box unit coordinates ``(x - lo) / (hi - lo)`` of leaf-local points."""
        if self.box is None:
            raise WarpError(f"node {_label(self.node.name)} has no box; pass box=(lo, hi)")
        lo, hi = self.box
        return (np.asarray(x, dtype=np.float64) - lo) / (hi - lo)

    def __call__(self, x: Any) -> np.ndarray:
        """Map leaf-local points (N, 3) (or (..., 3)) to world, in one step."""
        p, lead = _points(x)
        if self.grid is None:
            m = self.matrix
            out = p @ m[:3, :3].T + m[:3, 3]  # type: ignore[index]
        else:
            out = np.asarray(self.grid(self.to_unit(p)), dtype=np.float64)
        return out.reshape(*lead, 3)

    def jacobian(self, x: Any) -> np.ndarray:
        """Jacobians ``d world / d local`` (N, 3, 3) at leaf-local points (N, 3)."""
        p, _ = _points(x)
        if self.grid is None:
            return np.broadcast_to(self.matrix[:3, :3], (p.shape[0], 3, 3)).copy()  # type: ignore[index]
        lo, hi = self.box  # type: ignore[misc]
        return np.asarray(self.grid.jacobian(self.to_unit(p)), dtype=np.float64) / (hi - lo)

    def reference(self, x: Any) -> np.ndarray:
        """The exact chain, node by node (leaf first), for checking the composed transform."""
        p, lead = _points(x)
        for node in reversed(self.path):
            p = node.apply(p)
        return p.reshape(*lead, 3)


def _unit_nodes(cells: np.ndarray) -> np.ndarray:
    """(nx+1, ny+1, nz+1, 3) unit-cube node coordinates, node (i, j, k) at (i/nx, j/ny, k/nz)."""
    axes = [np.arange(n + 1, dtype=np.float64) / n for n in cells]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


@functools.lru_cache(maxsize=64)
def _unit_nodes_flat(cells: tuple[int, int, int]) -> np.ndarray:
    """:func:`_unit_nodes` flattened to (M, 3), cached (read-only): every leaf of a scene
    needs the same few."""
    out = _unit_nodes(np.asarray(cells)).reshape(-1, 3)
    out.flags.writeable = False
    return out


def compose_path(
    path: Sequence[SceneNode], resolution: Any = None, strict: bool = True
) -> ComposedTransform:
    """Compose the transforms of a root-to-leaf path into one local -> world transform.

    Parameters
    ----------
    path
        Nodes from the root (its parent is the world) to the leaf, each a child of the
        previous one.
    resolution
        Minimum cells per axis of a composed grid (an int or three ints); the grid has the
        finest resolution met on the path, raised to this.
    strict
        Refuse node points that fall outside the box of a grid node above the leaf.

    Returns
    -------
    ComposedTransform
        A matrix product when every transform on the path is a matrix, else a grid over
        the leaf's box-unit cube whose nodes are the leaf's node points pushed through the
        exact chain, child side first.

    Raises
    ------
    WarpError
        On an empty path, a bad resolution, a leaf without a box under a grid, or (with
        ``strict``) content outside a grid node's box.
    """
    path = tuple(path)
    if not path:
        raise WarpError("compose_path needs at least one node; pass [root, ..., leaf]")
    cells_min = _as_cells(resolution)
    leaf = path[-1]
    grids = [n.transform for n in path if isinstance(n.transform, TrilinearGrid)]
    if not grids:
        m = np.eye(4)
        for node in path:
            if node.transform is not None:
                m = m @ node.transform
        return ComposedTransform(leaf, leaf.box, matrix=m, path=path)
    if leaf.box is None:
        above = next(n for n in path if isinstance(n.transform, TrilinearGrid))
        raise WarpError(
            f"node {_label(leaf.name)} has geometry under the grid of node {_label(above.name)} "
            "but no box; the composed lattice is built over the leaf's box: pass box=(lo, hi), "
            "its geometry's bounds in local coordinates"
        )
    cells = np.max([np.asarray(g.shape, dtype=int) for g in grids], axis=0)
    if cells_min is not None:
        cells = np.maximum(cells, cells_min)
    u = _unit_nodes_flat(tuple(int(c) for c in cells))
    lo, hi = leaf.box
    if isinstance(leaf.transform, TrilinearGrid):
        # the leaf's own lattice: evaluate at the exact node coordinates (no box round trip)
        x = np.asarray(leaf.transform(u), dtype=np.float64)
    else:
        x = leaf.apply(lo + u * (hi - lo))
    for child, node in zip(reversed(path[1:]), reversed(path[:-1]), strict=True):
        if not isinstance(node.transform, TrilinearGrid):
            x = node.apply(x)
            continue
        un = node.to_unit(x)
        if strict:
            excess = float(np.max(np.maximum(-un, un - 1.0)))
            if excess > INSIDE_TOL:
                raise WarpError(
                    f"the content of node {_label(leaf.name)} (its box, through "
                    f"{_label(child.name)}) reaches {excess:.3g} box units outside the box of "
                    f"grid node {_label(node.name)}; enlarge that node's box to contain its "
                    "children's content (or compose with strict=False to extrapolate)"
                )
        x = np.asarray(node.transform(un), dtype=np.float64)
    nodes = x.reshape(cells[0] + 1, cells[1] + 1, cells[2] + 1, 3)
    return ComposedTransform(leaf, leaf.box, grid=TrilinearGrid(nodes), path=path)


def compose_scene(
    root: SceneNode, resolution: Any = None, strict: bool = True
) -> list[ComposedTransform]:
    """Propagate transforms from the world to every node with geometry (paper section 4.1).

    Parameters
    ----------
    root
        Root of the scene; its transform maps its local coordinates to world.
    resolution
        Minimum cells per axis of the composed grids (see :func:`compose_path`).
    strict
        Refuse content outside the box of a grid node above it (see :func:`compose_path`).

    Returns
    -------
    list of ComposedTransform
        One per node whose ``geometry`` is not None, in depth-first pre-order.

    Raises
    ------
    WarpError
        On a cycle, a bad resolution, or any error of :func:`compose_path`.
    """
    if not isinstance(root, SceneNode):
        raise WarpError(f"compose_scene takes a SceneNode; got {type(root).__name__}")
    _as_cells(resolution)
    return [
        compose_path(path, resolution=resolution, strict=strict)
        for path in root._walk_paths()
        if path[-1].geometry is not None
    ]
