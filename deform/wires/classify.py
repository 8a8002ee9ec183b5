"""Wire attribute field: propagation and flag classification in one OpenCL pass.

About this technique (the wire paper's sections 5.1 and 7.1, on the device)
----------------------------------------------------------------------------
:meth:`voxwarp.deform.wires.build.WireDeformer.build` gives every voxel of a wire's region the
wire id and arc-length fraction u of its nearest seed (the exact distance transform of
:mod:`voxwarp.deform.wires.propagation`), then, for the voxels within their wire's reach of
that seed, refines u to the closest point of the wire (Newton steps along the table's
tangents) and looks the voxel's projection up in the plane mask at u (turned and scaled
as the sweep does on the base side). The reference does those steps in numpy, one
full-region float64 temporary per operation; here one OpenCL work-item per region voxel
reads the nearest-seed index straight from the propagation's device buffer (never
copied to the host), finds that seed's (wire, u) by a binary search of the sorted seed
list, and writes the three results the field needs: wire id (int16), u (float32) and
the mask bit (uint8). Where a wire has smooth ends, the pass also runs the ends' trim
(:class:`voxwarp.deform.wires.sides._Trim`) on the voxels it flags, instead of a second
numpy pass over them: the Newton steps again from the stored float u, the end test along
the tangent and, on the base side, the core test ``hypot(x, y) > core``, decided only
where ``x^2 + y^2`` is clearly off ``core^2`` (the voxels too close to call go back to
numpy's trim, whose hypot decides them).

Exactness: the kernel repeats the reference's arithmetic operation by operation, in
the same precision (float64 where numpy computes in float64, float32 where it computes
in float32, no fused multiply-adds: ``FP_CONTRACT OFF``), so both give the same bits;
the one exception is the twist's cos and sin on the base side (one ``sincos`` of the
device's library against the host's cos and sin, within a few ulp), which can flip a
mask pixel only where a voxel projects onto a pixel edge to within ~1e-15 mm. The pass
needs double precision (``cl_khr_fp64``); :func:`classify_available` says whether the
device has it, and the caller keeps the numpy path otherwise.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: the pragmas and helpers shared with :mod:`voxwarp.deform.wires.fade_cl`: rint, np.interp,
#: the Newton steps of u (numpy's float64 arithmetic, no contractions)
KERNEL_HELPERS = r"""
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

/* rint (round half to even): for |x| < 2^52 (float: 2^23) adding 2^52 leaves a unit in
   the last place of 1, so the sum rounds x as rint does (in the default rounding mode)
   and the subtraction is exact; larger values are whole already. PoCL's rint is a
   library call, several times slower. */
static inline double rint_d(double x) {
    if (!(fabs(x) < 0x1p52)) return x;  /* already whole (or NaN) */
    return x >= 0.0 ? (x + 0x1p52) - 0x1p52 : -((-x + 0x1p52) - 0x1p52);
}
static inline float rint_f(float x) {
    if (!(fabs(x) < 0x1p23f)) return x;
    return x >= 0.0f ? (x + 0x1p23f) - 0x1p23f : -((-x + 0x1p23f) - 0x1p23f);
}

/* np.interp(x, xp, fp) for sorted xp (numpy's arithmetic, compiled_base.c). */
static double interp_keys(double x, __global const double *xp, __global const double *fp,
                          int n) {
    if (x < xp[0]) return fp[0];
    if (x > xp[n - 1]) return fp[n - 1];
    if (x == xp[n - 1]) return fp[n - 1];
    int j = 0;
    while (j + 1 < n && xp[j + 1] <= x) j++;
    if (x == xp[j]) return fp[j];
    double slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
    double r = slope * (x - xp[j]) + fp[j];
    if (isnan(r)) {
        r = slope * (x - xp[j + 1]) + fp[j + 1];
        if (isnan(r) && fp[j] == fp[j + 1]) r = fp[j];
    }
    return r;
}

