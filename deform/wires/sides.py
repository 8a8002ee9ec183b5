"""Propagation and flags of one side of the wire field build (wire paper
section 5.1): seeds, nearest-seed propagation (OpenCL in one pass, numpy, or the
paper's flagged domain), the mask test and the smooth ends' trim and weights."""

from __future__ import annotations

import math
import os
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires import propagation as prop
from voxwarp.deform.wires.classify import ClassifyInput, WireGeometry, classify
from voxwarp.deform.wires.constants import (
    FLAG_CHUNK,
    LUT_SIZE,
    MASK_THREADS,
    RADIAL_FADE,
    REFINE_STEPS,
    TOUCH_BLOCK_PIXELS,
)
from voxwarp.deform.wires.fade_cl import FadeInput, fade_available, fades
from voxwarp.deform.wires.geometry import (
    _CORNERS,
    _box_slices,
    _fade,
    _frame_coords,
    _refine_u,
    _region_centres,
    side_tables,
)
from voxwarp.deform.wires.masks import PlaneMasks
from voxwarp.deform.wires.propagation import nearest_seed
from voxwarp.deform.wires.seams import fade_seams
from voxwarp.deform.wires.tables import WireTables, _lerp_table
from voxwarp.deform.wires.wire import Wire

#: set to 0 to compute the fade weights with numpy even where the OpenCL pass could
#: (the same bits; for benchmarks of the two paths in one process)
FADE_ENV_VAR = "VOXWARP_WIRE_FADE_CL"

#: what one side's propagation gives: the region's first voxel and shape, wire id and
#: u per region voxel, the mask bits, and the seed count
_SideResult = tuple[np.ndarray, tuple[int, int, int], np.ndarray, np.ndarray, np.ndarray, int]


@dataclass
class _SideJob:
    """One side's propagation and flags in :meth:`WireDeformer.build`: the seeds (flat
    field index, wire, u), the wires' tables, their grown plane masks, the field's box
    corner, voxel size and shape, the side (``"modified"`` or ``"base"``), and the
    stage timings to add to."""

    seeds: tuple[np.ndarray, np.ndarray, np.ndarray]
    tables: list[WireTables]
    grown: list[tuple[np.ndarray, int, float]]
    lo: np.ndarray
    h: np.ndarray
    shape: tuple[int, int, int]
    side: str
    timings: dict[str, float]

    def parts(self) -> tuple[Any, ...]:
        """The fields in order (for unpacking into locals)."""
        return (
            self.seeds,
            self.tables,
            self.grown,
            self.lo,
            self.h,
            self.shape,
            self.side,
            self.timings,
        )


def _grow_one(bits: np.ndarray) -> np.ndarray:
    """``bits`` grown by one voxel (a 3x3x3 maximum, nothing beyond the array), run over
    the box of the set bits only (what ``ndimage.maximum_filter(bits, size=3,
    mode="constant")`` gives, without filtering the empty rest): one voxel along each
    axis in turn, by OR-ing the box with itself shifted (a third of the filter's time)."""
    out = np.zeros_like(bits)
    box = []
    for axis in range(3):
        hit = np.flatnonzero(bits.any(axis=tuple(a for a in range(3) if a != axis)))
        if len(hit) == 0:
            return out
        box.append(slice(max(int(hit[0]) - 1, 0), int(hit[-1]) + 2))
    sub = out[tuple(box)]
    sub[...] = bits[tuple(box)]
    for axis in range(3):
        first, rest = [slice(None)] * 3, [slice(None)] * 3
        first[axis], rest[axis] = slice(0, -1), slice(1, None)
        src = sub.copy()
        sub[tuple(rest)] |= src[tuple(first)]
        sub[tuple(first)] |= src[tuple(rest)]
    return out


