"""The :class:`WireFieldWarp`: the CPU reference of the wire mapping, its GLSL
constants, uniforms and textures, bounds, and its scene-JSON form."""

from __future__ import annotations

import threading
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from voxwarp.deform import gl_holders
from voxwarp.deform.warp import Warp, WarpError, check_forward, register_warp
from voxwarp.deform.wires.build import WireDeformer
from voxwarp.deform.wires.constants import (
    FAR,
    FIELD_SCALES,
    LAYOUTS,
    LUT_SIZE,
    MAX_WIRES,
    PACKED_VACATED,
    PAPER_MAX_SEGMENTS,
    PAPER_MAX_WIRES,
    PAPER_VACATED,
    PROPAGATE_MODES,
)
from voxwarp.deform.wires.field_bounds import FieldBounds
from voxwarp.deform.wires.layouts import (
    WireField,
    WireFieldStats,
    _sample_t_float,
    _sample_t_packed,
    _sample_t_paper,
    _trilinear_gradient,
)
from voxwarp.deform.wires.tables import _lerp_table, map_points
from voxwarp.deform.wires.wire import Wire


def _newton_forward(warp: Warp, p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Newton steps on ``warp.apply(p) = x`` from ``p`` (the base class's iteration from
    a given seed); unconverged points are left for :func:`check_forward`."""
    p = p.copy()
    for _ in range(warp.forward_steps):
        r = warp.apply(p) - x
        bad = np.linalg.norm(r, axis=1) > warp.forward_tolerance
        if not np.any(bad):
            break
        j = warp.jacobian(p[bad])
        ok = np.abs(np.linalg.det(j)) > 1e-12
        step = r[bad].copy()
        step[ok] = np.linalg.solve(j[ok], r[bad][ok][..., None])[..., 0]
        p[bad] -= step
    return p


#: makes one FieldBounds per field when two threads ask at once (the GUI's skip-map
#: worker and its support)
_BOUNDS_LOCK = threading.Lock()


@register_warp
class WireFieldWarp(Warp):
    """The warp of a wire attribute field (see :mod:`voxwarp.deform.wires`).

    Made by :meth:`WireDeformer.warp`; loaded from scene JSON it holds the wires and
    field parameters only, and builds its field when the scene binds the volume
    (:meth:`bind_volume`).
    """

    kind = "wires"
    glsl_file = "warp_wire.glsl"

    def __init__(
        self, deformer: WireDeformer | None = None, spec: Mapping[str, Any] | None = None
    ) -> None:
        self._deformer = deformer
        self._spec = dict(spec) if spec is not None else None
        self._field: WireField | None = deformer.field if deformer is not None else None
        self._revision = 0
        self._gpu: dict[int, tuple[Any, int, dict[str, Any]]] = {}
        self._bounds: FieldBounds | None = None

    # ------------------------------------------------------------------ state
    @property
    def deformer(self) -> WireDeformer:
        """The :class:`WireDeformer` behind this warp (after :meth:`bind_volume`)."""
        if self._deformer is None:
            raise WarpError(
                "this wire warp has no volume yet: load it through a scene (Scene.from_dict"
                " binds the volume) or call bind_volume(volume)"
            )
        return self._deformer

    @property
    def wires(self) -> list[Wire]:
        """The wires (live: edit them, then :meth:`rebuild`)."""
        return self.deformer.wires

    @property
    def field(self) -> WireField:
        """The current attribute field."""
        if self._field is None:
            self.deformer.build()
            self._field = self.deformer.field
        assert self._field is not None
        return self._field

    def _set_field(self, fld: WireField) -> None:
        self._field = fld
        self._revision += 1
        self._bounds = None

    def rebuild(self) -> WireFieldStats:
        """Rebuild the field after editing :attr:`wires` (the revision changes)."""
        return self.deformer.build()

    def bind_volume(self, volume: Any) -> None:
        """Build the field on ``volume`` (scene loading); no-op if already built on it."""
        if self._deformer is not None and self._deformer.data is getattr(volume, "data", None):
            return
        spec = self._spec if self._spec is not None else _deformer_spec(self.deformer)
        wires = [Wire.from_dict(w) for w in spec["wires"]]
        self._deformer = WireDeformer(
            volume,
            wires,
            field_scale=spec.get("field_scale", 2),
            layout=spec.get("layout", "float"),
            masks=spec.get("masks", True),
            mask_resolution=spec.get("mask_resolution"),
            dilation=spec.get("dilation", 1),
            propagate=spec.get("propagate", "region"),
        )
        self._deformer._warp = self
        self._deformer.build()

    @property
    def revision(self) -> int:
        """Changes with every rebuild of the field."""
        return self._revision

    # ------------------------------------------------------------------ CPU reference
    def _lookup(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per point: state (0 identity, 1 vacated, 2 swept), wire id and table t."""
        fld = self.field
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        g = (p - fld.lo) / fld.spacing
        shape = np.asarray(fld.shape)
        inside = np.all((g >= 0) & (g < shape), axis=1)
        state = np.zeros(len(p), dtype=np.uint8)
        wire = np.zeros(len(p), dtype=np.int64)
        t = np.zeros(len(p))
        gi = g[inside]
        v = np.floor(gi).astype(np.int64)
        if fld.layout == "float":
            assert fld.state is not None
            assert fld.t is not None
            s = fld.state[v[:, 0], v[:, 1], v[:, 2]].astype(np.int64)
            st = np.minimum(s, 2)
            sw = s >= 2
            w = np.where(sw, s - 2, 0)
            tt = np.zeros(len(gi))
            if sw.any():
                tt[sw] = _sample_t_float(fld.t, gi[sw])
        elif fld.layout == "packed":
            assert fld.code is not None
            c = fld.code[v[:, 0], v[:, 1], v[:, 2]].astype(np.int64)
            sw = (c & 0x8000) != 0
            st = np.where(sw, 2, np.where(c == PACKED_VACATED, 1, 0))
            w = (c >> 8) & 0x7F
            tt = np.zeros(len(gi))
            if sw.any():
                tt[sw] = _sample_t_packed(fld.code, gi[sw], w[sw])
        else:
            assert fld.code is not None
            assert fld.segments is not None
            c = fld.code[v[:, 0], v[:, 1], v[:, 2]].astype(np.int64)
            sw = (c & 0x8000) != 0
            st = np.where(sw, 2, np.where(c == PAPER_VACATED, 1, 0))
            w = (c >> 11) & 0xF
            tt = np.zeros(len(gi))
            if sw.any():
                tt[sw] = _sample_t_paper(fld.code, gi[sw], w[sw], fld.segments)
        state[inside], wire[inside], t[inside] = st, w, tt
        return state, wire, t

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Deformed -> original, as the shader does (vacated points go to :data:`FAR`)."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        return self._swept(p, *self._lookup(p))

    def apply_carried(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`apply` and :meth:`carried` from one field lookup."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        state, wire, t = self._lookup(p)
        return self._swept(p, state, wire, t), state != 1

    def _swept(
        self, p: np.ndarray, state: np.ndarray, wire: np.ndarray, t: np.ndarray
    ) -> np.ndarray:
        """:meth:`apply` of points ``p`` whose :meth:`_lookup` is given."""
        out = p.copy()
        out[state == 1] = FAR
        for wi in np.unique(wire[state == 2]):
            sel = (state == 2) & (wire == wi)
            out[sel] = map_points(self.field.tables[int(wi)], t[sel], p[sel])
        weight = self._weight(p, state)
        if weight is not None:  # smooth ends: p + w (sweep(p) - p), as the shader
            out[state == 2] = p[state == 2] + weight[:, None] * (out[state == 2] - p[state == 2])
        return out

    def carried(self, points: np.ndarray) -> np.ndarray:
        """False at vacated points (:meth:`vacated`), True elsewhere."""
        return ~self.vacated(points)

    def _weight(self, p: np.ndarray, state: np.ndarray) -> np.ndarray | None:
        """Displacement weight of the swept points among p (trilinear, as the GPU's
        filtered texture), or None when every wire is rigid."""
        fld = self.field
        if fld.weight is None:
            return None
        return _sample_t_float(fld.weight, (p[state == 2] - fld.lo) / fld.spacing)

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Original -> deformed for (N, 3) points (mm): meshes follow the swept object.

        A point the deformed volume shows in place (``apply(x) = x``) stays. Any other
        is seeded by the closed-form inverse of the sweep: its fraction u on the base
        wire is where the base wire's normal plane passes through it (``(x - C(u))
        . T_b(u) = 0``, interpolated between table entries), and the seed is
        ``A(u)^-1 (x - b(u))`` near the modified wire; Newton steps with
        :meth:`jacobian` then remove what the field's coarse t adds, down to
        :attr:`forward_tolerance`. Points neither in place nor swept (the vacated
        region, beyond the wire's reach) raise :class:`WarpError`
        (:func:`~voxwarp.deform.warp.check_forward`).
        """
        x = np.atleast_2d(np.asarray(points, dtype=np.float64))
        p = x.copy()
        moved = ~(np.linalg.norm(self.apply(x) - x, axis=1) <= self.forward_tolerance)
        if np.any(moved):
            seed = self._sweep_seed(x[moved])
            p[moved] = _newton_forward(self, seed, x[moved])
        return check_forward(self, p, x)

    def _sweep_seed(self, x: np.ndarray) -> np.ndarray:
        """Closed-form forward of each point by the wire whose base plane through it
        lies nearest to the base wire (the point itself where no plane passes)."""
        best = np.full(len(x), np.inf)
        out = x.copy()
        for tab in self.field.tables:
            normal = tab.base_frames[:, :, 2]  # (n, 3) base tangents
            for lo in range(0, len(x), 4096):
                q = x[lo : lo + 4096]
                side = np.einsum("mnk,nk->mn", q[:, None, :] - tab.base_points[None], normal)
                cross = (side[:, :-1] >= 0) & (side[:, 1:] < 0)
                i = np.arange(tab.size - 1)[None, :]
                frac = side[:, :-1] / np.where(cross, side[:, :-1] - side[:, 1:], 1.0)
                t = np.where(cross, i + frac, np.nan)
                near = _lerp_table(tab.base_points, np.nan_to_num(t).ravel()).reshape(*t.shape, 3)
                dist = np.where(cross, np.linalg.norm(q[:, None, :] - near, axis=2), np.inf)
                k = np.argmin(dist, axis=1)
                d = dist[np.arange(len(q)), k]
                sel = d < best[lo : lo + 4096]
                if not np.any(sel):
                    continue
                a, b = tab.lookup(t[np.arange(len(q)), k][sel])
                seed = np.linalg.solve(a, (q[sel] - b)[..., None])[..., 0]
                rows = np.flatnonzero(sel) + lo
                out[rows], best[rows] = seed, d[sel]
        return out

    def jacobian(self, points: np.ndarray, eps: float = 1e-3) -> np.ndarray:
        """d apply / d p: A(t) where swept (section 6.1), the identity elsewhere.

        Where the displacement is weighted (smooth sides or ends) it is
        ``I + w (A - I) + (A p + b - p) (x) grad w``, with grad w the exact gradient of
        the trilinear weight (so shading and normals are right in the fade). The terms
        through t's own gradient (``w (dA/dt p + db/dt) (x) grad t``) are left out, as
        the paper does (section 6.1): they vanish on straight parts of the wire and
        grow with its curvature times the distance from it."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        state, wire, t = self._lookup(p)
        out = np.broadcast_to(np.eye(3), (len(p), 3, 3)).copy()
        moved = np.zeros((len(p), 3))
        for wi in np.unique(wire[state == 2]):
            sel = (state == 2) & (wire == wi)
            a, b = self.field.tables[int(wi)].lookup(t[sel])
            out[sel] = a
            moved[sel] = np.einsum("nij,nj->ni", a, p[sel]) + b - p[sel]
        weight = self._weight(p, state)
        if weight is not None:
            sw = state == 2
            fld = self.field
            assert fld.weight is not None
            grad = _trilinear_gradient(fld.weight, (p[sw] - fld.lo) / fld.spacing) / fld.spacing
            out[sw] = np.eye(3) + weight[:, None, None] * (out[sw] - np.eye(3))
            out[sw] += moved[sw][:, :, None] * grad[:, None, :]
        return out

    def vacated(self, points: np.ndarray) -> np.ndarray:
        """Which deformed-space points show nothing because a rigid sweep vacated them
        (``sides="rigid"``, ``vacated="empty"``; :meth:`apply` sends them to
        :data:`FAR`): bool per point. Always False for smooth sides or
        ``vacated="rest"``."""
        return self._lookup(points)[0] == 1

    def wire_shortfall(self) -> float:
        """How far (mm) the content on the modified wires lands from the base wires'
        points it should show: the largest ``|apply(M(u)) - C(u)|`` over each wire's table
        points. About a field voxel when the sweep is whole; more where the seam fade
        (:mod:`voxwarp.deform.wires.seams`) took some of the move away."""
        worst = 0.0
        for tab in self.field.tables:
            got = self.apply(tab.modified_points)
            ok = np.all(np.isfinite(got), axis=1) & (np.abs(got) < FAR / 2).all(axis=1)
            if ok.any():
                err = np.linalg.norm(got[ok] - tab.base_points[ok], axis=1)
                worst = max(worst, float(err.max()))
        return worst

    def swept(self, points: np.ndarray) -> np.ndarray:
        """Which deformed-space points are swept by a wire (bool per point)."""
        return self._lookup(points)[0] == 2

    # ------------------------------------------------------------------ bounds
    def deformed_bounds(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The original box grown by the field box (a swept object may leave the box)."""
        fld = self.field
        return np.minimum(lo, fld.lo), np.maximum(hi, fld.hi)

    @property
    def bounds_displacement(self) -> bool:
        """True: intervals come from the field."""
        return True

    def displacement_range(
        self, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Per box, an interval holding ``apply(p) - p`` over the samples that can show
        something (vacated samples show nothing and are left out).

        A box whose swept voxels belong to one wire gets that wire's mapping bounded
        over the box itself for every t its samples can interpolate (the range of t
        over its voxels' 3³ neighbourhoods): the mapping is linear in p, and linear in t
        between table entries, so the extremes lie at the box's corners and at the
        entries in that range. Boxes without swept voxels move nothing; boxes reaching
        outside the propagated region also hold 0 (:class:`FieldBounds`).
        """
        return self._field_bounds().displacement_range(lo, hi)

    def support_bricks(self, lo: np.ndarray, hi: np.ndarray, tol: float) -> np.ndarray:
        """:meth:`Warp.support_bricks`, and every box holding a vacated voxel: the
        object has left it, so a straight sample there would show it again (a ghost
        of the moved part); the chain sends such samples far away."""
        moved = super().support_bricks(lo, hi, tol)
        vacated = self._field_bounds().any_vacated(lo, hi)
        return moved if vacated is None else np.asarray(moved, dtype=bool) | vacated

    def _field_bounds(self) -> FieldBounds:
        """The bounds of the current field (made once per revision, by one thread)."""
        fld = self.field
        with _BOUNDS_LOCK:
            if self._bounds is None or self._bounds.field is not fld:
                self._bounds = FieldBounds(fld)
            return self._bounds

    # ------------------------------------------------------------------ GPU side
    def glsl_constants(self) -> dict[str, Any]:
        """The layout (``#define WARP_LAYOUT_PACKED 0|1``, ``WARP_LAYOUT_PAPER 0|1``),
        table size and the far point."""
        return {
            "LAYOUT_PACKED": "1" if self.field.layout == "packed" else "0",
            "LAYOUT_PAPER": "1" if self.field.layout == "paper" else "0",
            "SMOOTH": "1" if self.field.weight is not None else "0",
            "LUT_SIZE": LUT_SIZE,
            "FAR": FAR,
        }

    def signature(self) -> str:
        """Kind and layout (the layouts compile differently)."""
        smooth = ":smooth" if self.field.weight is not None else ""
        return f"{self.kind}:{self.field.layout}{smooth}"

    def uniforms(self) -> dict[str, Any]:
        """Field box, shape and lookup-table rows (and the paper layout's segment
        starts, ``PAPER_MAX_WIRES`` rows of ``PAPER_MAX_SEGMENTS + 1``, as one array)."""
        fld = self.field
        out: dict[str, Any] = {
            "lo": tuple(float(v) for v in fld.lo),
            "size": tuple(float(v) for v in fld.hi - fld.lo),
            "shape": tuple(float(v) for v in fld.shape),
            "rows": float(3 * len(fld.tables)),
        }
        if fld.layout == "paper":
            assert fld.segments is not None
            seg = np.zeros((PAPER_MAX_WIRES, PAPER_MAX_SEGMENTS + 1), dtype=np.float32)
            seg[: len(fld.segments)] = fld.segments
            out["seg"] = seg.ravel()
        return out

    def textures(self, ctx: Any) -> dict[str, Any]:
        """The field (``state`` + ``t``, or ``code``) and ``lut`` textures on ``ctx``,
        uploaded on first use and after each rebuild."""
        entry = self._gpu.get(id(ctx))
        if entry is not None and entry[0] is ctx and entry[1] == self._revision:
            return entry[2]
        if entry is not None and entry[0] is ctx:
            for tex in entry[2].values():
                tex.release()
        fld = self.field
        texs: dict[str, Any] = {}
        max_3d = int(ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        if max(fld.shape) > max_3d:  # GL would fail silently (GL_INVALID_VALUE)
            axis = int(np.argmax(fld.shape))
            raise WarpError(
                f"the wire attribute field is {'x'.join(map(str, fld.shape))} voxels: axis"
                f" {axis} ({'xyz'[axis]}) is over the GPU's maximum 3D texture size {max_3d};"
                " use a larger field_scale (--field-scale) or keep the wires near the volume"
            )

        def tex3d(a: np.ndarray, dtype: str, linear: bool) -> Any:
            t = ctx.texture3d(fld.shape, 1, np.asfortranarray(a).tobytes(order="F"), dtype=dtype)
            f = ctx.LINEAR if linear else ctx.NEAREST
            t.filter = (f, f)
            t.repeat_x = t.repeat_y = t.repeat_z = False
            return t

        if fld.layout == "float":
            assert fld.state is not None
            assert fld.t is not None
            texs["state"] = tex3d(fld.state, "u1", False)
            texs["t"] = tex3d(fld.t, "f4", True)
        else:
            assert fld.code is not None
            texs["code"] = tex3d(fld.code, "u2", False)
        if fld.weight is not None:
            texs["weight"] = tex3d(fld.weight, "f4", True)
        rows = np.concatenate([tab.gpu_rows() for tab in fld.tables], axis=0)
        lut = ctx.texture((LUT_SIZE, rows.shape[0]), 4, rows.tobytes(), dtype="f4")
        lut.filter = (ctx.LINEAR, ctx.LINEAR)
        lut.repeat_x = lut.repeat_y = False
        texs["lut"] = lut
        self._gpu[id(ctx)] = (ctx, self._revision, texs)
        gl_holders.hold(ctx, self)
        return texs

    def release(self) -> None:
        """Free the GPU textures; idempotent."""
        for _, _, texs in self._gpu.values():
            for tex in texs.values():
                tex.release()
        self._gpu.clear()

    def release_context(self, ctx: Any) -> None:
        """Free the textures on ``ctx`` alone (``ctx`` current); idempotent."""
        entry = self._gpu.pop(id(ctx), None)
        if entry is not None and entry[0] is ctx:
            for tex in entry[2].values():
                tex.release()

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """The wires and field parameters (the field is rebuilt from the volume on load)."""
        spec = self._spec if self._deformer is None else _deformer_spec(self._deformer)
        assert spec is not None
        return {"type": self.kind, **spec}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> WireFieldWarp:
        """An unbuilt warp from :meth:`to_dict` output (validated now, built on
        :meth:`bind_volume`)."""
        wires = d.get("wires")
        if not isinstance(wires, Sequence) or isinstance(wires, str) or not wires:
            raise WarpError("a 'wires' warp needs 'wires': a non-empty list of wire objects")
        if len(wires) > MAX_WIRES:
            raise WarpError(f"at most {MAX_WIRES} wires fit one attribute field; got {len(wires)}")
        unknown = set(d) - {"type", *SPEC_KEYS}
        if unknown:
            raise WarpError(f"unknown keys {sorted(unknown)} in a 'wires' warp")
        for w in wires:
            Wire.from_dict(w)  # validate now: errors name the problem at load time
        scale = d.get("field_scale", 2)
        if scale not in FIELD_SCALES:
            raise WarpError(f"field_scale must be one of {FIELD_SCALES}; got {scale!r}")
        layout = d.get("layout", "float")
        if layout not in LAYOUTS:
            raise WarpError(f"layout must be one of {LAYOUTS}; got {layout!r}")
        if layout == "paper" and len(wires) > PAPER_MAX_WIRES:
            raise WarpError(
                f"layout='paper' holds at most {PAPER_MAX_WIRES} wires (4-bit wire id); got"
                f" {len(wires)}: use layout='packed'"
            )
        propagate = d.get("propagate", "region")
        if propagate not in PROPAGATE_MODES:
            raise WarpError(f"propagate must be one of {PROPAGATE_MODES}; got {propagate!r}")
        spec = {k: d[k] for k in SPEC_KEYS if k in d}
        return cls(spec=spec)


#: keys of a ``"wires"`` warp entry besides ``"type"`` (:meth:`WireFieldWarp.from_dict`)
SPEC_KEYS: tuple[str, ...] = (
    "wires",
    "field_scale",
    "layout",
    "masks",
    "mask_resolution",
    "dilation",
    "propagate",
)


def _deformer_spec(deformer: WireDeformer) -> dict[str, Any]:
    spec = {
        "wires": [w.to_dict() for w in deformer.wires],
        "field_scale": deformer.field_scale,
        "layout": deformer.layout,
        "masks": deformer.masks,
        "mask_resolution": deformer.mask_resolution,
        "dilation": deformer.dilation,
    }
    if deformer.propagate != "region":  # written only when not the default
        spec["propagate"] = deformer.propagate
    return spec