/* Newton steps of the wire parameter u of point p along the wire's 256 samples P and
   tangents T (numpy's arithmetic, as geometry._wire_local): u <- q / 255 + (p - P_q).T_q / len.
   A step depends on u only through its table entry q = rint(255 u): from the entry of a
   known step (*q_prev, whose step gave *u_prev) it gives *u_prev again without computing,
   and when u is that result, every later step would too, so the loop ends: the same bits
   as refine_steps full steps. *q_prev < 0: no step known. */
static double refine_u_known(const double p0, const double p1, const double p2,
                             __global const double *P, __global const double *T,
                             const double len, double u, const int refine_steps,
                             long *q_prev, double *u_prev) {
    for (int step = 0; step < refine_steps; step++) {
        long q = (long)rint_d(u * 255.0);
        q = q < 0 ? 0 : (q > 255 ? 255 : q);
        if (q == *q_prev) {
            if (u == *u_prev) break;  /* a fixed point */
            u = *u_prev;
            continue;
        }
        double z = ((p0 - P[3 * q]) * T[3 * q] + (p1 - P[3 * q + 1]) * T[3 * q + 1])
                   + (p2 - P[3 * q + 2]) * T[3 * q + 2];
        u = (double)q / 255.0 + z / len;
        u = u < 0.0 ? 0.0 : (u > 1.0 ? 1.0 : u);
        *q_prev = q;
        *u_prev = u;
    }
    return u;
}

static double refine_u(const double p0, const double p1, const double p2,
                       __global const double *P, __global const double *T, const double len,
                       double u, const int refine_steps) {
    long q_prev = -1;
    double u_prev = 0.0;
    return refine_u_known(p0, p1, p2, P, T, len, u, refine_steps, &q_prev, &u_prev);
}
"""

_KERNEL_TEMPLATE = (
    KERNEL_HELPERS
    + r"""
/* The smooth ends' trim (sides._Trim.drop): Newton steps from the stored float u (the
   first pass's last step, q_prev and u_prev, spares most of them), then
   drop a voxel at an end (u 0 or 1) farther than cap along the tangent there, and with
   core >= 0 (the base side of a smooth wire) one farther than core from the wire;
   numpy's arithmetic, as in classify_one. Returns 0 (kept), 1 (dropped) or 2: the core
   test is too close to call without numpy's hypot (x^2 + y^2 within 1e-9 of core^2,
   relative), numpy decides. */
static uchar end_trim(const double p0, const double p1, const double p2,
                      __global const double *P, __global const double *T,
                      __global const double *X, __global const double *Y, const double len,
                      double u, const int refine_steps, const double cap, const double core,
                      long q_prev, double u_prev) {
    u = refine_u_known(p0, p1, p2, P, T, len, u, refine_steps, &q_prev, &u_prev);
    const long q = (long)rint_d(u * 255.0);
    const double d0 = p0 - P[3 * q], d1 = p1 - P[3 * q + 1], d2 = p2 - P[3 * q + 2];
    if (u <= 0.0 || u >= 1.0) {
        const double z = (d0 * T[3 * q] + d1 * T[3 * q + 1]) + d2 * T[3 * q + 2];
        if (fabs(z) > cap) return 1;
    }
    if (!(core >= 0.0)) return 0;
    const double x = (d0 * X[3 * q] + d1 * X[3 * q + 1]) + d2 * X[3 * q + 2];
    const double y = (d0 * Y[3 * q] + d1 * Y[3 * q + 1]) + d2 * Y[3 * q + 2];
    const double r2 = x * x + y * y, c2 = core * core;
    if (r2 > c2 * (1.0 + 1e-9)) return 1;
    if (r2 < c2 * (1.0 - 1e-9)) return 0;
    return 2;
}