@dataclass
class _Trim:
    """The smooth-ends trim of one wire on one side (see :meth:`SidePasses._smooth_trim`):
    a voxel beyond an end plane farther than ``cap`` mm along the wire is dropped, and
    with ``core`` (the base side of a smooth wire) one farther than ``core`` mm from it."""

    tab: WireTables
    side: str
    cap: float
    core: float | None

    def drop(self, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Which points ``p`` (world mm; ``u`` their nearest seed's) are dropped: the
        arithmetic of :func:`_wire_local`, its x and y only where ``core`` needs them
        and z only at the ends."""
        points, frames, length = side_tables(self.tab, self.side)
        u = _refine_u(points, frames[:, :, 2], length, u, p)
        i = np.rint(u * (LUT_SIZE - 1)).astype(np.int64)
        ends = (u <= 0.0) | (u >= 1.0)
        if self.core is not None:
            x, y, z = _frame_coords(points, frames, i, p)
            return (ends & (np.abs(z) > self.cap)) | (np.hypot(x, y) > self.core)
        drop = np.zeros(len(u), dtype=bool)
        at = np.flatnonzero(ends)
        if len(at):
            z = _frame_coords(points, frames, i[at], p[at], axes=(2,))[0]
            drop[at] = np.abs(z) > self.cap
        return drop


class SidePasses(PlaneMasks):
    """Seed, propagation and flag stages of :class:`~voxwarp.deform.wires.build.WireDeformer`
    (which sets these attributes and says whether to classify on the OpenCL device)."""

    backend: str
    precision: float
    propagate: str
    propagation_input: tuple[np.ndarray, tuple[float, ...]] | None

    def _device_geometries(
        self,
        tables: list[WireTables],
        grown: list[tuple[np.ndarray, int, float]],
        h: np.ndarray,
        side: str,
    ) -> list[WireGeometry]:
        """What the OpenCL pass needs of each wire on ``side``: its table points and
        frames, length, reach, grown masks, twist and scale keys."""
        reach = self._reach(h, side)
        geoms = []
        for wi, (w, tab) in enumerate(zip(self.wires, tables, strict=True)):
            points, frames, length = side_tables(tab, side)
            geoms.append(
                WireGeometry(
                    points=points,
                    tangents=frames[:, :, 2],
                    frames=frames,
                    length=length,
                    reach=float(reach[wi]),
                    mask=grown[wi][0],
                    half=grown[wi][2],
                    twist=w.twist,
                    scale=w.scale,
                )
            )
        return geoms

    def classify_on_device(self) -> bool:  # pragma: no cover - WireDeformer's
        raise NotImplementedError

    def _side(self, job: _SideJob) -> _SideResult:
        """Propagation and flags of one side: the region's first voxel and shape, wire
        id and refined u per region voxel, the mask bits and the seed count. One OpenCL
        pass (:mod:`voxwarp.deform.wires.classify`) where the device allows, else numpy;
        adds the stages' seconds to ``timings``."""
        seeds, tables, grown, lo, h, shape, side, timings = job.parts()
        if self.propagate == "flagged":
            flagged = self._flagged_side(job)
            return self._smooth_trim(tables, lo, h, flagged, side)
        fast = self._fast_side(job)
        if fast is not None:  # the trims ran in the pass, but for the voxels it left over
            *out, undecided = fast
            return self._smooth_trim(tables, lo, h, tuple(out), side, undecided)
        t0 = time.perf_counter()
        region_lo, rshape, r_wire, r_u, r_near, count = self._propagate(
            seeds, tables, lo, h, shape, side
        )
        t1 = time.perf_counter()
        bits = self._flags(tables, grown, lo, h, region_lo, rshape, r_wire, r_u, r_near, side)
        timings["propagate"] += t1 - t0
        timings["flags"] += time.perf_counter() - t1
        out = (region_lo, rshape, r_wire, r_u, bits, count)
        return self._smooth_trim(tables, lo, h, out, side)

    def _fast_side(self, job: _SideJob) -> tuple[Any, ...] | None:
        """:meth:`_side` in one OpenCL pass, with the smooth ends' trim, and the flat
        indices of the voxels whose trim the pass left to numpy; None where OpenCL (with
        double precision) is unavailable, not asked for, or fails (the numpy path then
        runs)."""
        seeds, tables, grown, lo, h, shape, side, timings = job.parts()
        if self.backend not in ("auto", "opencl") or not self.classify_on_device():
            return None
        t0 = time.perf_counter()
        c_lo, rshape, grid, flat, s_wire, s_u = self._region(seeds, tables, lo, h, shape, side)
        if max(rshape) > prop.MAX_LINE:
            return None
        order = np.argsort(flat, kind="stable")
        modified = side == "modified"
        geoms = self._device_geometries(tables, grown, h, side)
        trims = self._device_trims(side)
        inp = ClassifyInput(
            seed_idx=flat[order],
            seed_wire=s_wire[order],
            seed_u=s_u[order],
            rshape=rshape,
            lo=lo,
            h=h,
            region_lo=c_lo,
            wires=geoms,
            px=self.mask_resolution,
            # smooth ends reach further (trimmed per wire later)
            cap=self._end_cap() + max(w.end_reach(side) for w in self.wires),
            base_side=not modified,
            refine_steps=REFINE_STEPS,
            trim=trims,
        )
        sampling = tuple(float(v) for v in h)
        if modified:
            self.propagation_input = (grid, sampling)
        split: list[float] = []

        def use(st: dict[str, Any], buf: Any) -> tuple[np.ndarray, ...]:
            st["queue"].finish()
            split.append(time.perf_counter())
            return classify(st, buf, inp)

        try:
            r_wire, r_u, bits, undecided = prop.on_device_nearest(grid, sampling, use)
        except (prop._opencl_state()["cl"].Error, MemoryError) as exc:  # e.g. out of memory
            if self.backend == "opencl":
                raise WarpError(
                    f"the OpenCL wire field pass failed ({type(exc).__name__}); use"
                    " backend='scipy' or a larger field_scale"
                ) from exc
            return None
        timings["propagate"] += split[0] - t0
        timings["flags"] += time.perf_counter() - split[0]
        # no trims in the pass: numpy trims all flagged voxels (if any wire is smooth)
        return c_lo, rshape, r_wire, r_u, bits, len(flat), None if trims is None else undecided

    def _region(
        self,
        seeds: tuple[np.ndarray, np.ndarray, np.ndarray],
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        side: str,
    ) -> tuple[np.ndarray, tuple[int, int, int], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The wires' region on one side (the box of their reach): its first voxel and
        shape, the seed mask over it, and the seeds' flat region indices, wires and u."""
        seed_idx, seed_wire, seed_u = seeds
        c_lo = np.full(3, np.iinfo(np.int64).max)
        c_hi = np.full(3, -1)
        for w, tab in zip(self.wires, tables, strict=True):
            w_lo, w_hi = self._wire_box(w, tab, side)
            a = np.floor((w_lo - lo) / h - 0.5).astype(int) - 1
            b = np.ceil((w_hi - lo) / h - 0.5).astype(int) + 1
            c_lo, c_hi = np.minimum(c_lo, a), np.maximum(c_hi, b)
        c_lo = np.clip(c_lo, 0, np.asarray(shape) - 1)
        c_hi = np.clip(c_hi, 0, np.asarray(shape) - 1)
        rshape = (
            int(c_hi[0] - c_lo[0] + 1),
            int(c_hi[1] - c_lo[1] + 1),
            int(c_hi[2] - c_lo[2] + 1),
        )
        grid = np.zeros(rshape, dtype=bool)
        sidx = np.stack(np.unravel_index(seed_idx, shape), -1) - c_lo
        inside = np.all((sidx >= 0) & (sidx < np.asarray(rshape)), axis=1)
        sidx, s_wire, s_u = sidx[inside], seed_wire[inside], seed_u[inside]
        if len(sidx) == 0:
            raise WarpError(
                f"no {side} wire passes through the attribute field: check the control points"
            )
        grid[sidx[:, 0], sidx[:, 1], sidx[:, 2]] = True
        flat = np.ravel_multi_index(sidx.T, rshape)
        return c_lo, rshape, grid, flat, s_wire, s_u

    def _wire_box(self, w: Wire, tab: WireTables, side: str) -> tuple[np.ndarray, np.ndarray]:
        """World box (mm) of what one wire can flag on ``side``: its points grown by
        the reach across it, and, for smooth ends, the box beyond each end over which
        the sweep fades (the reach across the end tangent, the fade along it), within
        the points grown by the fade in every direction."""
        points, frames, _ = side_tables(tab, side)
        smax = float(w.scale[:, 1].max()) if side == "modified" else 1.0
        margin = 2 * self.mask_resolution
        across = w.reach_at(smax) + margin
        lo, hi = points.min(0) - across, points.max(0) + across
        ends = w.end_reach(side)
        if ends <= 0.0:
            return lo, hi
        along = ends + self._end_cap() + margin
        for i in (0, LUT_SIZE - 1):  # the frame's x, y across, z along the end tangent
            f = frames[i]
            half = (np.abs(f[:, 0]) + np.abs(f[:, 1])) * across + np.abs(f[:, 2]) * along
            lo, hi = np.minimum(lo, points[i] - half), np.maximum(hi, points[i] + half)
        grown = max(w.reach_at(smax), ends) + margin  # never more than every direction
        return np.maximum(lo, points.min(0) - grown), np.minimum(hi, points.max(0) + grown)

    def _reach(self, h: np.ndarray, side: str) -> np.ndarray:
        """Per wire: how far (mm) from its nearest seed a voxel can still be flagged."""
        modified = side == "modified"
        return np.array(
            [
                math.hypot(
                    w.reach_at(float(w.scale[:, 1].max()) if modified else 1.0),
                    w.end_reach(side),
                )
                + 2 * self.mask_resolution
                + float(np.linalg.norm(h))
                for w in self.wires
            ]
        )

    def _end_cap(self) -> float:
        """How far (mm) beyond its end planes a rigid wire still sweeps: the along-wire
        offset of a voxel centre within half a field voxel (and a mask pixel) of them."""
        return float(np.linalg.norm(self.spacing * self.field_scale)) * 0.5 + self.mask_resolution

    def _smooth_trim(
        self,
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        out: _SideResult,
        side: str,
        undecided: np.ndarray | None = None,
    ) -> _SideResult:
        """One side's result with the bits of ``ends="smooth"`` wires as they need them
        (``undecided``: the OpenCL pass trimmed all but these flat indices, see
        :meth:`_device_trims`).

        A wire that vacates nothing (:attr:`Wire.vacates` false: smooth sides, or
        ``vacated="rest"``) keeps no bit on the base side.
        A flag beyond an end reaches as far as its own wire's :meth:`Wire.end_reach`
        (the OpenCL pass takes the largest of all wires): the falloff on the modified
        side, half of it on the base side. A smooth wire's place is vacated out to the
        middle of its fades (along the wire and across its radius, plus the half field
        voxel by which masks grow), not beyond: the fades move their content
        continuously, so what lies past their middle mostly stays and is shown.
        """
        region_lo, rshape, r_wire, r_u, bits, count = out
        if side == "base":  # smooth sides and vacated="rest" leave nothing empty
            for wi, w in enumerate(self.wires):
                if not w.vacates:
                    bits &= r_wire != wi
        if not any(w.smooth for w in self.wires):
            return out
        flat = np.flatnonzero(bits) if undecided is None else undecided[bits.ravel()[undecided]]
        wire_of = r_wire.ravel()[flat]
        flat_u = r_u.reshape(-1)
        jobs = []  # (the wire's trim, a chunk of its voxels): small temporaries
        for wi, (cap, core) in enumerate(self._trim_limits(side)):
            sel = flat[wire_of == wi]
            trim = _Trim(tables[wi], side, cap, core)
            jobs += [(trim, sel[a : a + FLAG_CHUNK]) for a in range(0, len(sel), FLAG_CHUNK)]

        def dropped(job: tuple[_Trim, np.ndarray]) -> np.ndarray:
            trim, chunk = job
            p = _region_centres(lo, h, region_lo, rshape, chunk)
            return chunk[trim.drop(flat_u[chunk], p)]

        # a few threads (numpy releases the GIL); no chunk reads the bits it clears
        with ThreadPoolExecutor(MASK_THREADS) as pool:
            for gone in pool.map(dropped, jobs):
                bits.reshape(-1)[gone] = False
        return region_lo, rshape, r_wire, r_u, bits, count

    def _trim_limits(self, side: str) -> list[tuple[float, float | None]]:
        """Per wire the smooth ends' trim on ``side`` as (cap, core) of :class:`_Trim`
        (core None: no core test, only the base side of a smooth wire has one)."""
        out: list[tuple[float, float | None]] = []
        for w in self.wires:
            cap = self._end_cap() + w.end_reach(side)
            core = (1.0 + 0.5 * RADIAL_FADE) * w.radius + self._end_cap()
            out.append((cap, core if side == "base" and w.smooth else None))
        return out

    def _device_trims(self, side: str) -> np.ndarray | None:
        """The smooth ends' trims for the OpenCL pass (:attr:`ClassifyInput.trim`):
        per wire (cap, core), core -1 where there is no core test; None where no wire
        is smooth (no trim at all)."""
        if not any(w.smooth for w in self.wires):
            return None
        limits = self._trim_limits(side)
        return np.array([(cap, -1.0 if core is None else core) for cap, core in limits])

    def _weights(
        self,
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        region_lo: np.ndarray,
        rshape: tuple[int, int, int],
        r_wire: np.ndarray,
        r_u: np.ndarray,
        swept: np.ndarray,
    ) -> tuple[np.ndarray | None, int]:
        """The field's displacement weights (see :attr:`WireField.weight`): 1 where a
        rigid wire is nearest, the fade of the nearest smooth (ends or sides) wire
        elsewhere, faded to 0 at the seams of smooth-sides wires
        (:func:`~voxwarp.deform.wires.seams.fade_seams`); None when every wire is rigid.
        Only the swept voxels and their neighbours (the corners a swept sample
        interpolates) are computed; the rest hold 1, unused. Also returns how many
        voxels the seams faded."""
        if not any(w.fades for w in self.wires):
            return None, 0
        # written straight into the field's (Fortran) weight: no C-order region of ones
        # filled first and copied over
        weight = np.ones(shape, dtype=np.float32, order="F")
        inner = weight[_box_slices(region_lo, rshape)]
        flat_wire = r_wire.ravel()
        known = _grow_one(swept)
        need = np.flatnonzero(known)
        flat_u = r_u.reshape(-1)

        def run(wi: int, chunk: np.ndarray) -> None:
            sel = chunk[flat_wire[chunk] == wi]
            if len(sel):
                p = _region_centres(lo, h, region_lo, rshape, sel)
                fade = _fade(self.wires[wi], tables[wi], flat_u[sel], p)
                inner[np.unravel_index(sel, rshape)] = fade

        def put(start: int) -> None:
            chunk = slice(start, start + FLAG_CHUNK)
            inner[np.unravel_index(need[chunk], rshape)] = values[chunk]

        box = (lo, h, region_lo, rshape)
        values = self._device_fades(tables, box, need, flat_wire[need], flat_u[need])
        numpy_part = need
        if values is not None:  # the pass's weights, numpy's for the voxels it left over
            numpy_part = need[np.isnan(values)]
        # chunks of voxels, a few threads (numpy releases the GIL)
        jobs = [
            (wi, numpy_part[start : start + FLAG_CHUNK])
            for wi, w in enumerate(self.wires)
            if w.fades
            for start in range(0, len(numpy_part), FLAG_CHUNK)
        ]
        with ThreadPoolExecutor(MASK_THREADS) as pool:
            if values is not None:
                list(pool.map(put, range(0, len(need), FLAG_CHUNK)))
            list(pool.map(lambda job: run(*job), jobs))
        grid = (lo + (region_lo + 0.5) * h, h)
        faded = fade_seams(inner, known.reshape(rshape), r_wire, r_u, grid, tables, self.wires)
        return weight, faded

    def _device_fades(
        self,
        tables: list[WireTables],
        box: tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, int, int]],
        flat: np.ndarray,
        wire: np.ndarray,
        u: np.ndarray,
    ) -> np.ndarray | None:
        """The fade weights of region voxels ``flat`` (their nearest wire and stored u;
        ``box``: the field's corner and voxel size, the region's first voxel and shape)
        from the OpenCL pass of :mod:`voxwarp.deform.wires.fade_cl`, NaN where numpy
        decides; None where the pass does not run (no OpenCL device with double
        precision, not asked for, ``VOXWARP_WIRE_FADE_CL=0``, or it fails)."""
        if self.backend not in ("auto", "opencl") or not self.classify_on_device():
            return None
        if os.environ.get(FADE_ENV_VAR, "").strip().lower() in ("0", "false", "off", "no"):
            return None
        lo, h, region_lo, rshape = box
        st = prop._opencl_state()
        inp = FadeInput(flat, wire, u, rshape, region_lo, lo, h, self.wires, tables, REFINE_STEPS)
        try:
            with prop._lock:
                return fades(st, inp) if fade_available(st) else None
        except (st["cl"].Error, MemoryError):  # e.g. out of memory: numpy gives the same
            return None

    def _propagate(
        self,
        seeds: tuple[np.ndarray, np.ndarray, np.ndarray],
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        side: str,
    ) -> _SideResult:
        """(wire, u) of the nearest seed for every voxel of the wires' region on one
        side (the reference, numpy path): the region's first voxel and shape, the two
        grids, which voxels lie within their wire's reach, and the seed count."""

        c_lo, rshape, grid, flat, s_wire, s_u = self._region(seeds, tables, lo, h, shape, side)
        wire_of = np.zeros(int(np.prod(rshape)), dtype=np.int16)
        u_of = np.zeros(int(np.prod(rshape)), dtype=np.float32)
        wire_of[flat], u_of[flat] = s_wire, s_u
        sampling = tuple(float(v) for v in h)
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            nearest = nearest_seed(grid, sampling, backend=self.backend).ravel()
        if side == "modified":
            #: the propagation's input (seed mask over the region, voxel spacing), kept
            #: for benchmarks that time other propagations on the same grid
            self.propagation_input = (grid, sampling)
        # voxels farther from their nearest seed than that wire's reach cannot be
        # flagged: only the others are refined and tested against the masks
        reach2 = self._reach(h, side) ** 2
        near = np.zeros(len(nearest), dtype=bool)

        def near_chunk(start: int) -> None:
            # squared distance to the nearest seed, summed over the axes in order
            idx = np.arange(start, min(start + FLAG_CHUNK, len(nearest)))
            own = np.unravel_index(idx, rshape)
            seed = np.unravel_index(nearest[idx], rshape)
            d2 = ((own[0] - seed[0]) * h[0]) ** 2
            d2 += ((own[1] - seed[1]) * h[1]) ** 2
            d2 += ((own[2] - seed[2]) * h[2]) ** 2
            near[idx] = d2 <= reach2[wire_of[nearest[idx]]]

        with ThreadPoolExecutor(MASK_THREADS) as pool:
            list(pool.map(near_chunk, range(0, len(nearest), FLAG_CHUNK)))
        return (
            c_lo,
            rshape,
            wire_of[nearest].reshape(rshape),
            u_of[nearest].reshape(rshape),
            near.reshape(rshape),
            len(flat),
        )

    def _flagged_side(self, job: _SideJob) -> _SideResult:
        """:meth:`_side` the paper's way (sections 5.1, 7.1): flag the voxels that a set
        pixel of a plane mask touches (grown by one voxel, so that planes fanning out
        on the outside of a bend leave no gap), propagate the nearest seed only over
        them and their neighbours (the voxels a swept sample interpolates t from; a
        k-d tree of the seeds, exact Euclidean), then the mask test of the numpy path on
        them: a voxel is swept where both say so."""
        seeds, tables, grown, lo, h, shape, side, timings = job.parts()

        t0 = time.perf_counter()
        c_lo, rshape, grid, flat, s_wire, s_u = self._region(seeds, tables, lo, h, shape, side)
        if side == "modified":
            self.propagation_input = (grid, tuple(float(v) for v in h))
        touched = self._touched(tables, grown, lo, h, c_lo, rshape, side)
        cand = ndimage.maximum_filter(touched, size=3, mode="constant")
        domain = ndimage.maximum_filter(cand, size=3, mode="constant")
        dom = np.flatnonzero(domain)
        seed_pts = np.stack(np.unravel_index(flat, rshape), -1) * h
        dist, which = cKDTree(seed_pts).query(
            np.stack(np.unravel_index(dom, rshape), -1) * h, workers=-1
        )
        n = int(np.prod(rshape))
        r_wire = np.zeros(n, dtype=np.int16)
        r_u = np.zeros(n, dtype=np.float32)
        near = np.zeros(n, dtype=bool)
        r_wire[dom], r_u[dom] = s_wire[which], s_u[which]
        near[dom] = dist <= self._reach(h, side)[s_wire[which]]
        r_wire, r_u, near = r_wire.reshape(rshape), r_u.reshape(rshape), near.reshape(rshape)
        t1 = time.perf_counter()
        bits = self._flags(tables, grown, lo, h, c_lo, rshape, r_wire, r_u, near, side) & cand
        timings["propagate"] += t1 - t0
        timings["flags"] += time.perf_counter() - t1
        return c_lo, rshape, r_wire, r_u, bits, len(flat)

    def _touched(
        self,
        tables: list[WireTables],
        grown: list[tuple[np.ndarray, int, float]],
        lo: np.ndarray,
        h: np.ndarray,
        c_lo: np.ndarray,
        rshape: tuple[int, int, int],
        side: str,
    ) -> np.ndarray:
        """Region voxels holding a set pixel of a (grown) plane mask: the paper's flags.
        On the base side the pixels are mapped as the sweep maps them (``q = A p + b``).
        The end planes also flag along the end tangents as far as the mask test reaches
        past them (the end cap, plus a smooth wire's :meth:`Wire.end_reach`)."""
        out = np.zeros(rshape, dtype=bool)
        rs = np.asarray(rshape)
        px = self.mask_resolution
        for wi, (w, tab) in enumerate(zip(self.wires, tables, strict=True)):
            mask, k, half = grown[wi]
            n_planes = mask.shape[0]
            tt_all = np.linspace(0.0, LUT_SIZE - 1.0, n_planes)
            reach = self._end_cap() + w.end_reach(side)
            steps = np.arange(1, math.ceil(reach / px) + 1) * px
            block = max(1, TOUCH_BLOCK_PIXELS // (k * k))
            for p0 in range(0, n_planes, block):
                pl, a, b = np.nonzero(mask[p0 : p0 + block])
                pl = pl + p0
                tt = tt_all[pl]
                fm = _lerp_table(tab.modified_frames, tt)
                x, y = (a - half) * px, (b - half) * px
                p = _lerp_table(tab.modified_points, tt)
                p += x[:, None] * fm[:, :, 0] + y[:, None] * fm[:, :, 1]
                tangent = fm[:, :, 2]
                if side == "base":  # where the sweep takes these pixels from
                    a_t, b_t = tab.lookup(tt)
                    p = np.einsum("nij,nj->ni", a_t, p) + b_t
                    tangent = _lerp_table(tab.base_frames, tt)[:, :, 2]
                pts = [p]
                for end, sign in ((0, -1.0), (n_planes - 1, 1.0)):
                    at = pl == end
                    if at.any():
                        pts += [p[at] + sign * d * tangent[at] for d in steps]
                p = np.concatenate(pts)
                idx = np.floor((p - lo) / h).astype(np.int64) - c_lo
                ok = np.all((idx >= 0) & (idx < rs), axis=1)
                out[idx[ok, 0], idx[ok, 1], idx[ok, 2]] = True
        return out

    def _flags(
        self,
        tables: list[WireTables],
        masks: list[tuple[np.ndarray, int, float]],
        lo: np.ndarray,
        h: np.ndarray,
        region_lo: np.ndarray,
        rshape: tuple[int, int, int],
        r_wire: np.ndarray,
        r_u: np.ndarray,
        r_near: np.ndarray,
        side: str,
    ) -> np.ndarray:
        """Mask bits of a region's voxels (refining ``r_u`` in place to the closest
        point): swept voxels on the modified side, the object's place on the base side."""
        out = np.zeros(rshape, dtype=bool)
        centres = [lo[a] + (np.arange(n) + region_lo[a] + 0.5) * h[a] for a, n in enumerate(rshape)]
        near = np.nonzero(r_near.ravel())[0]
        flat_wire = r_wire.ravel()[near]
        order = near[np.argsort(flat_wire, kind="stable")]
        bounds = np.searchsorted(r_wire.ravel()[order], np.arange(len(self.wires) + 1))
        flat_u = r_u.reshape(-1)
        flat_out = out.reshape(-1)

        def run(wi: int, sel: np.ndarray) -> None:
            ii, jj, kk = np.unravel_index(sel, rshape)
            p = np.stack([centres[0][ii], centres[1][jj], centres[2][kk]], -1)
            u, bits = self._mask_bits(self.wires[wi], tables[wi], masks[wi], flat_u[sel], p, side)
            flat_u[sel] = u
            flat_out[sel] = bits

        # chunks of voxels (small temporaries), a few threads (numpy releases the GIL)
        jobs = [
            (wi, order[a : min(a + FLAG_CHUNK, bounds[wi + 1])])
            for wi in range(len(self.wires))
            for a in range(int(bounds[wi]), int(bounds[wi + 1]), FLAG_CHUNK)
        ]
        with ThreadPoolExecutor(MASK_THREADS) as pool:
            list(pool.map(lambda job: run(*job), jobs))
        return out

    def _seeds(
        self,
        tables: list[WireTables],
        lo: np.ndarray,
        h: np.ndarray,
        shape: tuple[int, int, int],
        side: str,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Seed voxels (flat indices), their wire and closest u (section 5.1): the 8
        voxels of every field cell the wire of ``side`` enters, nearest wire first."""
        shape_a = np.asarray(shape)
        all_idx, all_d, all_w, all_u = [], [], [], []
        for wi, (w, tab) in enumerate(zip(self.wires, tables, strict=True)):
            curve = w.modified if side == "modified" else w.base
            tparam = tab.t_modified if side == "modified" else tab.t_base
            length = tab.length_modified if side == "modified" else tab.length_base
            n = max(2, math.ceil(4 * length / float(h.min())) + 1)
            pts = curve.evaluate(np.interp(np.linspace(0.0, 1.0, n), tab.u, tparam))
            cell = np.floor((pts - lo) / h - 0.5).astype(np.int64)
            corners = (cell[:, None, :] + _CORNERS[None]).reshape(-1, 3)
            ok = np.all((corners >= 0) & (corners < shape_a), axis=1)
            idx = np.unique(np.ravel_multi_index(corners[ok].T, shape))
            if len(idx) == 0:
                continue
            centres = lo + (np.stack(np.unravel_index(idx, shape), -1) + 0.5) * h
            tc, d = curve.closest_point(centres, precision=self.precision)
            all_idx.append(idx)
            all_d.append(d)
            all_w.append(np.full(len(idx), wi))
            all_u.append(np.interp(tc, tparam, tab.u))
        if not all_idx:
            raise WarpError(
                f"no {side} wire passes through the attribute field: check the control points"
            )
        idx = np.concatenate(all_idx)
        d = np.concatenate(all_d)
        wire = np.concatenate(all_w)
        u = np.concatenate(all_u)
        # keep the minimum distance per voxel
        order = np.lexsort((d, idx))
        idx, wire, u = idx[order], wire[order], u[order]
        first = np.ones(len(idx), dtype=bool)
        first[1:] = idx[1:] != idx[:-1]
        return idx[first], wire[first].astype(np.int16), u[first].astype(np.float32)
