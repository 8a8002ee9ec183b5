"""The fade weights of the wire field build in one OpenCL pass (bit for bit numpy's).

:meth:`voxwarp.deform.wires.sides.SidePasses._weights` needs, for every swept voxel and
its neighbours, the displacement weight of :func:`voxwarp.deform.wires.geometry._fade`:
Newton steps of u from the stored float u, the voxel's coordinates (x, y, z) in the
modified wire's frame, a smoothstep of ``hypot(x, y)`` past the (scaled) radius and one
of the distance beyond an end, their product rounded to float32. numpy runs that over
chunks of voxels, a dozen full-chunk float64 temporaries per step; here one work-item
per voxel does the same operations in the same order (float64, ``FP_CONTRACT OFF``, the
helpers of :mod:`voxwarp.deform.wires.classify`), so the bits are numpy's except where
``hypot`` enters: the device's ``sqrt(x*x + y*y)`` and numpy's ``hypot`` differ by a few
ulp. The weight falls with that radius, so the kernel evaluates it at the radius
:data:`RADIUS_MARGIN` (relative) below and above, pads each by :data:`WEIGHT_MARGIN`
(the rounding of the rest) and keeps the float32 weight only where both round to the
same float32: numpy's lies between them (a weight exactly 1 or 0 in the radial fade,
clamped for both radii, is exact). Elsewhere it writes NaN and the caller computes those
voxels with numpy: 0.37-0.39 % of them on the MRI head, mostly weights below ~1e-3, where
float32's steps are as fine as the margins.

Use: ``w = fades(st, inp)`` (``st`` the OpenCL state of
:mod:`voxwarp.deform.wires.propagation`, held under its lock), NaN where numpy decides.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from voxwarp.deform.wires.classify import KERNEL_HELPERS, fp64_kernel
from voxwarp.deform.wires.constants import RADIAL_FADE
from voxwarp.deform.wires.tables import WireTables
from voxwarp.deform.wires.wire import Wire

#: relative bound on |device sqrt(x*x + y*y) - numpy hypot(x, y)|: glibc's hypot is
#: within 1 ulp of the exact radius, the (correctly rounded) sqrt of the rounded sum of
#: squares within ~1.25 ulp, so they differ by < 2.5 ulp (5.5e-16); a wide margin (for
#: hosts whose libm hypot is less exact): 1e-13 instead handed back as many voxels
RADIUS_MARGIN = 1e-12
#: bound on the float64 rounding of the weight's other operations, per unit of the
#: terms it is made of (1 + radius / fade width + distance beyond the end / falloff):
#: a few ulp each, 2.2e-16; a hundredfold margin
WEIGHT_MARGIN = 1e-13

_KERNEL = (
    KERNEL_HELPERS
    + r"""
static inline double smoothstep(double x) {
    x = x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x);
    return x * x * (3.0 - 2.0 * x);
}

