"""The warp chain's support on the GPU: where rays and slices must pay for the chain.

:func:`voxwarp.deform.support.chain_support` says which bricks of the deformed ray box
the chain may move a point of by more than a tolerance; :class:`SupportCache` (one per
renderer or slice renderer) builds that map when a warp state is first drawn, keeps it
and its R8 texture until a warp's revision (or uniforms) changes, and tells the draw how
to use it (:meth:`SupportCache.plan`):

* ``"none"``: nothing moves beyond the tolerance anywhere; the scene is drawn as if it had
  no warps (straight rays, the undeformed image);
* ``"map"``: the shaders march straight outside the support and pay for the chain only
  inside (``SUPPORT_MAP``): shaders/raycast.frag.glsl by the box around the support
  bricks (three loops per ray: straight, chained, straight), shaders/slice.frag.glsl by
  the brick texture per pixel;
* ``"all"``: the chain may move every brick (or cannot bound itself), or more than
  :data:`MAP_MAX_FRACTION` of them (the map's loops would cost more than they save):
  the chain at every sample. The renderer also draws "all" where its warped skip maps
  say the mode sees less than :data:`MAP_MIN_VISIBLE` of the cells (a nearly empty
  view, where the map's loops cost more than the few chained samples they save).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.core.heap import return_freed_memory
from voxwarp.deform.identity import token
from voxwarp.deform.support import SupportMap, chain_support

if TYPE_CHECKING:
    from voxwarp.scene import Scene

#: default tolerance in voxels (of the finest spacing): a point moved less than this is
#: sampled where a straight ray samples it
TOLERANCE_VOXELS = 1e-3
#: a box in deformed world (mm): (lo, hi)
Box = tuple[np.ndarray, np.ndarray]
#: brick edge in voxels (of the finest spacing), before the MAX_BRICKS cap
BRICK_VOXELS = 4
#: the map path's three loops per ray cost more than they save once most rays chain
#: most of their samples anyway: a support of more than this share of the bricks is
#: drawn with the chain at every sample ("all"). On llvmpipe, 512² dvr: a drag whose
#: support holds 24 % of the bricks (the MRI head) costs 0.86x of "all" on the map path,
#: one holding 46 % (the stent CT) 1.13x (docs/benchmarks.md, "Per-ray ranges")
MAP_MAX_FRACTION = 0.35
#: ... and a view in which the mode can see fewer than this share of the deformed-space
#: cells is drawn with the chain everywhere too: its rays visit so few samples that the
#: chain costs little, while each of the map path's three loops costs every ray a pass
#: of its body on a CPU rasteriser (llvmpipe, 512² dvr, a ChainMail drag on two scans
#: and six transfer functions: "all" was faster at 0.1 % and 0.7 % visible cells, by
#: 1.4-1.6x; the map path at 1.5 % and above, or even at 4.9 %; docs/benchmarks.md,
#: "Nearly empty views draw the chain everywhere")
MAP_MIN_VISIBLE = 0.01


def warp_state_key(scene: Scene) -> tuple:
    """What a chain's derived maps depend on: each warp's identity, GLSL variant,
    revision and uniform values (exact bytes: ``repr`` of a numpy array elides the
    middle of a long one and took ~1 ms per array per draw)."""
    return tuple(
        (token(w), w.signature(), w.revision, uniforms_key(w.uniforms())) for w in scene.warps
    )


def uniforms_key(uniforms: dict[str, Any]) -> tuple:
    """A hashable, exact key of a warp's uniform values (name, dtype, shape, bytes)."""
    out = []
    for name in sorted(uniforms):
        a = np.asarray(uniforms[name])
        if a.dtype == object:
            out.append((name, repr(uniforms[name])))
        else:
            out.append((name, a.dtype.str, a.shape, a.tobytes()))
    return tuple(out)


