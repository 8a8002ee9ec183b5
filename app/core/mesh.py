"""Triangle meshes, mesh generators and mesh instances placed by a matrix or a lattice.

About this technique
--------------------
Knuth, Kohlhammer and Kuijper ("Embedding hierarchical deformation within a realtime
scene graph", GRAPP 2010) replace the 4x4 matrix of a scene-graph edge by a trilinear
transformation (section 3), or a grid of them to approximate any smooth deformation,
compose the transformations along the graph (section 4.1) and deform the geometry of
each leaf in the vertex shader (sections 4.2 and 5). This module holds the geometry
side of that: a :class:`Mesh` (vertices, faces, vertex normals), loaded through trimesh
(OBJ, STL, PLY, GLB/GLTF) or made by the small generators below, and a
:class:`MeshInstance`, one mesh placed in the world by

* nothing (identity), a 4x4 affine matrix (local -> world), or
* a :class:`voxwarp.deform.lattice.trilinear.TrilinearGrid` acting on the box-normalised coordinate
  ``u = (x - lo) / (hi - lo)`` of the instance's ``box`` (by default the mesh's
  bounding box: the paper's bounding box of the deformed object), ``world = grid(u)``.

:func:`instances_from_scene_graph` turns a :mod:`voxwarp.deform.lattice.scene_graph` hierarchy into
one
instance per mesh leaf, with the composed transform of its path (one matrix when every
transform on the path is linear, else one grid), so a vertex costs O(1) on the GPU
whatever the depth of the graph. :mod:`voxwarp.render.mesh_pass` draws the instances.

Meshes are treated as immutable: their arrays are read-only, and the renderer caches
GPU buffers per mesh object.
"""

from __future__ import annotations

import base64
import math
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from voxwarp.core.checks import finite_box, finite_vector
from voxwarp.core.limits import MAX_MESH_TRIANGLES
from voxwarp.deform.lattice.trilinear import TrilinearGrid, carry_normals, cofactor_matrix
from voxwarp.deform.warp import box_corners
from voxwarp.errors import MeshError

#: File extensions :func:`load_mesh` reads (through trimesh).
MESH_FORMATS: tuple[str, ...] = (".obj", ".stl", ".ply", ".glb", ".gltf")
#: Largest mesh (vertex + face bytes) scene JSON embeds inline; larger meshes need a file.
MESH_EMBED_LIMIT_BYTES = 4 * 2**20
#: How a lattice instance transforms vertex normals (see :mod:`voxwarp.render.mesh_pass`).
NORMAL_METHODS: tuple[str, ...] = ("normal", "tangent")
#: The default: the tangent-space normal, whose error against the smooth shape a
#: lattice samples shrinks as its cells get finer (the direct one keeps the error of a
#: non-uniform stretch; docs/benchmarks.md, "Lattice normals").
DEFAULT_NORMAL_METHOD = "tangent"
#: Colour of an instance when none is given (RGBA, straight alpha).
DEFAULT_COLOR = (0.85, 0.82, 0.75, 1.0)
#: Relative area below which a face counts as degenerate (of the squared bounding diagonal).
DEGENERATE_AREA = 1e-14


class MeshWarning(UserWarning):
    """Something about a mesh was repaired on loading (e.g. degenerate faces dropped)."""


def _vector(x: Any, n: int, what: str) -> np.ndarray:
    return finite_vector(x, n, what, MeshError)