__kernel void fade(
    __global const int *flat,        /* C-order flat region indices */
    __global const short *wire,      /* their nearest seed's wire */
    __global const float *u_in,      /* their stored u */
    const int n_voxels,
    const int n1, const int n2,
    const double lo0, const double lo1, const double lo2,
    const double h0, const double h1, const double h2,
    const long r0, const long r1, const long r2,
    __global const double *points,   /* per wire 256 x 3, modified side */
    __global const double *tangents,
    __global const double *axis_x,
    __global const double *axis_y,
    __global const double *length,
    __global const int *mode,        /* per wire: 0 no fade, 1 sides only, 2 smooth ends */
    __global const double *radius,
    __global const double *side_falloff, /* < 0: the radial fade is RADIAL_FADE x rm */
    __global const double *falloff,
    __global const int *key_off,     /* per wire: its scale keys */
    __global const int *key_n,
    __global const double *key_t,
    __global const double *key_v,
    const int refine_steps,
    const double radial_fade,
    const double radius_margin,
    const double weight_margin,
    __global float *out)
{
    const int g = get_global_id(0);
    if (g >= n_voxels) return;
    const int w = wire[g];
    if (mode[w] == 0) { out[g] = 1.0f; return; }
    const long f = flat[g];
    const long k = f % n2, rest = f / n2;
    const long j = rest % n1, i = rest / n1;
    const double p0 = lo0 + ((double)(i + r0) + 0.5) * h0;
    const double p1 = lo1 + ((double)(j + r1) + 0.5) * h1;
    const double p2 = lo2 + ((double)(k + r2) + 0.5) * h2;
    __global const double *P = points + (long)w * 256 * 3;
    __global const double *T = tangents + (long)w * 256 * 3;
    __global const double *X = axis_x + (long)w * 256 * 3;
    __global const double *Y = axis_y + (long)w * 256 * 3;
    const double u = refine_u(p0, p1, p2, P, T, length[w], (double)u_in[g], refine_steps);
    const long q = (long)rint_d(u * 255.0);
    const double d0 = p0 - P[3 * q], d1 = p1 - P[3 * q + 1], d2 = p2 - P[3 * q + 2];
    const double x = (d0 * X[3 * q] + d1 * X[3 * q + 1]) + d2 * X[3 * q + 2];
    const double y = (d0 * Y[3 * q] + d1 * Y[3 * q + 1]) + d2 * Y[3 * q + 2];
    const double rm = radius[w] * interp_keys(u, key_t + key_off[w], key_v + key_off[w],
                                              key_n[w]);
    const double width = side_falloff[w] >= 0.0 ? side_falloff[w] : radial_fade * rm;
    const double r = sqrt(x * x + y * y);
    /* numpy's radius lies within r (1 -+ radius_margin): the radial fade's argument
       between xs and xb (fp subtraction and division keep the order) */
    const double xs = (r * (1.0 - radius_margin) - rm) / width;
    const double xb = (r * (1.0 + radius_margin) - rm) / width;
    double along = 1.0, scale = 1.0 + r / width;
    if (mode[w] == 2) {
        const double z = (d0 * T[3 * q] + d1 * T[3 * q + 1]) + d2 * T[3 * q + 2];
        const double a = u >= 1.0 ? (z > 0.0 ? z : 0.0) : 0.0;
        const double b = u <= 0.0 ? (-z > 0.0 ? -z : 0.0) : 0.0;
        along = 1.0 - smoothstep((a + b) / falloff[w]);
        scale += (a + b) / falloff[w];
    }
    if (xb <= 0.0) { out[g] = (float)along; return; }  /* radial exactly 1 */
    if (xs >= 1.0 || along == 0.0) { out[g] = 0.0f; return; }  /* exactly 0 */
    /* the weight falls with the radius; each bound padded by the float64 rounding of
       its evaluation (relative to the terms it is made of) */
    const double pad = weight_margin * scale;
    const float up = (float)((1.0 - smoothstep(xs)) * along + pad);
    const float down = (float)((1.0 - smoothstep(xb)) * along - pad);
    out[g] = up == down ? up : NAN;
}
"""
)


@dataclass
class FadeInput:
    """What the fade pass needs: the voxels (flat region indices, their wire and stored
    u), the region (shape, first voxel) on the field's grid (box corner ``lo``, voxel
    size ``h``), the wires and their tables, and the Newton steps of u."""

    flat: np.ndarray
    wire: np.ndarray
    u: np.ndarray
    rshape: tuple[int, int, int]
    region_lo: np.ndarray
    lo: np.ndarray
    h: np.ndarray
    wires: Sequence[Wire]
    tables: Sequence[WireTables]
    refine_steps: int


#: compiled kernel per OpenCL context, kept with its context (see classify._programs)
_programs: dict[int, tuple[object, object | None]] = {}


def fade_available(st: dict) -> bool:
    """Whether the OpenCL state ``st`` can run the pass (double precision, it builds)."""
    return _program(st) is not None


def _program(st: dict) -> object | None:
    return fp64_kernel(st, _programs, _KERNEL, "fade")


def _wire_arrays(inp: FadeInput) -> list[np.ndarray]:
    """The per-wire tables and parameters, in the kernel's argument order."""
    ws, tabs = inp.wires, inp.tables
    keys = [np.asarray(w.scale, dtype=np.float64) for w in ws]
    key_off = np.cumsum([0] + [len(k) for k in keys[:-1]]).astype(np.int32)
    allkeys = np.concatenate(keys)
    mode = [0 if not w.fades else (2 if w.smooth else 1) for w in ws]
    frames = np.stack([t.modified_frames for t in tabs]).astype(np.float64)
    return [
        np.stack([t.modified_points for t in tabs]).astype(np.float64),
        *(np.ascontiguousarray(frames[:, :, :, a]) for a in (2, 0, 1)),
        np.array([t.length_modified for t in tabs], dtype=np.float64),
        np.array(mode, dtype=np.int32),
        np.array([w.radius for w in ws], dtype=np.float64),
        np.array([w.side_falloff if w.smooth_sides else -1.0 for w in ws], dtype=np.float64),
        np.array([w.falloff if w.smooth else 1.0 for w in ws], dtype=np.float64),
        key_off,
        np.array([len(k) for k in keys], dtype=np.int32),
        allkeys[:, 0].copy(),
        allkeys[:, 1].copy(),
    ]


def fades(st: dict, inp: FadeInput) -> np.ndarray:
    """The float32 fade weight of each voxel of ``inp`` (1 for a wire without fade), NaN
    where the pass cannot tell numpy's float32 (see the module's notes). ``st``: the
    OpenCL state of :mod:`voxwarp.deform.wires.propagation`, its lock held."""
    cl, queue = st["cl"], st["queue"]
    n = len(inp.flat)
    out = np.empty(n, dtype=np.float32)
    if n == 0:
        return out
    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR

    def dev(a: np.ndarray) -> object:
        return cl.Buffer(st["ctx"], flags, hostbuf=np.ascontiguousarray(a))

    out_buf = cl.Buffer(st["ctx"], cl.mem_flags.WRITE_ONLY, out.nbytes)
    i32, f64, i64 = np.int32, np.float64, np.int64
    args = [
        dev(inp.flat.astype(np.int32)),
        dev(inp.wire.astype(np.int16)),
        dev(inp.u.astype(np.float32)),
        i32(n),
        i32(inp.rshape[1]),
        i32(inp.rshape[2]),
        *(f64(v) for v in inp.lo),
        *(f64(v) for v in inp.h),
        *(i64(v) for v in inp.region_lo),
        *(dev(a) for a in _wire_arrays(inp)),
        i32(inp.refine_steps),
        f64(RADIAL_FADE),
        f64(RADIUS_MARGIN),
        f64(WEIGHT_MARGIN),
        out_buf,
    ]
    lx = 64
    _program(st)(queue, ((n + lx - 1) // lx * lx,), (lx,), *args)  # type: ignore[operator]
    cl.enqueue_copy(queue, out, out_buf, is_blocking=True)
    return out