class SupportCache:
    """The support brick map of the last warp state drawn, and its texture.

    ``ctx``: the moderngl context the texture is made on. :attr:`enabled` False (or the
    environment variable ``VOXWARP_SUPPORT_SKIPPING=0`` when the owner reads it) keeps
    the old path, for comparisons in one process.
    """

    def __init__(self, ctx: Any, *, enabled: bool = True) -> None:
        self.ctx = ctx
        #: march straight outside the chain's support (off: the chain at every sample)
        self.enabled = bool(enabled)
        #: when a warp state's map is built: "auto" when it is drawn a second time (a
        #: state that changes every frame, as while dragging, is drawn with the chain
        #: everywhere and costs no map, nor a GPU model's field read-back), "always" on
        #: its first draw, "never" not at all (while the user interacts: the slice views
        #: draw each state three times; a state drawn then counts as seen for "auto")
        self.build = "auto"
        self._seen: Any = None
        #: tolerance in voxels of the finest spacing
        self.tolerance_voxels = TOLERANCE_VOXELS
        #: the largest share of bricks in the support drawn by the map path; above it
        #: "all" (see MAP_MAX_FRACTION)
        self.map_max_fraction = MAP_MAX_FRACTION
        self._key: Any = None
        self._map: SupportMap | None = None
        self._texture: Any = None

    def support(self, scene: Scene, box: Box | None = None) -> SupportMap:
        """The support of ``scene``'s chain over ``box`` (default: its ray box), built
        once per warp state and box."""
        return self._support(scene, box, self._state_key(scene, box))

    def _support(self, scene: Scene, box: Box | None, key: tuple) -> SupportMap:
        if key != self._key or self._map is None:
            lo, hi = scene.ray_bounds() if box is None else box
            voxel = float(np.min(scene.volume.spacing))
            self._drop_texture()
            self._map = chain_support(
                list(scene.warps), lo, hi, BRICK_VOXELS * voxel, self.tolerance_voxels * voxel
            )
            self._key = key
            return_freed_memory()  # the warps' bound pyramids' temporaries
        return self._map

    def _state_key(self, scene: Scene, box: Box | None) -> tuple:
        lo, hi = scene.ray_bounds() if box is None else box
        tol = self.tolerance_voxels * float(np.min(scene.volume.spacing))
        return (warp_state_key(scene), tuple(lo), tuple(hi), tol)

    def plan(self, scene: Scene, box: Box | None = None, *, draw: bool = True) -> str:
        """How a draw of ``scene`` (a non-affine chain) uses the support over ``box``:
        "none", "map" or "all" (see the module docstring). With :attr:`build` "auto",
        the first draw of a warp state gets "all", with "never" every draw of a state
        without a map (``draw`` False: a question that is no draw, which neither builds
        the map nor counts as one)."""
        if not self.enabled or not scene.warps:
            return "all"
        key = self._state_key(scene, box)
        if key != self._key and self.build == "never":
            self._seen = key if draw else self._seen
            return "all"
        if key != self._key and (self.build == "auto" or not draw):
            if not draw or key != self._seen:
                self._seen = key if draw else self._seen
                return "all"
        fraction = self._support(scene, box, key).fraction
        if fraction == 0.0:
            return "none"
        return "map" if fraction <= self.map_max_fraction else "all"

    def texture(self, scene: Scene, box: Box | None = None) -> Any:
        """The R8 texture of the support (1 = brick in the support), nearest filtering."""
        smap = self.support(scene, box)
        if self._texture is None:
            data = np.ascontiguousarray(smap.moved.transpose(2, 1, 0), dtype=np.uint8) * 255
            self._texture = self.ctx.texture3d(smap.moved.shape, 1, data, dtype="f1", alignment=1)
            self._texture.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        return self._texture

    def uniforms(self, scene: Scene, box: Box | None = None) -> dict[str, Any]:
        """The shaders' view of the support map: ``u_world_to_support`` and
        ``u_support_dims`` (the bricks, for a texture lookup), ``u_support_lo`` and
        ``u_support_hi`` (the box around the support bricks, widened by a thousandth of a
        brick against rounding) and ``u_straight_to_texel`` (deformed world -> texel of
        a straight ray)."""
        smap = self.support(scene, box)
        around = smap.moved_box()
        lo, hi = (smap.lo, smap.hi) if around is None else around
        pad = 1e-3 * smap.size
        return {
            "u_world_to_support": smap.world_to_brick(),
            "u_support_dims": tuple(int(n) for n in smap.moved.shape),
            "u_support_lo": lo - pad,
            "u_support_hi": hi + pad,
            "u_straight_to_texel": scene.volume.world_to_texel_matrix(),
        }

    def _drop_texture(self) -> None:
        if self._texture is not None:
            self._texture.release()
            self._texture = None

    def release(self) -> None:
        """Free the texture (idempotent)."""
        self._drop_texture()
        self._map = None
        self._key = None