class Mesh:
    """An indexed triangle mesh with vertex normals.

    Parameters
    ----------
    vertices
        (N, 3) vertex positions (stored as float32); all finite.
    faces
        (M, 3) vertex indices (stored as uint32), counter-clockwise seen from the side the
        normals point to. Faces of zero area (or repeating a vertex) are dropped with a
        :class:`MeshWarning`; a mesh without faces left is an error.
    normals
        Optional (N, 3) vertex normals; by default the area-weighted mean of the normals
        of the faces around each vertex.
    name
        Display name.
    source
        Path of the file the mesh came from (scene JSON refers to it), if any.
    recipe
        ``{"generator": name, "args": {...}}`` of a generated mesh (scene JSON stores the
        recipe instead of the arrays), if any.

    Raises
    ------
    MeshError
        Wrong shapes, non-finite vertices, face indices out of range, no faces.
    """

    def __init__(
        self,
        vertices: Any,
        faces: Any,
        normals: Any = None,
        name: str = "mesh",
        *,
        source: str | None = None,
        recipe: Mapping[str, Any] | None = None,
    ) -> None:
        self.name = str(name)
        self.source = None if source is None else str(source)
        self.recipe = None if recipe is None else dict(recipe)
        v, f = _check_arrays(vertices, faces, self.name)
        f, dropped = _drop_degenerate(v, f)
        if dropped:
            warnings.warn(
                f"mesh {self.name!r}: dropped {dropped} degenerate (zero-area) face"
                f"{'s' if dropped != 1 else ''} of {dropped + len(f)}",
                MeshWarning,
                stacklevel=2,
            )
        if len(f) == 0:
            raise MeshError(
                f"mesh {self.name!r} has no faces of non-zero area left; give it at least one"
                " triangle whose corners are not collinear"
            )
        if normals is None:
            n = vertex_normals(v, f)
        else:
            try:
                n = np.asarray(normals, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise MeshError(f"mesh {self.name!r}: normals must be numbers") from exc
            if n.shape != v.shape:
                raise MeshError(
                    f"mesh {self.name!r}: normals must have the vertices' shape {v.shape};"
                    f" got {n.shape}"
                )
            if not np.all(np.isfinite(n)):
                raise MeshError(f"mesh {self.name!r}: normals must be finite")
            n = _normalised(n)
        self._vertices = _readonly(v.astype(np.float32))
        self._faces = _readonly(f.astype(np.uint32))
        self._normals = _readonly(n.astype(np.float32))
        self._watertight: bool | None = None
        v64 = self._vertices.astype(np.float64)
        self._bounds = (_readonly(v64.min(axis=0)), _readonly(v64.max(axis=0)))

    @classmethod
    def from_arrays(
        cls, vertices: Any, faces: Any, normals: Any = None, name: str = "mesh"
    ) -> Mesh:
        """A mesh from arrays (same checks and repairs as the constructor)."""
        return cls(vertices, faces, normals, name)

    # ------------------------------------------------------------------ properties
    @property
    def vertices(self) -> np.ndarray:
        """(N, 3) float32 vertex positions (read-only)."""
        return self._vertices

    @property
    def faces(self) -> np.ndarray:
        """(M, 3) uint32 vertex indices per triangle (read-only)."""
        return self._faces

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) float32 unit vertex normals (read-only)."""
        return self._normals

    @property
    def n_vertices(self) -> int:
        """Number of vertices."""
        return len(self._vertices)

    @property
    def n_faces(self) -> int:
        """Number of triangles."""
        return len(self._faces)

    @property
    def nbytes(self) -> int:
        """Bytes of the vertex and face arrays."""
        return self._vertices.nbytes + self._faces.nbytes

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) float64 corners of the axis-aligned bounding box (read-only)."""
        return self._bounds

    @property
    def is_watertight(self) -> bool:
        """Whether every edge is shared by exactly two faces (vertices at the same
        position count as one, so split normals do not open a closed surface).

        Rendering never needs it; a non-manifold or open mesh loads and draws.
        """
        if self._watertight is None:
            _, inverse = np.unique(self._vertices, axis=0, return_inverse=True)
            f = inverse.reshape(-1)[self._faces.astype(np.int64)]
            edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
            _, counts = np.unique(edges, axis=0, return_counts=True)
            self._watertight = bool(np.all(counts == 2))
        return self._watertight

    def face_normals(self) -> np.ndarray:
        """(M, 3) float64 unit normals of the faces (from their winding)."""
        v = self._vertices.astype(np.float64)
        f = self._faces.astype(np.int64)
        return _normalised(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]))

    # ------------------------------------------------------------------ conversion
    def to_trimesh(self) -> Any:
        """A ``trimesh.Trimesh`` with the same vertices, faces and normals."""
        import trimesh

        return trimesh.Trimesh(
            vertices=self._vertices.astype(np.float64),
            faces=self._faces.astype(np.int64),
            vertex_normals=self._normals.astype(np.float64),
            process=False,
        )

    def save(self, path: str | os.PathLike) -> Path:
        """Write the mesh atomically (format from the extension, one of
        :data:`MESH_FORMATS`): a previous file of that name stays intact on failure."""
        path = Path(path)
        ext = path.suffix.lower()
        if ext not in MESH_FORMATS:
            raise MeshError(
                f"cannot write {path}: unknown mesh format {ext!r}; use one of"
                f" {', '.join(MESH_FORMATS)}"
            )
        from voxwarp.core.files import atomic_write

        mesh = self.to_trimesh()
        # trimesh picks the format from the extension: the temporary file keeps it
        atomic_write(path, ext, lambda tmp: mesh.export(tmp, file_type=ext[1:]))
        return path

    def to_dict(self, base_dir: str | os.PathLike | None = None) -> dict[str, Any]:
        """JSON form: a path (if the mesh came from a file that still exists), the
        generator recipe (generated meshes), or the arrays inline (base64 of
        little-endian float32 vertices and uint32 faces) when the mesh has at most
        :data:`MESH_EMBED_LIMIT_BYTES` bytes; larger meshes must be saved to a file first.
        """
        d: dict[str, Any] = {"name": self.name}
        if self.source is not None and os.path.exists(self.source):
            from voxwarp.core.scene_paths import path_entry

            d["path"] = path_entry(self.source, base_dir)
            return d
        if self.recipe is not None:
            d["generator"] = self.recipe["generator"]
            d["args"] = _jsonable(self.recipe.get("args", {}))
            return d
        if self.nbytes > MESH_EMBED_LIMIT_BYTES:
            raise MeshError(
                f"mesh {self.name!r} ({self.nbytes / 2**20:.1f} MB) has no file and is too large"
                f" to embed in scene JSON (limit {MESH_EMBED_LIMIT_BYTES / 2**20:.0f} MB);"
                " save it first with mesh.save('mesh.ply') and load it from there"
            )
        d["embedded"] = {
            "n_vertices": self.n_vertices,
            "n_faces": self.n_faces,
            "vertices": base64.b64encode(self._vertices.astype("<f4").tobytes()).decode("ascii"),
            "faces": base64.b64encode(self._faces.astype("<u4").tobytes()).decode("ascii"),
        }
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], base_dir: str | os.PathLike | None = None) -> Mesh:
        """Inverse of :meth:`to_dict`; raises :class:`MeshError`."""
        if not isinstance(d, Mapping):
            raise MeshError("a mesh entry must be an object with 'path', 'generator' or 'embedded'")
        name = str(d.get("name", "mesh"))
        if "path" in d:
            from voxwarp.core.scene_paths import scene_file

            mesh = load_mesh(
                scene_file(d["path"], base_dir, f"mesh {name!r}", MeshError, noun="mesh file")
            )
            mesh.name = name
            return mesh
        if "generator" in d:
            gen = d["generator"]
            if gen not in GENERATORS:
                raise MeshError(
                    f"unknown mesh generator {gen!r}; known: {', '.join(sorted(GENERATORS))}"
                )
            args = d.get("args") or {}
            if not isinstance(args, Mapping):
                raise MeshError(f"mesh generator args must be an object; got {args!r:.80}")
            try:
                mesh = GENERATORS[gen](**args)
            except MeshError:
                raise
            except (TypeError, ValueError, OverflowError) as exc:
                raise MeshError(f"invalid arguments for mesh generator {gen!r}: {exc}") from exc
            mesh.name = name
            return mesh
        if "embedded" in d:
            e = d["embedded"]
            try:
                nv, nf = int(e["n_vertices"]), int(e["n_faces"])
                vb = base64.b64decode(str(e["vertices"]), validate=True)
                fb = base64.b64decode(str(e["faces"]), validate=True)
            except (KeyError, TypeError, ValueError) as exc:
                raise MeshError(f"embedded mesh {name!r} is malformed: {exc}") from exc
            if len(vb) != nv * 12 or len(fb) != nf * 12:
                raise MeshError(
                    f"embedded mesh {name!r}: {len(vb)} vertex bytes and {len(fb)} face bytes do"
                    f" not match {nv} vertices and {nf} faces"
                )
            v = np.frombuffer(vb, dtype="<f4").reshape(nv, 3)
            f = np.frombuffer(fb, dtype="<u4").reshape(nf, 3)
            return cls(v, f, name=name)
        raise MeshError("a mesh entry needs one of 'path', 'generator' or 'embedded'")

    def __repr__(self) -> str:
        return f"Mesh({self.name!r}, vertices={self.n_vertices}, faces={self.n_faces})"


