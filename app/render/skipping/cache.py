"""When the raycaster's empty-space skip maps are built, kept, reused and dropped.

The maths of the maps is :mod:`voxwarp.render.skipping.maps`; this module is their cache
policy, for :class:`voxwarp.render.raycaster.Renderer`:

* :class:`VolumeSkipMaps` holds one volume's maps (GPU textures and the CPU arrays they
  are made from), kept with the volume's texture.
* :class:`SkipMapCache` (one per renderer) decides per draw which skipping a scene uses
  (:meth:`SkipMapCache.kind`), builds or reuses the textures of that kind, drops them
  when what the mode can see or the warp state changes, and, with ``warped_skip_maps``
  "background", hands the CPU work of warped maps to a worker thread
  (:meth:`SkipMapCache.take_job`, :meth:`SkipMapCache.install`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.core.heap import return_freed_memory
from voxwarp.deform.warp import fold_affine
from voxwarp.errors import RenderError
from voxwarp.render.skipping.bitmask import BitMask
from voxwarp.render.skipping.maps import (
    WARPED_COMPILED_MIN_SIZE,
    Octant,
    block_skip_distances,
    cell_grid_shape,
    cell_visibility,
    coarsen_visibility,
    octant_skip_distances,
    skip_map_key,
    static_block_visibility,
    warped_cell_grid,
    warped_cell_visibility,
)
from voxwarp.render.skipping.segments import RaySegments, SegmentMap, segment_lengths
from voxwarp.render.skipping.support import warp_state_key

if TYPE_CHECKING:
    from voxwarp.scene import Scene

#: modes whose visibility is sparse enough for cell-resolution skipping
SPARSE_MODES = ("dvr", "iso", "flm")
#: with ``cell_skip_maps`` "auto", the straight-ray cell maps of a volume of more trilinear
#: cells than this are built when it is drawn a second time (see SkipMapCache.kind)
EAGER_CELLS = 1 << 22
#: with ``coarse_cell_maps`` "auto", the straight-ray octant maps of a volume of more
#: trilinear cells than COARSE_MIN_CELLS are kept per COARSE_FACTOR³ cells (see
#: SkipMapCache.cell_factor): from about 322³ voxels, where one map of uint8 would take
#: 32 MiB, as the slice layers take over from slice pairs; below it the per-cell maps
#: skip more (the coarse ones cost the bundled 128x128x256 stent ~12 % of a frame)
COARSE_MIN_CELLS = 1 << 25
COARSE_FACTOR = 2


class VolumeSkipMaps:
    """The skip maps of one volume: a GPU block-info texture, per-octant R8 cell textures
    (straight and warped rays) and the CPU arrays they come from.

    Made beside the volume's texture from its data and block (min, max) grids
    (:func:`voxwarp.render.skipping.maps.block_min_max`); only a :class:`SkipMapCache` fills it.
    Free its textures with :meth:`release` while the context is current.
    """

    def __init__(
        self, ctx: Any, data: np.ndarray, block_min: np.ndarray, block_max: np.ndarray
    ) -> None:
        block_min, block_max = _compact_ranges(data, block_min, block_max)
        self.block_min, self.block_max = block_min, block_max
        # block info texture (skip distance, min, max, 0), written once a mode is known;
        # half floats where they hold every value exactly (uint8 data: half the bytes)
        info_dtype = "f2" if _half_exact(block_min, block_max) else "f4"
        self.info = ctx.texture3d(block_min.shape, 4, dtype=info_dtype)
        self.info.filter = (ctx.NEAREST, ctx.NEAREST)
        self.info_key: Any = None
        self.volume_data = data
        #: the cell visibility the octant maps are built from, one bit per cell (BitMask),
        #: per visible_factor³ cells (coarsen_visibility: kept coarse for coarse maps)
        self.cell_visible: BitMask | None = None
        self.visible_factor = 1
        #: octant -> R8 texture of octant skip distances, for the scene key cell_key
        self.cell_skip: dict[Octant, Any] = {}
        self.cell_key: Any = None
        #: cells per edge of a cell_skip map's cells (1, or COARSE_FACTOR for big volumes)
        self.cell_factor = 1
        # deformed-space skip maps of warped rays (one warp state at a time)
        self.warped_skip: dict[Octant, Any] = {}
        self.warped_key: Any = None
        self.warped_visible: np.ndarray | None = None
        #: the share of warped_visible's cells the mode can see (0..1)
        self.warped_fraction = 1.0
        self.warped_offset = np.zeros(3, dtype=int)
        #: the warp state's piecewise-linear segment lengths (ray_segments.py) and texture
        self.warped_segments: SegmentMap | None = None
        self.segment_texture: Any = None

    def release(self) -> None:
        """Free every texture (idempotent)."""
        textures = (self.info, self.segment_texture, *self.cell_skip.values())
        for tex in (*textures, *self.warped_skip.values()):
            if tex is not None:
                tex.release()
        self.cell_skip.clear()
        self.warped_skip.clear()
        self.info = self.segment_texture = None


class SkipMapCache:
    """Which empty-space skipping each draw uses, and the maps it needs, kept up to date.

    ``ctx`` is the renderer's moderngl context (the octant textures are made on it). Per
    draw the renderer asks :meth:`kind`, then for the textures of that kind
    (:meth:`block_info`, :meth:`cell_skip`, :meth:`warped_cell_skip`), passing the
    draw volume's :class:`VolumeSkipMaps`. The settings below are the renderer's
    ``empty_space_skipping``, ``cell_skipping`` and ``warped_skip_maps``.
    """

    def __init__(self, ctx: Any, *, empty_space_skipping: bool = True) -> None:
        self.ctx = ctx
        #: largest 3D texture edge: a cell map longer than this on an axis (a volume of
        #: exactly that many voxels has one cell more) cannot be a texture, so its draws
        #: skip per block instead (correct, a little slower)
        self.max_texture_size = int(ctx.info.get("GL_MAX_3D_TEXTURE_SIZE", 2048))
        #: skip blocks the mode cannot see (off only to measure what it buys)
        self.empty_space_skipping = empty_space_skipping
        #: skip at the resolution of trilinear cells
        self.cell_skipping = True
        #: deformed-space skip maps of warped rays (see :meth:`kind`): "auto" builds them
        #: when a warp state is drawn a second time, "always" on first use, "never" keeps
        #: per-block checks, "background" offers them as :meth:`take_job`
        self.warped_skip_maps = "auto"
        self._warped_seen: dict[int, Any] = {}
        #: straight-ray cell maps (see :meth:`kind`): "auto" builds those of a volume of
        #: more than EAGER_CELLS cells when it is drawn a second time with the same
        #: visibility (its first frame skips per block, the same image), "always" at
        #: once, "background" offers their CPU work as :meth:`take_job` (the GUI)
        self.cell_skip_maps = "auto"
        #: straight-ray octant maps per COARSE_FACTOR³ cells (see :meth:`cell_factor`):
        #: "auto" for volumes of more than EAGER_CELLS cells, "always", or "never"
        self.coarse_cell_maps = "auto"
        self._cells_seen: dict[int, Any] = {}
        #: "background" mode: the job the last draw wanted, and finished results
        self._skip_wanted: tuple[Any, Callable[[], Any]] | None = None
        self._skip_ready: dict[Any, Any] = {}
        #: piecewise-linear warped rays: settings; their maps come with the warped maps
        self.segments = RaySegments()

    # ------------------------------------------------------------------ policy
    def kind(self, scene: Scene, linear: bool, maps: VolumeSkipMaps | None = None) -> str:
        """Which empty-space skipping a draw uses: "cells", "blocks" or "none".

        Straight rays (affine chains) skip at trilinear-cell resolution for the modes
        whose visibility is sparse (dvr, iso, flm), from the first draw of a volume of
        at most EAGER_CELLS cells, else from its second (:meth:`_cells_now`; the first
        skips per block). mip, minip, average and xray must
        look at (nearly) every sample along the ray; on the benchmark CT their skip checks
        cost more than they saved (docs/benchmarks.md), so they march plainly.
        Warped (non-affine) rays skip at cell resolution too, through deformed space,
        when every warp of the chain bounds its displacement
        (:meth:`voxwarp.deform.warp.Warp.displacement_range`; see
        :func:`voxwarp.render.skipping.maps.warped_cell_visibility`); otherwise they test their
        4³ block per sample. Building those maps takes seconds on the CPU for a 256³
        volume (a one-frame render costs less with block checks, and a warp that
        changes every frame, as while dragging, would rebuild every frame), so with
        :attr:`warped_skip_maps` "auto" they are built when the same warp state is
        drawn a second time (``maps`` given: the draw volume's, whose cache decides).
        A cell map longer than :attr:`max_texture_size` on some axis (a volume of
        exactly that many voxels, or a warped ray box reaching beyond it) gives "blocks".
        """
        if not self.empty_space_skipping:
            return "none"
        sparse = scene.mode in SPARSE_MODES and self.cell_skipping
        if not linear:
            if not self._warped_cells_possible(scene) or self.warped_skip_maps == "never":
                return "blocks"
            if self.warped_skip_maps == "always" or maps is None:
                return "cells"
            key = self._warped_key(scene)
            if self.warped_skip_maps == "background":
                return self._background_kind(maps, scene, key)
            if maps.warped_key == key or self._warped_seen.get(id(maps)) == key:
                return "cells"
            self._warped_seen[id(maps)] = key
            return "blocks"
        if sparse:
            return (
                "cells"
                if self._straight_cells_possible(scene) and self._cells_now(scene, maps)
                else "blocks"
            )
        if scene.mode in ("mip", "minip", "average", "xray"):
            return "none"
        return "blocks"

    def _cells_now(self, scene: Scene, maps: VolumeSkipMaps | None) -> bool:
        """Whether a straight-ray draw of ``scene`` uses (and so builds) cell maps now:
        with :attr:`cell_skip_maps` "auto", a volume of more than EAGER_CELLS cells
        first draws with block skipping (building its cell maps costs seconds, more than
        the frame they speed up) and gets them on its second draw with the same
        visibility, or as soon as they are built."""
        if self.cell_skip_maps == "always" or maps is None or not self._big(scene):
            return True
        key = skip_map_key(scene)
        if maps.cell_key == key:
            return True
        if self.cell_skip_maps == "background":
            return self._background_cells(maps, scene, key)
        if self._cells_seen.get(id(maps)) == key:
            return True
        self._cells_seen[id(maps)] = key
        return False

    def _straight_cells_possible(self, scene: Scene) -> bool:
        """Whether straight rays of ``scene`` may skip by cell maps: skipping on, a mode
        with sparse visibility and a cell grid that fits in a 3D texture."""
        if not (self.empty_space_skipping and self.cell_skipping):
            return False
        return scene.mode in SPARSE_MODES and self._fits(cell_grid_shape(scene.volume.shape))

    @staticmethod
    def _big(scene: Scene) -> bool:
        """A volume of more than EAGER_CELLS cells: its cell maps come after its first draw."""
        return int(np.prod(cell_grid_shape(scene.volume.shape))) > EAGER_CELLS

    def _background_cells(self, maps: VolumeSkipMaps, scene: Scene, key: Any) -> bool:
        """ "background" straight-ray cell maps: installed when a worker built them for
        this visibility, else the work is offered as :meth:`take_job` (blocks meanwhile)."""
        job_key = ("cells", id(maps), key)
        ready = self._skip_ready.pop(job_key, None)
        if ready is not None:
            self._install_cells(maps, key, *ready)
            return True
        data, bmin, bmax = maps.volume_data, maps.block_min, maps.block_max
        factor = self.cell_factor(scene)

        def job() -> tuple[np.ndarray, int]:
            return _coarsened(cell_visibility(scene, data, bmin, bmax), factor), factor

        self._skip_wanted = (job_key, job)
        return False

    @staticmethod
    def _install_cells(
        maps: VolumeSkipMaps, key: Any, visible: np.ndarray | None, factor: int = 1
    ) -> None:
        """Keep a cell visibility (per ``factor``³ cells) for the visibility ``key``; the
        octant maps of the old one go (those a view needs follow on first use, a
        fraction of its cost each)."""
        _release_all(maps.cell_skip)
        maps.cell_visible = None if visible is None else BitMask(visible)
        maps.visible_factor = factor
        maps.cell_key = key

    def _background_kind(self, maps: VolumeSkipMaps, scene: Scene, key: Any) -> str:
        """ "background" mode: cells when this warp state's maps are built or ready,
        else blocks, and the work is offered as :meth:`take_job`."""
        if maps.warped_key == key:
            return "cells"
        ready = self._skip_ready.pop(key, None)
        self._skip_ready.clear()  # results for other states are stale
        if ready is not None:
            self._install_warped(maps, key, ready)
            return "cells"
        self._skip_wanted = (key, self._warped_job(maps, scene))
        return "blocks"

    def _warped_cells_possible(self, scene: Scene) -> bool:
        """Whether warped rays of ``scene`` can skip by deformed-space cell maps: a mode
        with sparse visibility (dvr, iso, flm), cell skipping on, every warp of the
        chain bounding its displacement, and voxel axes along the world axes (the
        deformed-space map is the volume's cell grid; an oblique scan's cells are
        rotated, so its warped rays test blocks instead)."""
        return (
            self.empty_space_skipping
            and self.cell_skipping
            and not scene.volume.is_oblique
            and scene.mode in SPARSE_MODES
            and _bounded(scene.warps)
            and self._fits(self._warped_grid_shape(scene))
        )

    def _fits(self, shape: Any) -> bool:
        """Whether a cell map of ``shape`` can be a 3D texture on this context."""
        return all(0 < int(n) <= self.max_texture_size for n in shape)

    @staticmethod
    def _warped_grid_shape(scene: Scene) -> Any:
        """Cells per axis of ``scene``'s deformed-space skip map (its ray box)."""
        vol = scene.volume
        lo, hi = scene.ray_bounds()
        shape, _ = warped_cell_grid(cell_grid_shape(vol.shape), vol.spacing, vol.origin, lo, hi)
        return shape

    # ------------------------------------------------------------------ background builds
    def needs_maps(self, scene: Scene, maps: VolumeSkipMaps | None) -> bool:
        """With :attr:`warped_skip_maps` (or, for straight rays, :attr:`cell_skip_maps`)
        "background": whether drawing ``scene`` now would march block by block only
        because its skip maps are not built yet (``maps``: its volume's, None before its
        first draw; no side effects)."""
        if fold_affine(scene.warps) is not None:
            return self._needs_cells(scene, maps)
        if self.warped_skip_maps != "background" or not self._warped_cells_possible(scene):
            return False
        key = self._warped_key(scene)
        return not (maps is not None and maps.warped_key == key) and key not in self._skip_ready

    def _needs_cells(self, scene: Scene, maps: VolumeSkipMaps | None) -> bool:
        """Straight rays with :attr:`cell_skip_maps` "background": whether the draw
        skips by blocks only because the volume's cell maps are not built yet."""
        if self.cell_skip_maps != "background" or maps is None:
            return False
        if not (self._straight_cells_possible(scene) and self._big(scene)):
            return False
        key = skip_map_key(scene)
        return maps.cell_key != key and ("cells", id(maps), key) not in self._skip_ready

    def take_job(self) -> tuple[Any, Callable[[], Any]] | None:
        """With :attr:`warped_skip_maps` or :attr:`cell_skip_maps` "background":
        ``(key, job)`` for the warp state (or the big volume's cell visibility) the last
        draw drew with block checks, or None (handed out once). ``job()`` is CPU work (no
        GL) that may run on any thread while the warps it was made from stay alive; hand
        its result to :meth:`install`."""
        wanted, self._skip_wanted = self._skip_wanted, None
        return wanted

    def install(self, key: Any, result: Any) -> None:
        """Keep a finished :meth:`take_job` result; the next draw of its warp state
        uploads and uses it (a state that changed meanwhile never does)."""
        if result is not None:
            self._skip_ready = {key: result}

    def _warped_job(self, maps: VolumeSkipMaps, scene: Scene) -> Callable[[], Any]:
        """The CPU work of ``scene``'s deformed-space cell visibility, as a closure over
        its inputs (no GL: it may run on any thread)."""
        visible = self._cell_visibility(maps, scene)
        vol = scene.volume
        lo, hi = scene.ray_bounds()
        warps = list(scene.warps)
        spacing, origin = vol.spacing, vol.origin
        segments = self._segment_job(scene) if self.segments.setting == "auto" else None

        def job() -> Any:
            cells = warped_cell_visibility(visible, spacing, origin, warps, lo, hi)
            if cells is None:
                return None
            return (*cells, None if segments is None else segments())

        return job

    def _segment_job(self, scene: Scene) -> Callable[[], SegmentMap]:
        """The CPU work of ``scene``'s segment map at the current tolerance (no GL)."""
        vol = scene.volume
        lo, hi = scene.ray_bounds()
        warps = list(scene.warps)
        to_texel = vol.world_to_texel_matrix()
        tol, longest = self.segments.tolerance, self.segments.max_length(vol)
        return lambda: segment_lengths(warps, lo, hi, to_texel, tol, longest)

    def _install_warped(self, maps: VolumeSkipMaps, key: Any, result: Any) -> None:
        """Keep a deformed-space visibility and segment map on the volume (its old skip
        maps go)."""
        for tex in maps.warped_skip.values():
            tex.release()
        maps.warped_skip.clear()
        maps.warped_visible, maps.warped_offset, segments = result
        maps.warped_fraction = float(np.count_nonzero(maps.warped_visible)) / max(
            maps.warped_visible.size, 1
        )
        self._install_segments(maps, segments)
        maps.warped_key = key
        return_freed_memory()  # the build's temporaries (and the warp's bounds')

    # ------------------------------------------------------------------ maps
    def block_info(self, maps: VolumeSkipMaps, scene: Scene) -> Any:
        """The block info texture (skip distance, min, max, 0) for ``scene``'s mode,
        rewritten when what the mode can see changes."""
        key = skip_map_key(scene)
        if maps.info_key != key:
            dist = block_skip_distances(
                static_block_visibility(scene, maps.block_min, maps.block_max)
            )
            _write_block_info(maps.info, (dist, maps.block_min, maps.block_max))
            maps.info_key = key
        return maps.info

    def _cell_visibility(self, maps: VolumeSkipMaps, scene: Scene, factor: int = 1) -> np.ndarray:
        """Which cells of ``factor``³ trilinear cells ``scene``'s mode can see (kept on
        the volume at one bit per cell, at the factor first asked for; the bool array
        returned is the caller's, to drop after use). Fine cells of a volume that kept
        coarse ones (warped rays of a big volume) are classified again, and kept."""
        key = skip_map_key(scene)
        data, bmin, bmax = maps.volume_data, maps.block_min, maps.block_max
        if maps.cell_key != key:
            self._install_cells(maps, None, None)  # the old one goes before the new is built
            visible = _coarsened(cell_visibility(scene, data, bmin, bmax), factor)
            self._install_cells(maps, key, visible, factor)
            return visible
        assert maps.cell_visible is not None
        if maps.visible_factor == factor:
            return maps.cell_visible.unpack()
        if maps.visible_factor == 1:
            return coarsen_visibility(maps.cell_visible.unpack(), factor)
        visible = cell_visibility(scene, data, bmin, bmax)  # fine, from coarse kept bits
        maps.cell_visible, maps.visible_factor = BitMask(visible), 1  # the maps stay
        return _coarsened(visible, factor)

    def _octant_texture(self, visible: np.ndarray, octant: Octant, warped: bool = False) -> Any:
        """The octant map of ``visible`` as a texture; ``warped``: a deformed-space map
        (compiled kernels from WARPED_COMPILED_MIN_SIZE cells)."""
        compiled = True if warped and visible.size >= WARPED_COMPILED_MIN_SIZE else None
        return self._distance_texture(octant_skip_distances(visible, octant, compiled=compiled))

    def _distance_texture(self, dist: np.ndarray) -> Any:
        """An R8 3D texture of octant skip distances (nearest filtering)."""
        data = np.ascontiguousarray(dist.transpose(2, 1, 0))  # no copy: built in this layout
        tex = self.ctx.texture3d(dist.shape, 1, data, dtype="f1", alignment=1)
        tex.filter = (self.ctx.NEAREST, self.ctx.NEAREST)
        return tex

    def cell_factor(self, scene: Scene) -> int:
        """Trilinear cells per edge of a cell of ``scene``'s straight-ray octant maps:
        COARSE_FACTOR for a volume of more than COARSE_MIN_CELLS cells with
        :attr:`coarse_cell_maps` "auto" (or any volume with "always"), else 1.

        A coarse map is an eighth of the bytes (a 512³ uint8 volume's map was the
        volume's own size, and a view needs one to four): the raycaster reads it as a
        conservative fine map, so images do not change; rays near visible cells jump a
        little less far.
        """
        setting = self.coarse_cell_maps
        cells = int(np.prod(cell_grid_shape(scene.volume.shape)))
        if setting == "always" or (setting == "auto" and cells > COARSE_MIN_CELLS):
            return COARSE_FACTOR
        return 1

    def cell_skip(self, maps: VolumeSkipMaps, scene: Scene, octant: Octant) -> Any:
        """R8 texture of ``octant``'s skip distances per trilinear cell for ``scene``
        (per :meth:`cell_factor`³ cells: ``maps.cell_factor`` says which).

        Computed on first use per (mode visibility, octant) and cached on the volume;
        a change of what the mode can see (transfer function, isovalue, ...) drops all.
        """
        visible = None
        factor = self.cell_factor(scene)
        if maps.cell_key != skip_map_key(scene):  # what the mode sees changed: rebuild
            visible = self._cell_visibility(maps, scene, factor)
        if maps.cell_factor != factor:
            _release_all(maps.cell_skip)
            maps.cell_factor = factor
        tex = maps.cell_skip.get(octant)
        if tex is None:  # unpacked only to build a map
            if visible is None:
                visible = self._cell_visibility(maps, scene, factor)
            dist = octant_skip_distances(visible, octant)
            del visible  # before the upload: the map's bytes, not the visibility's too
            tex = maps.cell_skip[octant] = self._distance_texture(dist)
            del dist
            return_freed_memory()  # the build's temporaries, kept resident by the heap
        return tex

    def _warped_key(self, scene: Scene) -> tuple:
        """What the deformed-space skip maps of ``scene`` depend on."""
        lo, hi = scene.ray_bounds()
        return (
            skip_map_key(scene),
            warp_state_key(scene),
            tuple(np.round(np.asarray(lo, float), 9)),
            tuple(np.round(np.asarray(hi, float), 9)),
        )

    def warped_visibility(self, maps: VolumeSkipMaps, scene: Scene) -> np.ndarray:
        """Deformed-space cell visibility of ``scene``'s warped rays (cached on the volume
        for one warp state; a change of the warps or of what the mode sees rebuilds it).
        Its grid is the volume's shifted by ``maps.warped_offset`` cells."""
        key = self._warped_key(scene)
        if maps.warped_key != key:
            result = self._warped_job(maps, scene)()
            if result is None:
                raise RenderError("warped cell skipping needs warps that bound their displacement")
            self._install_warped(maps, key, result)
        assert maps.warped_visible is not None
        return maps.warped_visible

    @staticmethod
    def visible_fraction(maps: VolumeSkipMaps, scene: Scene) -> float | None:
        """The share of the straight cells (per ``maps.visible_factor``³ cells) ``scene``'s
        mode can see, when the volume keeps that visibility; else None (nothing built)."""
        if maps.cell_visible is None or maps.cell_key != skip_map_key(scene):
            return None
        return maps.cell_visible.fraction

    def warped_fraction(self, maps: VolumeSkipMaps, scene: Scene) -> float:
        """The share of deformed-space cells ``scene``'s warped rays can see (its
        :meth:`warped_visibility`, built now if needed)."""
        self.warped_visibility(maps, scene)
        return maps.warped_fraction

    def warped_segments(self, maps: VolumeSkipMaps, scene: Scene) -> Any:
        """The R32F texture of the warp state's segment map (:mod:`ray_segments`) at the
        current tolerance, built now if the warped maps came without it."""
        self.warped_visibility(maps, scene)
        have = maps.warped_segments
        if have is None or have.tolerance != self.segments.tolerance:
            self._install_segments(maps, self._segment_job(scene)())
        return maps.segment_texture

    def _install_segments(self, maps: VolumeSkipMaps, segments: SegmentMap | None) -> None:
        if maps.segment_texture is not None:
            maps.segment_texture.release()
        maps.warped_segments, maps.segment_texture = segments, None
        if segments is not None:
            maps.segment_texture = self.segments.texture(self.ctx, segments)

    def warped_cell_skip(self, maps: VolumeSkipMaps, scene: Scene, octant: Octant) -> Any:
        """R8 octant skip map of the deformed-space cells (see :meth:`warped_visibility`)."""
        visible = self.warped_visibility(maps, scene)
        tex = maps.warped_skip.get(octant)
        if tex is None:
            tex = maps.warped_skip[octant] = self._octant_texture(visible, octant, warped=True)
        return tex


#: bytes of the block info texture written at a time (its host copy is one slab)
INFO_SLAB_BYTES = 4 * 1024**2


#: largest magnitude up to which every integer is a half float
HALF_EXACT = 2048


def _compact_ranges(
    data: np.ndarray, block_min: np.ndarray, block_max: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The block (min, max) grids in the data's own dtype when it is an integer type
    narrower than their float32 (the same values: a uint8 volume's grids in a quarter
    of the bytes), else as they are."""
    dtype = np.asarray(data).dtype
    if dtype.kind in "ui" and dtype.itemsize < block_min.dtype.itemsize:
        return block_min.astype(dtype), block_max.astype(dtype)
    return block_min, block_max


def _half_exact(*grids: np.ndarray) -> bool:
    """Whether every value of ``grids`` is an integer a half float holds exactly (the
    block info's skip distances are integers up to 255 too)."""
    for g in grids:
        if g.size and g.dtype.kind not in "ui":
            return False
        if g.size and (int(g.min()) < -HALF_EXACT or int(g.max()) > HALF_EXACT):
            return False
    return True


def _write_block_info(texture: Any, parts: tuple[np.ndarray, ...]) -> None:
    """Write (x, y, z)-indexed block grids as the RGBA32F (or RGBA16F) texture's
    channels (the fourth 0), in slabs of z layers in its (z, y, x, channel) layout."""
    nx, ny, nz = parts[0].shape
    dtype = np.float16 if texture.dtype == "f2" else np.float32
    step = max(1, INFO_SLAB_BYTES // (nx * ny * 4 * dtype().itemsize))
    for z0 in range(0, nz, step):
        z1 = min(z0 + step, nz)
        slab = np.zeros((z1 - z0, ny, nx, 4), dtype=dtype)
        for c, part in enumerate(parts):
            slab[..., c] = part[:, :, z0:z1].T
        texture.write(slab, viewport=(0, 0, z0, nx, ny, z1 - z0))


def _coarsened(visible: np.ndarray, factor: int) -> np.ndarray:
    """``visible`` per ``factor``³ cells (itself for 1; see coarsen_visibility)."""
    return visible if factor == 1 else coarsen_visibility(visible, factor)


def _release_all(textures: dict[Any, Any]) -> None:
    """Release and forget every texture of ``textures``."""
    for tex in textures.values():
        tex.release()
    textures.clear()


def _bounded(warps: Any) -> bool:
    """Whether every warp of the chain bounds its displacement (no read-back)."""
    return all(w.bounds_displacement for w in warps)
