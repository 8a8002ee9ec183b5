"""Nearest-seed propagation: every voxel learns which seed voxel is closest to it.

About this technique (the distance transform of the wire paper, section 5)
--------------------------------------------------------------------------
A wire deformation needs, for every voxel of the volume, the wire that influences it and
the curve parameter ``t`` of the closest point on that wire. Both are known exactly at a
few thousand *seed* voxels (the corners of the cells a wire passes through, rasterised by
the caller, each labelled with its wire id and closest ``t``); :func:`nearest_seed`
*propagates* them: it returns, for every voxel, the flat index of its nearest seed voxel
(Euclidean distance with anisotropic voxel spacing), so ``wire_id[voxel] =
seed_wire_id.flat[nearest]`` and ``t[voxel] = seed_t.flat[nearest]`` are one gather each.
This is the feature transform (the "closest feature" variant of the Euclidean distance
transform); the distance itself is never needed by the caller and is not returned.

Algorithm (exact, separable; Felzenszwalb & Huttenlocher 2012, "Distance transforms of
sampled functions", the lower envelope of parabolas; the same decomposition as Meijster
et al. 2000 and Maurer et al. 2003), one OpenCL work-item per 1D line per pass:

1. along the axis that is contiguous in memory, the nearest seed on the same line, by a
   forward and a backward sweep (stored: that seed's coordinate along the axis, int16);
2. along the middle axis, the lower envelope of the parabolas
   ``f(j) + ((y - j) h)^2``, where ``f(j)`` is pass 1's squared distance in line ``j``;
   the winning column's two coordinates are carried (stored packed in an int32);
3. along the slowest axis, the same envelope over pass 2's squared distances; the
   winner's three coordinates give the flat C-order index, written to the output.

Each pass is ``O(n)`` per line, so the whole transform is ``O(N)`` for ``N`` voxels
(compare jump flooding: ``O(N log n)`` and approximate). Pass order follows the input's
memory layout (C-, Fortran- or any axis-permuted contiguous order; anything else is
copied once), so pass 1 streams memory and passes 2 and 3 read lines whose neighbours
are handled by adjacent work-items. Device memory: the input (1 byte/voxel), pass 2's
int32 and the int32 output (which first holds pass 1's int16): 9 bytes per voxel (151 MB
at 256^3); per work-item ~14 KB of private arrays for a line of up to :data:`MAX_LINE`
voxels (longer axes: ``"auto"`` uses scipy, ``"opencl"`` raises).

Ties: along each line the lower coordinate wins an exact tie (pass 1: the seed before
the voxel; passes 2, 3: the envelope keeps the parabola with the lower vertex at an exact
crossing). Near-ties within float32 rounding of the squared distance may go either way;
scipy resolves ties its own way, so the two backends may pick different seeds at equal
distance (the distance to the chosen seed agrees to float32 rounding).

Backends: ``"opencl"`` (above; the context, queue and program are built once per
process, and PoCL also caches the compiled binary on disk), ``"scipy"``
(``scipy.ndimage.distance_transform_edt(~seeds, sampling, return_indices=True,
return_distances=False)``, single-threaded) and ``"auto"`` (OpenCL when a platform
exists, else scipy with an :class:`OpenCLUnavailableWarning`, once per process). A GPU
device is preferred when one exists, else a CPU device (PoCL's ``pip install
pocl-binary-distribution`` gives one everywhere; the GPU path runs the same kernels but
has not been measured). Set the environment variable ``VOXWARP_OPENCL=0`` to switch the
OpenCL backend off (``"auto"`` then uses scipy; ``"opencl"`` raises), e.g. to test the fallback
or to work around a broken driver.

Measurements (OpenCL against scipy, kernel build and buffer allocation): docs/benchmarks.md,
section 'voxwarp.deform.wires.propagation: OpenCL vs scipy'; the timing helper is
:func:`benchmarks.propagation.benchmark_nearest_seed`.
"""

from __future__ import annotations

import os
import threading
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from voxwarp.deform.warp import WarpError