# ---------------------------------------------------------------------- helpers
def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


def _normalised(n: np.ndarray, fallback: Sequence[float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    ok = length[..., 0] > 0
    out = np.empty_like(n, dtype=np.float64)
    out[ok] = n[ok] / length[ok]
    out[~ok] = fallback
    return out


def _check_arrays(vertices: Any, faces: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"mesh {name!r}: vertices must be an (N, 3) array of numbers") from exc
    if v.ndim != 2 or v.shape[1] != 3:
        raise MeshError(f"mesh {name!r}: vertices must be an (N, 3) array; got shape {v.shape}")
    bad = ~np.all(np.isfinite(v), axis=1)
    if bad.any():
        first = int(np.argmax(bad))
        raise MeshError(
            f"mesh {name!r} has {int(bad.sum())} vertices with NaN or Inf coordinates (first:"
            f" vertex {first} = {v[first].tolist()}); repair or remove them before loading"
        )
    f = np.asarray(faces)
    if f.size == 0:
        raise MeshError(
            f"mesh {name!r} is empty: it has no faces (a point cloud or an empty file?);"
            " voxwarp draws triangle meshes"
        )
    if f.dtype.kind not in "iu":
        if f.dtype.kind == "f" and np.all(np.isfinite(f)) and np.all(f == np.round(f)):
            f = f.astype(np.int64)
        else:
            raise MeshError(f"mesh {name!r}: faces must be integer vertex indices; got {f.dtype}")
    if f.ndim != 2 or f.shape[1] != 3:
        raise MeshError(
            f"mesh {name!r}: faces must be an (M, 3) array of triangle indices; got shape"
            f" {f.shape} (triangulate quads/polygons first, e.g. with trimesh)"
        )
    f = f.astype(np.int64)
    out = (f < 0) | (f >= len(v))
    if out.any():
        face, corner = (int(i) for i in np.argwhere(out)[0])
        raise MeshError(
            f"mesh {name!r}: faces index vertices out of range: face {face} refers to vertex"
            f" {int(f[face, corner])} but the mesh has {len(v)} vertices (valid indices 0.."
            f"{len(v) - 1}); {int(out.any(axis=1).sum())} faces are affected"
        )
    return v, f


def _drop_degenerate(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, int]:
    """Faces with non-zero area, and how many were dropped."""
    diag2 = float(np.sum((v.max(axis=0) - v.min(axis=0)) ** 2)) if len(v) else 0.0
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    area2 = np.sum(cross**2, axis=1)  # (2 area)^2
    repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
    good = ~repeated & (area2 > (2.0 * DEGENERATE_AREA * diag2) ** 2)
    return f[good], int((~good).sum())


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N, 3) unit vertex normals: area-weighted sum of the adjacent faces' normals
    (``(0, 0, 1)`` for vertices no face uses).

    Summed through trimesh's vertex-face incidence matrix
    (``trimesh.geometry.index_sparse``, as ``mean_vertex_normals`` does) over the faces'
    cross products (twice the area times the unit normal): area weighting, not trimesh's
    default angle weighting, and normalised here at any scale (trimesh's ``unitize``
    zeroes sums shorter than 1e-13, e.g. a mesh in metres with sub-micron faces).
    """
    from trimesh.geometry import index_sparse  # trimesh loads when used

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # 2 * area * n
    return _normalised(np.asarray(index_sparse(len(v), f) @ cross))


def _jsonable(x: Any) -> Any:
    if isinstance(x, Mapping):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple | np.ndarray):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return x.item()
    return x


# ---------------------------------------------------------------------- loading
def _from_trimesh(obj: Any, name: str, merge: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and faces of a trimesh Trimesh or Scene (geometries concatenated with
    their scene-graph transforms)."""
    import trimesh

    parts: list[tuple[np.ndarray, np.ndarray]] = []
    if isinstance(obj, trimesh.Scene):
        for node in obj.graph.nodes_geometry:
            transform, geometry_name = obj.graph[node]
            geom = obj.geometry.get(geometry_name)
            if not isinstance(geom, trimesh.Trimesh):
                continue  # paths, point clouds: nothing to draw as triangles
            v = np.asarray(geom.vertices, dtype=np.float64)
            t = np.asarray(transform, dtype=np.float64)
            parts.append((v @ t[:3, :3].T + t[:3, 3], np.asarray(geom.faces)))
    elif isinstance(obj, trimesh.Trimesh):
        parts.append((np.asarray(obj.vertices, dtype=np.float64), np.asarray(obj.faces)))
    else:
        raise MeshError(
            f"{name} has no faces: it holds a {type(obj).__name__}, not a triangle mesh;"
            " voxwarp draws triangle meshes"
        )
    if not parts or all(len(f) == 0 for _, f in parts):
        raise MeshError(
            f"{name} is empty: it has no faces (a point cloud or an empty file?);"
            " voxwarp draws triangle meshes"
        )
    vertices, faces, offset = [], [], 0
    for v, f in parts:
        vertices.append(v)
        faces.append(np.asarray(f, dtype=np.int64).reshape(-1, 3) + offset)
        offset += len(v)
    v, f = np.concatenate(vertices), np.concatenate(faces)
    if merge and np.all(np.isfinite(v)) and f.size and f.min() >= 0 and f.max() < len(v):
        # STL stores every triangle's corners separately: share equal positions so
        # vertex normals are smooth across faces
        v, inverse = np.unique(v, axis=0, return_inverse=True)
        f = inverse.reshape(-1)[f]
    return v, f


def load_mesh(path_or_trimesh: Any, name: str | None = None) -> Mesh:
    """Load a triangle mesh from a file (OBJ, STL, PLY, GLB/GLTF) or a trimesh object.

    A GLB/GLTF (or any trimesh ``Scene``) is flattened: its geometries are concatenated
    with their scene-graph transforms applied. Vertex normals are recomputed from the
    faces (area-weighted), STL corners at equal positions are merged first.
    Degenerate faces are dropped with a :class:`MeshWarning`.

    Raises
    ------
    MeshError
        Missing file, unknown format, unreadable file, empty mesh (no faces), NaN/Inf
        vertices, faces indexing vertices out of range.
    """
    import trimesh

    if isinstance(path_or_trimesh, trimesh.Trimesh | trimesh.Scene):
        label = name or str(getattr(path_or_trimesh, "metadata", {}).get("name") or "mesh")
        v, f = _from_trimesh(path_or_trimesh, f"mesh {label!r}")
        return Mesh(v, f, name=label)
    if not isinstance(path_or_trimesh, str | os.PathLike):
        raise MeshError(
            "load_mesh needs a path or a trimesh.Trimesh/Scene; got"
            f" {type(path_or_trimesh).__name__}"
        )
    path = Path(path_or_trimesh)
    ext = path.suffix.lower()
    if ext not in MESH_FORMATS:
        raise MeshError(
            f"unknown mesh format {ext or '(no extension)'!r} of {path}; voxwarp reads"
            f" {', '.join(MESH_FORMATS)} (convert it, e.g. with trimesh or MeshLab)"
        )
    if not path.is_file():
        raise MeshError(f"no such mesh file: {path}")
    try:
        obj = trimesh.load(str(path), process=False)
    except IndexError as exc:
        raise MeshError(
            f"cannot read mesh file {path}: a face indexes vertices out of range ({exc})"
        ) from exc
    except Exception as exc:  # trimesh raises many kinds on bad files
        raise MeshError(f"cannot read mesh file {path}: {type(exc).__name__}: {exc}") from exc
    v, f = _from_trimesh(obj, str(path), merge=ext == ".stl")
    return Mesh(v, f, name=name or path.stem, source=str(path.resolve()))


# ---------------------------------------------------------------------- generators
# voxwarp's own, not trimesh.creation's: scene JSON stores generated meshes as recipes, and
# trimesh's box (8 shared vertices), uv_sphere (rounded counts, seam copies), cylinder
# (caps sharing the side's vertices) and torus (the other quad diagonal) would change them.
def _check_triangles(generator: str, count: int) -> None:
    """Raise :class:`MeshError` before ``generator`` allocates ``count`` triangles over
    :data:`voxwarp.core.limits.MAX_MESH_TRIANGLES`."""
    if count > MAX_MESH_TRIANGLES:
        raise MeshError(
            f"{generator} would make {count:,} triangles, over the limit of"
            f" {MAX_MESH_TRIANGLES:,}; give fewer sections, rows, cells or subdivisions"
        )


def _generated(v: Any, f: Any, normals: Any, generator: str, **args: Any) -> Mesh:
    return Mesh(v, f, normals, name=generator, recipe={"generator": generator, "args": args})


def box_mesh(
    lo: Sequence[float] = (-0.5, -0.5, -0.5), hi: Sequence[float] = (0.5, 0.5, 0.5)
) -> Mesh:
    """Axis-aligned box [lo, hi]: 24 vertices (4 per side, flat normals), 12 triangles."""
    lo_, hi_ = _vector(lo, 3, "box lo"), _vector(hi, 3, "box hi")
    if np.any(hi_ <= lo_):
        raise MeshError(f"box hi must exceed lo on every axis; got {lo_}, {hi_}")
    center, half = (lo_ + hi_) / 2, (hi_ - lo_) / 2
    eye = np.eye(3)
    # (normal, u, v) with u x v = normal: corners (-u,-v), (u,-v), (u,v), (-u,v) are CCW
    sides = [
        (eye[0], eye[1], eye[2]),
        (-eye[0], eye[2], eye[1]),
        (eye[1], eye[2], eye[0]),
        (-eye[1], eye[0], eye[2]),
        (eye[2], eye[0], eye[1]),
        (-eye[2], eye[1], eye[0]),
    ]
    verts, norms, faces = [], [], []
    for i, (n, u, w) in enumerate(sides):
        for su, sw in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            verts.append(center + (n + su * u + sw * w) * half)
            norms.append(n)
        faces += [(4 * i, 4 * i + 1, 4 * i + 2), (4 * i, 4 * i + 2, 4 * i + 3)]
    return _generated(verts, faces, norms, "box_mesh", lo=lo_.tolist(), hi=hi_.tolist())


def uv_sphere(
    radius: float = 1.0,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    rows: int = 16,
    cols: int = 32,
) -> Mesh:
    """Sphere of ``rows`` latitude bands and ``cols`` meridians (poles on ±z); closed."""
    c = _vector(center, 3, "sphere center")
    rows, cols = int(rows), int(cols)
    if rows < 2 or cols < 3 or not radius > 0:
        raise MeshError(f"uv_sphere needs rows >= 2, cols >= 3, radius > 0; got {rows}, {cols}")
    _check_triangles("uv_sphere", 2 * (rows - 1) * cols)
    theta = np.pi * np.arange(1, rows) / rows
    phi = 2 * np.pi * np.arange(cols) / cols
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack(
        [st * np.cos(phi), st * np.sin(phi), np.broadcast_to(ct, (rows - 1, cols))], axis=-1
    ).reshape(-1, 3)
    n = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]])
    north, south = 0, len(n) - 1
    faces = []
    idx = lambda i, j: 1 + i * cols + j % cols  # noqa: E731 - ring i (0-based), column j
    for j in range(cols):
        faces.append((north, idx(0, j), idx(0, j + 1)))
        for i in range(rows - 2):
            a, b, cc, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            faces += [(a, b, cc), (a, cc, d)]
        faces.append((idx(rows - 2, j), south, idx(rows - 2, j + 1)))
    return _generated(
        c + radius * n,
        faces,
        n,
        "uv_sphere",
        radius=float(radius),
        center=c.tolist(),
        rows=rows,
        cols=cols,
    )