/* The position of seed s in the sorted seed list; a line's next voxel mostly has the
   same nearest seed as the last, so the last answer is kept (*last_s, *last_a) and the
   binary search, whose branches a CPU mispredicts half the time, runs only on a change. */
static int seed_position(__global const int *seed_idx, const int n_seeds, const int s,
                         int *last_s, int *last_a) {
    if (s == *last_s) return *last_a;
    int a = 0, b = n_seeds - 1;
    while (a < b) {
        int m = (a + b) >> 1;
        if (seed_idx[m] < s) a = m + 1; else b = m;
    }
    *last_s = s;
    *last_a = a;
    return a;
}

static void classify_one(
@PARAMS@,
    const int k, const int j, const int i, int *last_s, int *last_a)
{
    const long v = ((long)i * n1 + j) * n2 + k;
    const int s = nearest[v];
    const int a = seed_position(seed_idx, n_seeds, s, last_s, last_a);
    const int w = seed_wire[a];
    const float u0 = seed_u[a];
    out_wire[v] = (short)w;
    out_u[v] = u0;
    out_flag[v] = 0;
    const int sk = s % n2, sr = s / n2;
    const int sj = sr % n1, si = sr / n1;
    const double e0 = (double)(i - si) * h0, e1 = (double)(j - sj) * h1;
    const double e2 = (double)(k - sk) * h2;
    const double d2 = (e0 * e0 + e1 * e1) + e2 * e2;
    if (!(d2 <= reach2[w])) return;

    const double p0 = lo0 + ((double)(i + r0) + 0.5) * h0;
    const double p1 = lo1 + ((double)(j + r1) + 0.5) * h1;
    const double p2 = lo2 + ((double)(k + r2) + 0.5) * h2;
    __global const double *P = points + (long)w * 256 * 3;
    __global const double *T = tangents + (long)w * 256 * 3;
    const double len = length[w];
    double u = (double)u0;
    long q_last = -1;  /* the last step's entry and result: the trim starts from them */
    double u_last = 0.0;
    u = refine_u_known(p0, p1, p2, P, T, len, u, refine_steps, &q_last, &u_last);
    out_u[v] = (float)u;

    const long q = (long)rint_d(u * 255.0);
    __global const float *F = frames + ((long)w * 256 + q) * 9;
    const float d0 = (float)(p0 - P[3 * q]), d1 = (float)(p1 - P[3 * q + 1]);
    const float dz = (float)(p2 - P[3 * q + 2]);
    const float x32 = (d0 * F[0] + d1 * F[3]) + dz * F[6];
    const float y32 = (d0 * F[1] + d1 * F[4]) + dz * F[7];
    const float z32 = (d0 * F[2] + d1 * F[5]) + dz * F[8];
    const int np = n_planes[w], ks = k_side[w];
    long plane = (long)rint_d(u * (double)(np - 1));
    plane = plane < 0 ? 0 : (plane > np - 1 ? np - 1 : plane);
    long ia, ib;
    if (base_side) {
        const int o = key_off[w];
        const double th = interp_keys(u, key_t + o, key_v + o, key_n[2 * w]);
        const int o2 = o + key_n[2 * w];
        const double sc = interp_keys(u, key_t + o2, key_v + o2, key_n[2 * w + 1]);
        double c;
        const double sn = sincos(th, &c);
        const double x = sc * (c * (double)x32 - sn * (double)y32);
        const double y = sc * (sn * (double)x32 + c * (double)y32);
        ia = (long)rint_d(x / px + mask_half[w]);
        ib = (long)rint_d(y / px + mask_half[w]);
    } else {
        ia = (long)rint_f(x32 / (float)px + (float)mask_half[w]);
        ib = (long)rint_f(y32 / (float)px + (float)mask_half[w]);
    }
    if (ia < 0 || ia >= ks || ib < 0 || ib >= ks) return;
    const int ends = (u <= 0.0) || (u >= 1.0);
    if (ends && !(fabs(z32) <= cap32)) return;
    const uchar flag = masks[mask_off[w] + (plane * ks + ia) * ks + ib];
    out_flag[v] = flag;
    if (flag && trim_cap[w] >= 0.0) {
        const uchar t = end_trim(p0, p1, p2, P, T, axis_x + (long)w * 256 * 3,
                                 axis_y + (long)w * 256 * 3, len, (double)(float)u,
                                 refine_steps, trim_cap[w], trim_core[w], q_last, u_last);
        out_flag[v] = t == 2 ? 2 : !t;
    }
}