#: Longest line (voxels along any axis) the OpenCL kernels handle (private arrays).
MAX_LINE = 1024
#: Largest ratio between two voxel spacings (keeps float32 squared distances finite).
MAX_SAMPLING_RATIO = 1e6
#: Backends accepted by :func:`nearest_seed`.
BACKENDS: tuple[str, ...] = ("auto", "opencl", "scipy")
#: How to get an OpenCL platform (quoted in warnings and errors).
OPENCL_FIX = (
    "install an OpenCL ICD: your GPU's, or PoCL for the CPU (Debian/Ubuntu: "
    "apt-get install pocl-opencl-icd; elsewhere pip install pocl-binary-distribution)"
)
#: Environment variable; ``0`` / ``false`` / ``off`` / ``no`` disables the OpenCL backend.
ENV_VAR = "VOXWARP_OPENCL"

T = TypeVar("T")


class OpenCLUnavailableWarning(RuntimeWarning):
    """``backend="auto"`` found no usable OpenCL platform and fell back to scipy."""


_KERNELS = r"""
#define MAXLEN %(maxlen)d

/* Felzenszwalb-Huttenlocher: add the parabola of sample q (height fq, carried seed c of
   type T) to the lower envelope v/cv/fv with boundaries z (k: its last index, -1 when
   empty); used inside the loop over q of passes 2 and 3. */
#define ENVELOPE_PUSH(T)                                                           \
    if (k < 0) {                                                                   \
        k = 0; v[0] = (ushort)q; cv[0] = (T)c; fv[0] = fq;                         \
        z[0] = -INFINITY; z[1] = INFINITY;                                         \
        continue;                                                                  \
    }                                                                              \
    {                                                                              \
        float s;                                                                   \
        for (;;) {                                                                 \
            const int p = v[k];                                                    \
            s = 0.5f * ((fq - fv[k]) / (float)(q - p) + (float)(q + p));           \
            if (s > z[k]) break;                                                   \
            --k;                                                                   \
        }                                                                          \
        ++k;                                                                       \
        v[k] = (ushort)q; cv[k] = (T)c; fv[k] = fq; z[k] = s; z[k + 1] = INFINITY; \
    }

/* Pass 1, along the contiguous axis (length n2): nearest seed on the line. */
__kernel void pass_contig(__global const uchar *seeds, __global short *near,
                          const int n2, const int n1, const int n0)
{
    const int i1 = get_global_id(0);
    const int i0 = get_global_id(1);
    if (i1 >= n1 || i0 >= n0) return;
    const size_t base = ((size_t)i0 * n1 + i1) * n2;
    __global const uchar *s = seeds + base;
    __global short *o = near + base;
    int last = -1;
    for (int k = 0; k < n2; ++k) {
        if (s[k]) last = k;
        o[k] = (short)last;
    }
    if (last < 0) return;
    int next = -1;
    for (int k = n2 - 1; k >= 0; --k) {
        const int prev = o[k];
        if (prev == k) { next = k; continue; }
        if (next >= 0 && (prev < 0 || next - k < k - prev)) o[k] = (short)next;
    }
}

/* Pass 2, along the middle axis (length n1, stride n2). f = ((i2 - c) h2)^2 / h1^2. */
__kernel void pass_mid(__global const short *near, __global int *outp,
                       const int n2, const int n1, const int n0, const float r2)
{
    const int i2 = get_global_id(0);
    const int i0 = get_global_id(1);
    if (i2 >= n2 || i0 >= n0) return;
    const size_t base = (size_t)i0 * n1 * n2 + i2;
    __global const short *in = near + base;
    __global int *o = outp + base;
    ushort v[MAXLEN];
    short cv[MAXLEN];
    float fv[MAXLEN];
    float z[MAXLEN + 1];
    int k = -1;
    for (int q = 0; q < n1; ++q) {
        const int c = in[(size_t)q * n2];
        if (c < 0) continue;
        const float d = (float)(i2 - c);
        const float fq = d * d * r2;
        ENVELOPE_PUSH(short)
    }
    if (k < 0) {
        for (int q = 0; q < n1; ++q) o[(size_t)q * n2] = -1;
        return;
    }
    int j = 0;
    for (int q = 0; q < n1; ++q) {
        while (z[j + 1] < (float)q) ++j;
        o[(size_t)q * n2] = ((int)v[j] << 16) | (int)cv[j];
    }
}

/* Pass 3, along the slowest axis (length n0, stride n1 n2); writes flat seed indices. */
__kernel void pass_slow(__global const int *packed, __global int *outp,
                        const int n2, const int n1, const int n0,
                        const float r1, const float r2,
                        const int fs0, const int fs1, const int fs2,
                        const int os0, const int os1, const int os2)
{
    const int i2 = get_global_id(0);
    const int i1 = get_global_id(1);
    if (i2 >= n2 || i1 >= n1) return;
    const size_t stride = (size_t)n1 * n2;
    __global const int *in = packed + (size_t)i1 * n2 + i2;
    __global int *o = outp + (size_t)i1 * os1 + (size_t)i2 * os2;
    ushort v[MAXLEN];
    int cv[MAXLEN];
    float fv[MAXLEN];
    float z[MAXLEN + 1];
    int k = -1;
    for (int q = 0; q < n0; ++q) {
        const int c = in[(size_t)q * stride];
        if (c < 0) continue;
        const float d1 = (float)(i1 - (c >> 16));
        const float d2 = (float)(i2 - (c & 0xffff));
        const float fq = d1 * d1 * r1 + d2 * d2 * r2;
        ENVELOPE_PUSH(int)
    }
    if (k < 0) {
        for (int q = 0; q < n0; ++q) o[(size_t)q * os0] = -1;
        return;
    }
    int j = 0;
    for (int q = 0; q < n0; ++q) {
        while (z[j + 1] < (float)q) ++j;
        const int c = cv[j];
        o[(size_t)q * os0] = (int)v[j] * fs0 + (c >> 16) * fs1 + (c & 0xffff) * fs2;
    }
}
"""