def cylinder_mesh(
    radius: float = 0.5,
    height: float = 1.0,
    sections: int = 32,
    center: Sequence[float] = (0.0, 0.0, 0.0),
    caps: bool = True,
) -> Mesh:
    """Cylinder along z, ``height`` long, centred on ``center``; flat caps (own normals)."""
    c = _vector(center, 3, "cylinder center")
    sections = int(sections)
    if sections < 3 or not radius > 0 or not height > 0:
        raise MeshError("cylinder_mesh needs sections >= 3, radius > 0 and height > 0")
    _check_triangles("cylinder_mesh", 4 * sections)
    phi = 2 * np.pi * np.arange(sections) / sections
    radial = np.stack([np.cos(phi), np.sin(phi), np.zeros(sections)], axis=-1)
    h = height / 2
    verts = [radial * radius + [0, 0, -h], radial * radius + [0, 0, h]]
    norms = [radial, radial]
    faces = []
    for j in range(sections):
        b0, b1, t0, t1 = j, (j + 1) % sections, sections + j, sections + (j + 1) % sections
        faces += [(b0, b1, t1), (b0, t1, t0)]
    if caps:
        base = 2 * sections
        for z, sign in ((h, 1.0), (-h, -1.0)):
            start = base
            verts.append(np.array([[0.0, 0.0, z]]))
            verts.append(radial * radius + [0, 0, z])
            norms.append(np.tile([0.0, 0.0, sign], (sections + 1, 1)))
            for j in range(sections):
                a, b = start + 1 + j, start + 1 + (j + 1) % sections
                faces.append((start, a, b) if sign > 0 else (start, b, a))
            base += sections + 1
    return _generated(
        c + np.concatenate(verts),
        faces,
        np.concatenate(norms),
        "cylinder_mesh",
        radius=float(radius),
        height=float(height),
        sections=sections,
        center=c.tolist(),
        caps=bool(caps),
    )