/* One work-item per line along the middle axis (few work-groups: PoCL pays per
   work-group); neighbouring work-items take neighbouring voxels of the contiguous
   axis, so their loads and stores are contiguous (vector lanes on a CPU, coalesced on
   a GPU). */
__kernel void classify(
@PARAMS@)
{
    const int k = get_global_id(0), i = get_global_id(1);
    if (k >= n2 || i >= n0) return;
    int last_s = -1, last_a = 0;  /* seed indices are >= 0: no voxel reuses this */
    for (int j = 0; j < n1; j++)
        classify_one(@ARGS@, k, j, i, &last_s, &last_a);
}
"""
)

#: the arguments of the kernel (and of its per-voxel body)
_PARAMS = r"""
    __global const int *nearest,      /* C-order flat seed index per region voxel */
    __global const int *seed_idx,     /* sorted flat indices of the seeds */
    __global const short *seed_wire,
    __global const float *seed_u,
    const int n_seeds,
    const int n0, const int n1, const int n2,
    const double lo0, const double lo1, const double lo2,
    const double h0, const double h1, const double h2,
    const long r0, const long r1, const long r2,
    __global const double *reach2,     /* per wire */
    __global const double *points,     /* per wire 256 x 3 */
    __global const double *tangents,   /* per wire 256 x 3 */
    __global const float *frames,      /* per wire 256 x 3 x 3, float32 */
    __global const double *length,     /* per wire */
    __global const int *n_planes,
    __global const int *k_side,
    __global const double *mask_half,
    __global const long *mask_off,
    __global const uchar *masks,
    __global const int *key_off,       /* per wire: twist first, then scale, counts */
    __global const int *key_n,
    __global const double *key_t,
    __global const double *key_v,
    const double px,
    const float cap32,
    const int base_side,
    const int refine_steps,
    __global const double *trim_cap,   /* per wire: the end trim's cap (mm), < 0: none */
    __global const double *trim_core,  /* per wire: its core radius (mm), < 0: none */
    __global const double *axis_x,     /* per wire 256 x 3: the frames' x, y axes */
    __global const double *axis_y,
    __global short *out_wire,
    __global float *out_u,
    __global uchar *out_flag
"""
_ARGS = ", ".join(
    re.split(r"[\s*]+", p.strip())[-1]
    for p in re.sub(r"/\*.*?\*/", "", _PARAMS).replace("\n", " ").split(",")
)
_KERNEL = _KERNEL_TEMPLATE.replace("@PARAMS@", _PARAMS.strip("\n")).replace("@ARGS@", _ARGS)


@dataclass
class WireGeometry:
    """One wire's data for the classification on one side (modified or base)."""

    #: (256, 3) table points, unit tangents (float64) and frames (256, 3, 3)
    points: np.ndarray
    tangents: np.ndarray
    frames: np.ndarray
    length: float
    #: reach (mm) from the nearest seed beyond which nothing is flagged
    reach: float
    #: the grown masks (planes, K, K) and (K - 1) / 2
    mask: np.ndarray
    half: float
    #: twist and scale keys ((K, 2): u, value); used on the base side only
    twist: np.ndarray
    scale: np.ndarray