# ------------------------------------------------------------------ OpenCL state
_cl_state: dict[str, Any] | None = None  # context, queue, kernels, buffers; or {"error"}
_warned = False
_last_backend = ""
_lock = threading.RLock()


def _env_disabled() -> bool:
    return os.environ.get(ENV_VAR, "").strip().lower() in ("0", "false", "off", "no")


def _ranked_devices(cl: Any) -> list[Any]:
    """Every OpenCL device, GPUs first, then those with double precision (the
    classification pass needs it), most compute units first; platform order breaks ties."""
    devices = []
    for platform in cl.get_platforms():
        try:
            devices.extend(platform.get_devices())
        except cl.Error:  # a platform without devices raises
            continue
    if not devices:
        raise RuntimeError("no OpenCL device found")

    def rank(d: Any) -> tuple[int, int, int]:
        is_gpu = bool(d.type & cl.device_type.GPU)
        fp64 = "cl_khr_fp64" in d.extensions
        return (0 if is_gpu else 1, 0 if fp64 else 1, -int(d.max_compute_units))

    return sorted(devices, key=rank)


def _opencl_state() -> dict[str, Any]:
    """Build (once per process) and return the OpenCL state, or ``{"error": reason}``."""
    global _cl_state
    with _lock:
        if _cl_state is None:
            _cl_state = _build_state()
        return _cl_state


def _build_state() -> dict[str, Any]:
    """The first device, in :func:`_ranked_devices` order, whose kernels build: a driver
    can list a device and still fail to compile for it (the PoCL that pyopencl's wheels
    bundle does on CPUs its LLVM does not know, e.g. AMD Zen 5: "unknown target CPU
    'generic'"), and another platform's device may work."""
    try:
        import pyopencl as cl

        devices = _ranked_devices(cl)
    except Exception as exc:  # no pyopencl, no ICD loader, no platform
        return {"error": _one_line(exc)}
    failures = []
    for device in devices:
        try:
            return _device_state(cl, device)
        except Exception as exc:  # this device cannot build or run: try the next one
            failures.append(f"{device.name.strip()}: {_one_line(exc)}")
    return {"error": "; ".join(failures)[:400]}


def _one_line(exc: Exception) -> str:
    return f"{type(exc).__name__}: {exc}".splitlines()[0][:200]