def torus_mesh(
    major_radius: float = 1.0,
    minor_radius: float = 0.3,
    major_sections: int = 48,
    minor_sections: int = 24,
    center: Sequence[float] = (0.0, 0.0, 0.0),
) -> Mesh:
    """Torus about the z axis; closed."""
    c = _vector(center, 3, "torus center")
    nu, nv = int(major_sections), int(minor_sections)
    if nu < 3 or nv < 3 or not 0 < minor_radius < major_radius:
        raise MeshError(
            "torus_mesh needs sections >= 3 and 0 < minor_radius < major_radius; got"
            f" {major_radius}, {minor_radius}"
        )
    _check_triangles("torus_mesh", 2 * nu * nv)
    u = 2 * np.pi * np.arange(nu) / nu
    v = 2 * np.pi * np.arange(nv) / nv
    uu, vv = np.meshgrid(u, v, indexing="ij")
    n = np.stack([np.cos(vv) * np.cos(uu), np.cos(vv) * np.sin(uu), np.sin(vv)], -1)
    ring = np.stack([np.cos(uu), np.sin(uu), np.zeros_like(uu)], -1)
    p = major_radius * ring + minor_radius * n
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    cc, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    faces = np.concatenate(
        [np.stack([a, b, cc], -1).reshape(-1, 3), np.stack([a, cc, d], -1).reshape(-1, 3)]
    )
    return _generated(
        c + p.reshape(-1, 3),
        faces,
        n.reshape(-1, 3),
        "torus_mesh",
        major_radius=float(major_radius),
        minor_radius=float(minor_radius),
        major_sections=nu,
        minor_sections=nv,
        center=c.tolist(),
    )


def tile_mesh(
    nx: int = 8,
    ny: int = 8,
    size: Sequence[float] = (1.0, 1.0),
    center: Sequence[float] = (0.0, 0.0, 0.0),
) -> Mesh:
    """A flat tile of ``nx`` x ``ny`` quads (2 triangles each) in the plane z = center z,
    ``size`` wide in x and y, normals +z (an open surface)."""
    c = _vector(center, 3, "tile center")
    sx, sy = _vector(size, 2, "tile size")
    nx, ny = int(nx), int(ny)
    if nx < 1 or ny < 1 or sx <= 0 or sy <= 0:
        raise MeshError(f"tile_mesh needs nx, ny >= 1 and a positive size; got {nx}, {ny}")
    _check_triangles("tile_mesh", 2 * nx * ny)
    x = (np.arange(nx + 1) / nx - 0.5) * sx
    y = (np.arange(ny + 1) / ny - 0.5) * sy
    xx, yy = np.meshgrid(x, y, indexing="ij")
    v = np.stack([xx, yy, np.zeros_like(xx)], -1).reshape(-1, 3) + c
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a, b = i * (ny + 1) + j, (i + 1) * (ny + 1) + j
    cc, d = (i + 1) * (ny + 1) + j + 1, i * (ny + 1) + j + 1
    faces = np.concatenate(
        [np.stack([a, b, cc], -1).reshape(-1, 3), np.stack([a, cc, d], -1).reshape(-1, 3)]
    )
    normals = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    return _generated(
        v,
        faces,
        normals,
        "tile_mesh",
        nx=nx,
        ny=ny,
        size=[float(sx), float(sy)],
        center=c.tolist(),
    )