@dataclass
class ClassifyInput:
    """What the classification pass needs besides the nearest-seed buffer."""

    seed_idx: np.ndarray  # sorted flat region indices of the seeds
    seed_wire: np.ndarray
    seed_u: np.ndarray
    rshape: tuple[int, int, int]
    lo: np.ndarray
    h: np.ndarray
    region_lo: np.ndarray
    wires: Sequence[WireGeometry]
    px: float
    cap: float
    base_side: bool
    refine_steps: int
    #: per wire, the smooth ends' trim of :class:`~voxwarp.deform.wires.sides._Trim` run
    #: in the pass on the flagged voxels: (cap, core) in mm, core < 0 for no core test,
    #: cap < 0 (or None) for no trim there
    trim: np.ndarray | None = None


#: compiled kernel per OpenCL context, keyed by id() but kept with its context: a
#: context made after another was freed may reuse its id (the tests reset the state),
#: and the old context's kernel then fails with INVALID_CONTEXT
_programs: dict[int, tuple[object, object | None]] = {}


def classify_available(st: dict) -> bool:
    """Whether the OpenCL state ``st`` (of :mod:`voxwarp.deform.wires.propagation`) can run the
    pass: a device with double precision whose program builds."""
    return fp64_kernel(st, _programs, _KERNEL, "classify") is not None


def _program(st: dict) -> object | None:
    return fp64_kernel(st, _programs, _KERNEL, "classify")


def fp64_kernel(
    st: dict, programs: dict[int, tuple[object, object | None]], source: str, name: str
) -> object | None:
    """Kernel ``name`` of ``source`` built on the OpenCL state ``st``'s context, kept in
    ``programs`` with its context; None without a double-precision device or when the
    program does not build (the caller keeps numpy)."""
    if "error" in st or "cl_khr_fp64" not in st["device"].extensions:
        return None
    ctx = st["ctx"]
    entry = programs.get(id(ctx))
    if entry is None or entry[0] is not ctx:
        try:
            prg = st["cl"].Program(ctx, source).build(options=["-w"])
            kernel: object | None = st["cl"].Kernel(prg, name)
        except Exception as exc:  # any build failure: the caller keeps the numpy path
            kernel = None
            warnings.warn(_build_failure(name, st["device"], exc), RuntimeWarning, stacklevel=3)
        entry = (ctx, kernel)
        programs[id(ctx)] = entry
    return entry[1]