def _device_state(cl: Any, device: Any) -> dict[str, Any]:
    ctx = cl.Context([device])
    queue = cl.CommandQueue(ctx)
    prg = cl.Program(ctx, _KERNELS % {"maxlen": MAX_LINE}).build(options=["-w"])
    kernels = {name: cl.Kernel(prg, name) for name in ("pass_contig", "pass_mid", "pass_slow")}
    return {
        "cl": cl,
        "ctx": ctx,
        "queue": queue,
        "prg": prg,
        "kernels": kernels,
        "device": device,
        "buffers": {},
    }


def _reset_opencl_cache() -> None:
    """Forget the OpenCL state and the warned-once flag (for tests)."""
    global _cl_state, _warned, _last_backend
    with _lock:
        _cl_state = None
        _warned = False
        _last_backend = ""


def release_opencl_buffers() -> None:
    """Free the device buffers kept between :func:`nearest_seed` calls.

    The OpenCL backend keeps its buffers (9 bytes per voxel: 151 MB at 256^3) for the
    next call of a similar size, which saves allocating them again; call this when no
    more propagation is expected. The context and the compiled kernels stay.
    """
    with _lock:
        if _cl_state is not None and "buffers" in _cl_state:
            _cl_state["buffers"].clear()


def opencl_available() -> bool:
    """Whether the OpenCL backend can run here.

    Returns
    -------
    bool
        False when ``VOXWARP_OPENCL=0`` is set or no OpenCL platform/device can be
        opened; the first call builds the context and the kernels (cached per process).
    """
    if _env_disabled():
        return False
    return "error" not in _opencl_state()


def opencl_device_name() -> str:
    """Name of the OpenCL device :func:`nearest_seed` uses, or ``""`` when unavailable."""
    if not opencl_available():
        return ""
    st = _opencl_state()
    return f"{st['device'].platform.name}: {st['device'].name}"


def _unavailable_reason() -> str:
    if _env_disabled():
        return f"{ENV_VAR}={os.environ.get(ENV_VAR)} is set (unset it to enable OpenCL)"
    return _opencl_state().get("error", "")


def last_backend() -> str:
    """The backend the latest :func:`nearest_seed` call of this process used.

    Returns
    -------
    str
        ``"opencl"`` or ``"scipy"``; ``""`` before the first call.
    """
    return _last_backend


# ------------------------------------------------------------------ validation
def _check_seeds(seeds: Any) -> np.ndarray:
    arr = np.asarray(seeds)
    if arr.ndim != 3:
        raise WarpError(
            f"seeds must be a 3D boolean array (nx, ny, nz); got {arr.ndim}D shape {arr.shape}"
        )
    if 0 in arr.shape:
        raise WarpError(f"seeds must have at least one voxel per axis; got shape {arr.shape}")
    if arr.dtype == np.bool_:
        return arr
    if arr.dtype.kind in "iu":
        if arr.size and (arr.min() < 0 or arr.max() > 1):
            raise WarpError(
                "seeds must be boolean (or integers 0/1); got integers outside {0, 1}: "
                "pass seeds != 0 or seeds.astype(bool)"
            )
        return arr.astype(np.bool_)
    raise WarpError(
        f"seeds must be a boolean array (or integers 0/1); got dtype {arr.dtype}: "
        "pass seeds.astype(bool)"
    )


def check_sampling(sampling: Any) -> tuple[float, float, float]:
    try:
        s = np.asarray(sampling, dtype=np.float64)
    except (TypeError, ValueError):
        s = np.asarray([np.nan])
    if s.ndim == 0:
        s = np.repeat(s, 3)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise WarpError(
            f"sampling must be one positive number or 3 positive voxel spacings (x, y, z) "
            f"in mm; got {sampling!r:.80}"
        )
    if s.max() > MAX_SAMPLING_RATIO * s.min():
        raise WarpError(
            f"voxel spacings {tuple(s.tolist())} differ by more than {MAX_SAMPLING_RATIO:g}x; "
            "resample the volume to less extreme spacings"
        )
    return (float(s[0]), float(s[1]), float(s[2]))


# ------------------------------------------------------------------ backends
def _nearest_scipy(seeds: np.ndarray, sampling: tuple[float, float, float]) -> np.ndarray:
    from scipy import ndimage

    idx = ndimage.distance_transform_edt(
        ~seeds, sampling=sampling, return_distances=False, return_indices=True
    )
    return np.ravel_multi_index(tuple(idx), seeds.shape).astype(np.int32)