def tube_mesh(
    length: float = 1.0,
    radius: float = 0.25,
    rings: int = 96,
    sections: int = 16,
    ring_x: Sequence[float] | None = None,
    phase: float = 0.0,
) -> Mesh:
    """An open tube along x from 0 to ``length``, axis y = z = 0, ``rings`` rings of
    ``sections`` vertices (tessellated along its length, so a lattice can bend it).

    ``ring_x``: the rings' x positions instead (increasing; ``rings`` is then their
    count); ``phase``: the first vertex of each ring a fraction of a section past the +y
    axis (e.g. 0.25 keeps vertices off the planes y = 0 and z = 0).
    """
    if ring_x is not None:
        x = np.asarray(ring_x, dtype=np.float64)
        if x.ndim != 1 or len(x) < 2 or not np.all(np.isfinite(x)) or np.any(np.diff(x) <= 0):
            raise MeshError("tube_mesh ring_x must be at least 2 finite, increasing x positions")
        rings = len(x)
    rings, sections, phase = int(rings), int(sections), float(phase)
    if rings < 2 or sections < 3 or not math.isfinite(phase):
        raise MeshError(
            f"tube_mesh needs rings >= 2, sections >= 3 and a finite phase; got {rings},"
            f" {sections}, {phase}"
        )
    _check_triangles("tube_mesh", 2 * (rings - 1) * sections)
    if ring_x is None:
        x = np.linspace(0.0, length, rings)
    phi = 2 * np.pi * (np.arange(sections) + phase) / sections
    xx, pp = np.meshgrid(x, phi, indexing="ij")
    n = np.stack([np.zeros_like(pp), np.cos(pp), np.sin(pp)], -1)
    v = np.stack([xx, radius * np.cos(pp), radius * np.sin(pp)], -1)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(sections), indexing="ij")
    a, b = i * sections + j, (i + 1) * sections + j
    c, d = (i + 1) * sections + (j + 1) % sections, i * sections + (j + 1) % sections
    f = np.concatenate(
        [np.stack([a, c, b], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    extra: dict[str, Any] = {}  # recorded only when given: older recipes stay as they were
    if ring_x is not None:
        extra["ring_x"] = x.tolist()
    if phase:
        extra["phase"] = phase
    return _generated(
        v.reshape(-1, 3),
        f,
        n.reshape(-1, 3),
        "tube_mesh",
        length=float(length),
        radius=float(radius),
        rings=int(rings),
        sections=int(sections),
        **extra,
    )


def height_tile(size: float = 1.0, height: float = 0.25, n: int = 24) -> Mesh:
    """A square tile ``size`` wide on z = 0 with a raised rounded boss (up to ``height``)
    and a ridge along its diagonal; its border is flat, so copies meet without gaps."""
    n = int(n)
    if n < 1:
        raise MeshError(f"height_tile needs n >= 1; got {n}")
    _check_triangles("height_tile", 2 * n * n)
    g = np.linspace(0.0, size, n + 1)
    x, y = np.meshgrid(g, g, indexing="ij")
    s = 2.0 * x / size - 1.0
    t = 2.0 * y / size - 1.0
    boss = np.clip(1.0 - (s * s + t * t) / 0.45, 0.0, None) ** 1.5
    ridge = np.clip(1.0 - np.abs(s - t) / 0.25, 0.0, None) * (1.0 - np.maximum(s * s, t * t))
    z = height * np.maximum(boss, 0.6 * ridge)
    v = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a, b = i * (n + 1) + j, (i + 1) * (n + 1) + j
    c, d = (i + 1) * (n + 1) + j + 1, i * (n + 1) + j + 1
    f = np.concatenate(
        [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    )
    return _generated(
        v, f, vertex_normals(v, f), "height_tile", size=float(size), height=float(height), n=int(n)
    )


def box_mesh_tessellated(
    size: Sequence[float] = (1.0, 1.0, 1.0), cells: Sequence[int] = (4, 4, 4)
) -> Mesh:
    """A box [0, size] whose faces are split into ``cells`` quads per axis (so a lattice
    can bend it; :func:`voxwarp.core.mesh.box_mesh` has 2 triangles per face)."""
    size = [float(v) for v in size]
    cells = [int(c) for c in cells]
    if min(cells) < 1 or min(size) <= 0:
        raise MeshError("box_mesh_tessellated needs cells >= 1 and sizes > 0 per axis")
    cx, cy, cz = cells
    _check_triangles("box_mesh_tessellated", 4 * (cx * cy + cy * cz + cx * cz))
    verts, faces, norms = [], [], []
    offset = 0
    for axis in range(3):
        a1, a2 = [d for d in range(3) if d != axis]
        n1, n2 = cells[a1], cells[a2]
        g1 = np.linspace(0.0, size[a1], n1 + 1)
        g2 = np.linspace(0.0, size[a2], n2 + 1)
        p1, p2 = np.meshgrid(g1, g2, indexing="ij")
        for side in (0.0, 1.0):
            v = np.zeros((n1 + 1, n2 + 1, 3))
            v[..., a1], v[..., a2], v[..., axis] = p1, p2, side * size[axis]
            nrm = np.zeros(3)
            nrm[axis] = 1.0 if side else -1.0
            i, j = np.meshgrid(np.arange(n1), np.arange(n2), indexing="ij")
            a = i * (n2 + 1) + j
            b, c, d = (i + 1) * (n2 + 1) + j, (i + 1) * (n2 + 1) + j + 1, i * (n2 + 1) + j + 1
            tri = np.concatenate(
                [np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
            )
            # orient each face outwards
            e1 = v.reshape(-1, 3)[tri[0, 1]] - v.reshape(-1, 3)[tri[0, 0]]
            e2 = v.reshape(-1, 3)[tri[0, 2]] - v.reshape(-1, 3)[tri[0, 0]]
            if np.cross(e1, e2) @ nrm < 0:
                tri = tri[:, ::-1]
            verts.append(v.reshape(-1, 3))
            faces.append(tri + offset)
            norms.append(np.tile(nrm, ((n1 + 1) * (n2 + 1), 1)))
            offset += (n1 + 1) * (n2 + 1)
    return _generated(
        np.concatenate(verts),
        np.concatenate(faces),
        np.concatenate(norms),
        "box_mesh_tessellated",
        size=size,
        cells=cells,
    )


#: Mesh generators by name (scene JSON stores generated meshes as recipes).
GENERATORS = {
    "tube_mesh": tube_mesh,
    "height_tile": height_tile,
    "box_mesh_tessellated": box_mesh_tessellated,
    "box_mesh": box_mesh,
    "uv_sphere": uv_sphere,
    "cylinder_mesh": cylinder_mesh,
    "torus_mesh": torus_mesh,
    "tile_mesh": tile_mesh,
}


# ---------------------------------------------------------------------- instances
def default_box(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's bounding box, widened on flat axes (a flat tile has zero thickness)
    to ±5 % of the largest extent, so the box-normalised coordinate is always defined."""
    lo, hi = mesh.bounds
    extent = hi - lo
    pad = np.where(extent <= 1e-9 * max(float(extent.max()), 1e-30), 0.05 * extent.max(), 0.0)
    return lo - pad, hi + pad


class MeshInstance:
    """One mesh placed in the world by a matrix or a trilinear lattice.

    Parameters
    ----------
    mesh
        The :class:`Mesh`.
    transform
        ``None`` (identity), a 4x4 affine matrix (local -> world), or a
        :class:`voxwarp.deform.lattice.trilinear.TrilinearGrid` mapping the box-normalised
        coordinate
        ``u = (x - lo) / (hi - lo)`` to world. Vertices outside the box continue the
        boundary cells' trilinear maps.
    box
        ``(lo, hi)`` the grid acts on, in the mesh's local coordinates; by default the
        mesh's bounds (flat axes widened, see :func:`default_box`). Ignored by matrices.
    color
        RGBA (straight alpha) in [0, 1]; ``(r, g, b)`` means opaque.
    normal_method
        How a lattice carries vertex normals (GRAPP 2010, section 4.2; see
        :func:`voxwarp.deform.lattice.trilinear.carry_normals`): ``"normal"``, the paper's direct
        transform ``J n`` (smooth across cell faces, not always orthogonal to the
        surface), or ``"tangent"``, two tangents through ``J`` crossed (orthogonal to the
        surface, seams at cell faces; the default, :data:`DEFAULT_NORMAL_METHOD`). A
        matrix has no cell faces: there ``"normal"`` is the exact inverse transpose and
        ``"tangent"`` ``cof(A) n``.
    name
        Display name.
    """

    def __init__(
        self,
        mesh: Mesh,
        transform: Any = None,
        box: tuple[Sequence[float], Sequence[float]] | None = None,
        color: Sequence[float] = DEFAULT_COLOR,
        normal_method: str = DEFAULT_NORMAL_METHOD,
        name: str = "",
    ) -> None:
        if not isinstance(mesh, Mesh):
            raise MeshError(
                f"MeshInstance needs a Mesh (from voxwarp.load_mesh); got {type(mesh).__name__}"
            )
        self.mesh = mesh
        self.transform = transform
        self.box = box
        self.color = color
        self.normal_method = normal_method
        self.name = str(name or mesh.name)

    # ------------------------------------------------------------------ validated attributes
    @property
    def transform(self) -> np.ndarray | TrilinearGrid | None:
        """``None``, a 4x4 float64 affine matrix, or a :class:`TrilinearGrid`."""
        return self._transform

    @transform.setter
    def transform(self, value: Any) -> None:
        if value is None or isinstance(value, TrilinearGrid):
            self._transform = value
            return
        try:
            m = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise MeshError(
                "a mesh instance's transform must be None, a 4x4 matrix or a TrilinearGrid;"
                f" got {type(value).__name__}"
            ) from exc
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise MeshError(
                "a mesh instance's transform must be None, a finite 4x4 matrix or a"
                f" TrilinearGrid; got an array of shape {m.shape}"
            )
        if not np.allclose(m[3], (0, 0, 0, 1), atol=1e-9):
            raise MeshError(
                f"a mesh instance's matrix must be affine (last row 0 0 0 1); got {m[3].tolist()}"
            )
        self._transform = m

    @property
    def box(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) box the grid acts on (local coordinates)."""
        return self._box if self._box is not None else default_box(self.mesh)

    @box.setter
    def box(self, value: Any) -> None:
        if value is None:
            self._box = None
            return
        self._box = finite_box(value, "box", MeshError)

    @property
    def color(self) -> tuple[float, float, float, float]:
        """RGBA in [0, 1] (straight alpha)."""
        return self._color

    @color.setter
    def color(self, value: Sequence[float]) -> None:
        if not hasattr(value, "__len__") or len(value) not in (3, 4):
            raise MeshError(f"color must be (r, g, b) or (r, g, b, a) in [0, 1]; got {value!r}")
        c = _vector(value, len(value), "color")
        if np.any(c < 0) or np.any(c > 1):
            raise MeshError(f"color components must lie in [0, 1]; got {c.tolist()}")
        self._color = (*(float(x) for x in c[:3]), float(c[3]) if len(c) == 4 else 1.0)

    @property
    def normal_method(self) -> str:
        """``"normal"`` or ``"tangent"``."""
        return self._normal_method

    @normal_method.setter
    def normal_method(self, value: str) -> None:
        if value not in NORMAL_METHODS:
            raise MeshError(
                f"normal_method must be one of {', '.join(NORMAL_METHODS)}; got {value!r}"
            )
        self._normal_method = value

    @property
    def is_lattice(self) -> bool:
        """Whether the instance is deformed by a :class:`TrilinearGrid`."""
        return isinstance(self._transform, TrilinearGrid)

    # ------------------------------------------------------------------ geometry
    def matrix(self) -> np.ndarray:
        """The 4x4 local -> world matrix (identity for ``None``); lattices raise."""
        if self.is_lattice:
            raise MeshError(f"instance {self.name!r} is deformed by a lattice, not a matrix")
        return np.eye(4) if self._transform is None else self._transform.copy()

    def box_to_unit(self) -> np.ndarray:
        """4x4 matrix local -> box-normalised coordinate u."""
        lo, hi = self.box
        m = np.eye(4)
        m[:3, :3] = np.diag(1.0 / (hi - lo))
        m[:3, 3] = -lo / (hi - lo)
        return m

    def local_to_world(self, points: Any) -> np.ndarray:
        """CPU reference of the vertex shader: (N, 3) local points -> world (float64)."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.is_lattice:
            lo, hi = self.box
            return np.asarray(self._transform((p - lo) / (hi - lo)), dtype=np.float64)
        m = self.matrix()
        return p @ m[:3, :3].T + m[:3, 3]

    def affine_matrix(self) -> np.ndarray | None:
        """The 4x4 local -> world matrix when the instance is one affine map, else None.

        A matrix (or None: identity), or a lattice whose grid is one affine map
        (:attr:`TrilinearGrid.is_linear`: the paper's parallelepiped check, GRAPP 2010,
        section 4.1), composed with the box normalisation.
        """
        if not self.is_lattice:
            return self.matrix()
        grid = self._transform
        if not grid.is_linear:
            return None
        return grid.matrix() @ self.box_to_unit()

    def world_normals(self, points: Any = None, normals: Any = None) -> np.ndarray:
        """CPU reference of the vertex shader's normals: (N, 3) float64 unit vectors.

        ``points``/``normals``: local positions and normals (default: the mesh's). Lattices
        carry them by their Jacobian as :attr:`normal_method` says
        (:func:`voxwarp.deform.lattice.trilinear.carry_normals`); a matrix by its inverse
        transpose (``"normal"``; the cofactor matrix where it is singular) or its
        cofactor matrix (``"tangent"``).
        """
        p = self.mesh.vertices if points is None else points
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        n = self.mesh.normals if normals is None else normals
        n = np.asarray(n, dtype=np.float64).reshape(-1, 3)
        if self.is_lattice:
            lo, hi = self.box
            jac = np.asarray(self._transform.jacobian((p - lo) / (hi - lo))).reshape(-1, 3, 3)
            return carry_normals(jac / (hi - lo)[None, None, :], n, self.normal_method)
        a = self.matrix()[:3, :3]
        singular = abs(float(np.linalg.det(a))) <= 1e-300
        if self.normal_method == "tangent" or singular:
            m = cofactor_matrix(a)
        else:
            m = np.linalg.inv(a).T
        out = n @ m.T
        with np.errstate(invalid="ignore", divide="ignore"):
            return out / np.linalg.norm(out, axis=1, keepdims=True)

    def world_vertices(self) -> np.ndarray:
        """(N, 3) float64 deformed vertex positions (CPU)."""
        return self.local_to_world(self.mesh.vertices)

    def world_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) box holding the placed mesh.

        Matrices: the transformed corners of the mesh's bounding box. Lattices: the
        grid nodes' box (a trilinear cell stays inside its corners' convex hull) when the
        mesh lies in the instance box, else the bounds of the mapped vertices.
        """
        lo, hi = self.mesh.bounds
        if not self.is_lattice:
            m = self.matrix()
            corners = box_corners(lo, hi)
            w = corners @ m[:3, :3].T + m[:3, 3]
            return w.min(axis=0), w.max(axis=0)
        blo, bhi = self.box
        if np.all(lo >= blo) and np.all(hi <= bhi):
            nodes = np.asarray(self._transform.nodes, dtype=np.float64).reshape(-1, 3)
            return nodes.min(axis=0), nodes.max(axis=0)
        w = self.world_vertices()
        return w.min(axis=0), w.max(axis=0)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self, base_dir: str | os.PathLike | None = None) -> dict[str, Any]:
        """JSON form; the mesh by path, generator recipe or inline (see :meth:`Mesh.to_dict`)."""
        t = self._transform
        if t is None:
            transform = None
        elif isinstance(t, TrilinearGrid):
            transform = {"grid": t.to_dict()}
        else:
            transform = {"matrix": t.tolist()}
        return {
            "mesh": self.mesh.to_dict(base_dir),
            "transform": transform,
            "box": None if self._box is None else [c.tolist() for c in self._box],
            "color": list(self.color),
            "normal_method": self.normal_method,
            "name": self.name,
        }

    @classmethod
    def from_dict(
        cls, d: Mapping[str, Any], base_dir: str | os.PathLike | None = None
    ) -> MeshInstance:
        """Inverse of :meth:`to_dict`; raises :class:`MeshError`."""
        if not isinstance(d, Mapping) or "mesh" not in d:
            raise MeshError("a mesh instance entry must be an object with a 'mesh' key")
        mesh = Mesh.from_dict(d["mesh"], base_dir)
        t = d.get("transform")
        transform: Any = None
        if t is not None:
            if not isinstance(t, Mapping) or not ({"matrix", "grid"} & set(t)):
                raise MeshError("a mesh instance 'transform' must be null, {matrix} or {grid}")
            if "matrix" in t:
                transform = t["matrix"]
            else:
                try:
                    transform = TrilinearGrid.from_dict(t["grid"])
                except (TypeError, ValueError, KeyError) as exc:
                    raise MeshError(f"invalid lattice in mesh instance: {exc}") from exc
        return cls(
            mesh,
            transform,
            box=d.get("box"),
            color=d.get("color", DEFAULT_COLOR),
            normal_method=d.get("normal_method", DEFAULT_NORMAL_METHOD),
            name=str(d.get("name", "")),
        )

    def __repr__(self) -> str:
        kind = (
            "identity"
            if self._transform is None
            else f"lattice {self._transform.shape}"
            if self.is_lattice
            else "matrix"
        )
        return f"MeshInstance({self.name!r}, {self.mesh!r}, {kind})"


#: Colours given to scene-graph leaves in turn (RGBA).
PALETTE = (
    (0.85, 0.82, 0.75, 1.0),
    (0.45, 0.65, 0.9, 1.0),
    (0.9, 0.55, 0.4, 1.0),
    (0.55, 0.8, 0.5, 1.0),
    (0.8, 0.6, 0.85, 1.0),
)


def instances_from_scene_graph(
    root: Any, resolution: int | None = None, normal_method: str = DEFAULT_NORMAL_METHOD
) -> list[MeshInstance]:
    """One :class:`MeshInstance` per scene-graph leaf whose geometry is a mesh.

    Uses :func:`voxwarp.deform.lattice.scene_graph.compose_scene` (GRAPP 2010, section 4.1): each
    leaf
    gets the composition of the transforms on its path from the root, one 4x4 matrix
    when all are linear, else one :class:`TrilinearGrid` over the leaf's box. A leaf's
    geometry may be a :class:`Mesh` (coloured from :data:`PALETTE` in turn) or an
    untransformed :class:`MeshInstance` (its colour and normal method are kept).
    Leaves with other geometry (volumes, ...) are skipped.
    """
    from voxwarp.deform.lattice.scene_graph import compose_scene

    out: list[MeshInstance] = []
    for composed in compose_scene(root, resolution=resolution):
        geom = composed.node.geometry
        if isinstance(geom, MeshInstance):
            if geom.transform is not None:
                raise MeshError(
                    f"scene-graph leaf {composed.node.name!r} holds a MeshInstance with its own"
                    " transform; put the transform on the node and the plain mesh in it"
                )
            mesh, color, method = geom.mesh, geom.color, geom.normal_method
        elif isinstance(geom, Mesh):
            mesh, color, method = geom, PALETTE[len(out) % len(PALETTE)], normal_method
        else:
            continue
        if composed.matrix is not None:
            transform: Any = np.asarray(composed.matrix, dtype=np.float64)
        else:
            transform = composed.grid
        box = composed.box
        out.append(
            MeshInstance(
                mesh,
                transform,
                box=None if box is None else (np.asarray(box[0]), np.asarray(box[1])),
                color=color,
                normal_method=method,
                name=composed.node.name or mesh.name,
            )
        )
    return out


__all__ = [
    "DEFAULT_NORMAL_METHOD",
    "GENERATORS",
    "MESH_EMBED_LIMIT_BYTES",
    "MESH_FORMATS",
    "NORMAL_METHODS",
    "Mesh",
    "MeshInstance",
    "MeshWarning",
    "box_mesh",
    "box_mesh_tessellated",
    "cylinder_mesh",
    "default_box",
    "height_tile",
    "instances_from_scene_graph",
    "load_mesh",
    "tile_mesh",
    "torus_mesh",
    "tube_mesh",
    "uv_sphere",
    "vertex_normals",
]