def _build_failure(name: str, device: object, exc: Exception) -> str:
    """One line: which kernel did not build on which device, the compiler's first
    error, and that numpy takes over (same field, slower)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    first = next((ln for ln in lines if ln.lower().startswith("error")), None)
    first = first or (lines[0] if lines else type(exc).__name__)
    where = getattr(device, "name", "the OpenCL device").strip()
    return (
        f"the wire field's OpenCL {name!r} kernel did not build on {where} ({first[:160]});"
        " numpy computes the same field, more slowly"
    )


def _device(st: dict, a: np.ndarray) -> object:
    cl = st["cl"]
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
    a = np.ascontiguousarray(a)
    if a.nbytes == 0:
        a = np.zeros(1, dtype=a.dtype)
    return cl.Buffer(st["ctx"], flags, hostbuf=a)


def _wire_buffers(st: dict, wires: Sequence[WireGeometry]) -> list[object]:
    masks = [np.ascontiguousarray(g.mask, dtype=np.uint8).ravel() for g in wires]
    mask_off = np.cumsum([0] + [len(m) for m in masks[:-1]]).astype(np.int64)
    keys = [np.concatenate([g.twist, g.scale]) for g in wires]
    key_off = np.cumsum([0] + [len(k) for k in keys[:-1]]).astype(np.int32)
    key_n = np.array([[len(g.twist), len(g.scale)] for g in wires], dtype=np.int32)
    allkeys = np.concatenate(keys)
    arrays = [
        np.array([g.reach**2 for g in wires], dtype=np.float64),
        np.stack([g.points for g in wires]).astype(np.float64),
        np.stack([g.tangents for g in wires]).astype(np.float64),
        np.stack([g.frames for g in wires]).astype(np.float32),
        np.array([g.length for g in wires], dtype=np.float64),
        np.array([g.mask.shape[0] for g in wires], dtype=np.int32),
        np.array([g.mask.shape[1] for g in wires], dtype=np.int32),
        np.array([g.half for g in wires], dtype=np.float64),
        mask_off,
        np.concatenate(masks),
        key_off,
        key_n.ravel(),
        allkeys[:, 0].copy(),
        allkeys[:, 1].copy(),
    ]
    return [_device(st, a) for a in arrays]


def _trim_buffers(st: dict, inp: ClassifyInput) -> list[object]:
    """The trim's per-wire caps and cores (-1: none) and the frames' x and y axes."""
    n = len(inp.wires)
    trim = np.full((n, 2), -1.0) if inp.trim is None else np.asarray(inp.trim, np.float64)
    axes = [np.stack([g.frames[:, :, a] for g in inp.wires]).astype(np.float64) for a in (0, 1)]
    return [_device(st, a) for a in (trim[:, 0].copy(), trim[:, 1].copy(), *axes)]


def classify(
    st: dict, nearest_buf: object, inp: ClassifyInput
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run the pass over a region whose nearest-seed indices are in ``nearest_buf``.

    Parameters
    ----------
    st
        The OpenCL state of :mod:`voxwarp.deform.wires.propagation` (its lock held).
    nearest_buf
        Device buffer of int32 C-order nearest-seed indices over ``inp.rshape``.
    inp
        Seeds, region geometry and per-wire data.

    Returns
    -------
    tuple of np.ndarray
        (wire int16, u float32, flag bool), each of shape ``inp.rshape`` (C order), and
        the flat indices of the flagged voxels whose trim's core test the pass left to
        numpy (set in the flags; see :attr:`ClassifyInput.trim`).
    """
    cl, queue = st["cl"], st["queue"]
    kernel = _program(st)
    out_wire = np.empty(inp.rshape, dtype=np.int16)
    out_u = np.empty(inp.rshape, dtype=np.float32)
    out_flag = np.empty(inp.rshape, dtype=np.uint8)
    bufs = [
        cl.Buffer(st["ctx"], cl.mem_flags.WRITE_ONLY, a.nbytes) for a in (out_wire, out_u, out_flag)
    ]
    i32, f64, i64 = np.int32, np.float64, np.int64
    args = [
        nearest_buf,
        _device(st, inp.seed_idx.astype(np.int32)),
        _device(st, inp.seed_wire.astype(np.int16)),
        _device(st, inp.seed_u.astype(np.float32)),
        i32(len(inp.seed_idx)),
        *(i32(v) for v in inp.rshape),
        *(f64(v) for v in inp.lo),
        *(f64(v) for v in inp.h),
        *(i64(v) for v in inp.region_lo),
        *_wire_buffers(st, inp.wires),
        f64(inp.px),
        np.float32(inp.cap),
        i32(1 if inp.base_side else 0),
        i32(inp.refine_steps),
        *_trim_buffers(st, inp),
        *bufs,
    ]
    n0, _, n2 = inp.rshape
    lx = 16  # PoCL picks huge work-groups by itself (see voxwarp.deform.wires.propagation)
    kernel(queue, ((n2 + lx - 1) // lx * lx, n0), (lx, 1), *args)  # type: ignore[operator]
    for host, dev in zip((out_wire, out_u, out_flag), bufs, strict=True):
        cl.enqueue_copy(queue, host, dev, is_blocking=False)
    queue.finish()
    undecided = np.zeros(0, dtype=np.int64)
    if inp.trim is not None and np.any(np.asarray(inp.trim)[:, 1] >= 0):
        flat = out_flag.reshape(-1)
        undecided = np.flatnonzero(flat == 2)
        flat[undecided] = 1
    return out_wire, out_u, out_flag.view(bool), undecided