def _buffer(st: dict[str, Any], name: str, nbytes: int) -> Any:
    """A device buffer of at least ``nbytes``, kept for the next call of the same size."""
    cl = st["cl"]
    buf = st["buffers"].get(name)
    if buf is None or buf.size < nbytes or buf.size > 2 * nbytes:
        buf = cl.Buffer(st["ctx"], cl.mem_flags.READ_WRITE, max(nbytes, 1))
        st["buffers"][name] = buf
    return buf


def _round_up(n: int, m: int) -> int:
    return (n + m - 1) // m * m


def _nearest_opencl(seeds: np.ndarray, sampling: tuple[float, float, float]) -> np.ndarray:
    with _lock:  # the cached buffers are shared
        return _run_kernels(_opencl_state(), seeds, sampling)


def _run_kernels(
    st: dict[str, Any], seeds: np.ndarray, sampling: tuple[float, float, float]
) -> np.ndarray:
    out = np.empty(seeds.shape, dtype=np.int32)
    st["cl"].enqueue_copy(st["queue"], out, _enqueue_passes(st, seeds, sampling), is_blocking=True)
    return out


def _enqueue_passes(
    st: dict[str, Any], seeds: np.ndarray, sampling: tuple[float, float, float]
) -> Any:
    """Enqueue the three passes; the device buffer that will hold the C-order indices."""
    cl, queue, k = st["cl"], st["queue"], st["kernels"]
    shape = seeds.shape
    # Memory axes, slowest first: the permutation that makes the array C-contiguous
    # (no copy for C, Fortran or axis-permuted contiguous input).
    perm = tuple(int(a) for a in np.argsort([-abs(s) for s in seeds.strides], kind="stable"))
    mem = np.ascontiguousarray(seeds.transpose(perm)).view(np.uint8)
    n0, n1, n2 = mem.shape
    h0, h1, h2 = (sampling[a] for a in perm)
    world_strides = (shape[1] * shape[2], shape[2], 1)  # C-order flat index per world axis
    # The seed's flat index and the output position use the same strides: the output is
    # C-ordered in world axes whatever the input order.
    strides = [np.int32(world_strides[a]) for a in perm]

    seeds_buf = _buffer(st, "seeds", mem.nbytes)
    packed_buf = _buffer(st, "packed", 4 * mem.size)
    out_buf = _buffer(st, "out", 4 * mem.size)  # also holds pass 1's int16 (read by pass 2)
    cl.enqueue_copy(queue, seeds_buf, mem, is_blocking=False)

    i32, f32 = np.int32, np.float32
    lx = 16  # PoCL picks huge work-groups by itself and then overflows its stack
    k["pass_contig"](
        queue, (_round_up(n1, lx), n0), (lx, 1), seeds_buf, out_buf, i32(n2), i32(n1), i32(n0)
    )
    k["pass_mid"](
        queue,
        (_round_up(n2, lx), n0),
        (lx, 1),
        out_buf,
        packed_buf,
        i32(n2),
        i32(n1),
        i32(n0),
        f32((h2 / h1) ** 2),
    )
    k["pass_slow"](
        queue,
        (_round_up(n2, lx), n1),
        (lx, 1),
        packed_buf,
        out_buf,
        i32(n2),
        i32(n1),
        i32(n0),
        f32((h1 / h0) ** 2),
        f32((h2 / h0) ** 2),
        *strides,
        *strides,
    )
    return out_buf


def nearest_seed(
    seeds: np.ndarray,
    sampling: float | Sequence[float] = (1.0, 1.0, 1.0),
    *,
    backend: str = "auto",
) -> np.ndarray:
    """Flat index of the nearest seed voxel, for every voxel (Euclidean, anisotropic).

    Parameters
    ----------
    seeds : np.ndarray
        Boolean array (nx, ny, nz), True at seed voxels (integers 0/1 are accepted). Any
        memory order; C, Fortran and axis-permuted contiguous arrays are not copied.
    sampling : float or sequence of 3 floats
        Voxel spacing along x, y, z (mm); one number for isotropic voxels.
    backend : {"auto", "opencl", "scipy"}
        ``"opencl"``: exact separable transform on an OpenCL device (module docstring);
        ``"scipy"``: ``scipy.ndimage.distance_transform_edt``; ``"auto"``: OpenCL when
        available, else scipy with an :class:`OpenCLUnavailableWarning` (once per
        process); also scipy, silently, for axes longer than :data:`MAX_LINE`, and with
        a warning when the OpenCL run fails (e.g. out of memory). ``VOXWARP_OPENCL=0``
        disables OpenCL.

    Returns
    -------
    np.ndarray
        int32 (nx, ny, nz), C-ordered: ``np.ravel_multi_index`` (C order, ``seeds.shape``)
        of the nearest seed; all -1 when there is no seed. Equidistant seeds may resolve
        differently between backends (module docstring, "Ties"). The backend used is
        reported by :func:`last_backend`.

    Raises
    ------
    WarpError
        Bad ``seeds`` / ``sampling`` / ``backend``; ``backend="opencl"`` without a usable
        OpenCL device, with an axis longer than :data:`MAX_LINE`, or when its run fails.
    """
    global _warned, _last_backend
    if backend not in BACKENDS:
        raise WarpError(f"unknown nearest_seed backend {backend!r}; use one of {list(BACKENDS)}")
    arr = _check_seeds(seeds)
    spacing = check_sampling(sampling)
    too_long = max(arr.shape) > MAX_LINE
    if backend == "opencl":
        if not opencl_available():
            raise WarpError(
                f"the OpenCL backend is unavailable ({_unavailable_reason()}); "
                f"{OPENCL_FIX}; or use backend='scipy'"
            )
        if too_long:
            raise WarpError(
                f"the OpenCL backend handles at most {MAX_LINE} voxels per axis; got shape "
                f"{arr.shape}: use backend='scipy' (or 'auto')"
            )
        use = "opencl"
    elif backend == "auto":
        if too_long:
            use = "scipy"
        elif opencl_available():
            use = "opencl"
        else:
            use = "scipy"
            if not _warned:
                _warned = True
                warnings.warn(
                    f"no usable OpenCL device ({_unavailable_reason()}); nearest-seed "
                    f"propagation falls back to scipy, several times slower: {OPENCL_FIX}",
                    OpenCLUnavailableWarning,
                    stacklevel=2,
                )
    else:
        use = "scipy"
    if not arr.any():
        _last_backend = use
        return np.full(arr.shape, -1, dtype=np.int32)
    if use == "opencl":
        try:
            out = _nearest_opencl(arr, spacing)
            _last_backend = use
            return out
        except (_opencl_state()["cl"].Error, MemoryError) as exc:  # e.g. out of memory
            reason = f"{type(exc).__name__}: {exc}".splitlines()[0][:200]
            if backend == "opencl":
                raise WarpError(
                    f"the OpenCL nearest-seed run failed ({reason}); use backend='scipy' or a "
                    "smaller grid"
                ) from exc
            warnings.warn(
                f"the OpenCL nearest-seed run failed ({reason}); falling back to scipy",
                OpenCLUnavailableWarning,
                stacklevel=2,
            )
            use = "scipy"
    _last_backend = use
    return _nearest_scipy(np.ascontiguousarray(arr), spacing)


def on_device_nearest(
    seeds: np.ndarray, sampling: Sequence[float], use: Callable[[dict[str, Any], Any], T]
) -> T:
    """Run the OpenCL transform and hand its device buffer (int32 C-order nearest-seed
    indices) to ``use(state, buffer)``, under the lock that guards the shared buffers.

    For callers that consume the indices on the device (the wire field's classification,
    :mod:`voxwarp.deform.wires.classify`); the caller checks :func:`opencl_available`, the
    axis limit :data:`MAX_LINE` and that ``seeds`` holds a seed first. OpenCL errors
    propagate (``state["cl"].Error``).
    """
    global _last_backend
    arr = _check_seeds(seeds)
    spacing = check_sampling(sampling)
    with _lock:
        st = _opencl_state()
        result = use(st, _enqueue_passes(st, arr, spacing))
    _last_backend = "opencl"
    return result
