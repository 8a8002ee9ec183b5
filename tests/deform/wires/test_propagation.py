"""Tests of voxwarp.deform.wires.propagation: the nearest-seed transform (OpenCL vs scipy vs brute
force).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.propagation import benchmark_nearest_seed, helix_seeds, seed_distance
from voxwarp.deform.warp import WarpError
from voxwarp.deform.wires import propagation as prop
from voxwarp.deform.wires.propagation import (
    MAX_LINE,
    OpenCLUnavailableWarning,
    last_backend,
    nearest_seed,
    opencl_available,
)

requires_opencl = pytest.mark.skipif(
    not opencl_available(),
    reason=f"no usable OpenCL device ({prop._unavailable_reason()}); {prop.OPENCL_FIX}",
)


@pytest.fixture
def fresh_state() -> Iterator[None]:
    """Reset the cached OpenCL state and the warned-once flag before and after a test."""
    saved = prop._cl_state
    prop._reset_opencl_cache()
    yield
    prop._reset_opencl_cache()
    prop._cl_state = saved


def _brute_force(seeds: np.ndarray, sampling) -> tuple[np.ndarray, np.ndarray]:
    """(squared distance to the nearest seed, to the second nearest) per voxel."""
    h = np.broadcast_to(np.asarray(sampling, dtype=np.float64), (3,))
    pts = np.indices(seeds.shape).reshape(3, -1).T * h
    sd = np.argwhere(seeds) * h
    d2 = ((pts[:, None, :] - sd[None, :, :]) ** 2).sum(-1)
    part = np.sort(d2, axis=1)
    second = part[:, 1] if sd.shape[0] > 1 else np.full(len(pts), np.inf)
    return part[:, 0].reshape(seeds.shape), second.reshape(seeds.shape)


def _random_seeds(shape, density: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    s = rng.random(shape) < density
    if not s.any():
        s[tuple(rng.integers(0, n) for n in shape)] = True
    return s


def _check_against_scipy(seeds: np.ndarray, sampling, brute: bool) -> np.ndarray:
    got = nearest_seed(seeds, sampling, backend="opencl")
    assert last_backend() == "opencl"
    ref = nearest_seed(seeds, sampling, backend="scipy")
    assert got.dtype == np.int32
    assert got.shape == seeds.shape
    assert got.flags.c_contiguous
    assert np.asarray(seeds).ravel(order="C")[got.ravel()].all(), "chosen voxels must be seeds"
    d_got, d_ref = seed_distance(got, sampling), seed_distance(ref, sampling)
    np.testing.assert_allclose(d_got, d_ref, rtol=1e-4, atol=1e-6)
    if brute:
        first, second = _brute_force(np.asarray(seeds), sampling)
        np.testing.assert_allclose(d_got**2, first, rtol=1e-4, atol=1e-6)
        unique = second > first * (1 + 1e-4) + 1e-9
        assert unique.any()
        np.testing.assert_array_equal(got[unique], ref[unique])
    return got


CASES = [
    # shape, sampling, density
    ((20, 30, 17), (1.0, 1.0, 1.0), 0.01),
    ((33, 8, 41), (0.5, 1.3, 2.0), 0.005),
    ((1, 40, 25), (1.0, 1.0, 1.0), 0.02),
    ((25, 1, 9), (2.0, 0.7, 0.3), 0.05),
    ((7, 9, 1), (1.0, 3.0, 1.0), 0.05),
    ((100, 8, 8), (1.0, 1.0, 1.0), 0.003),  # crashed PoCL with automatic work-groups
    ((16, 12, 10), (0.1, 5.0, 1.0), 0.01),
]


@requires_opencl
@pytest.mark.parametrize("order", ["C", "F", "permuted"])
@pytest.mark.parametrize(("shape", "sampling", "density"), CASES)
def test_opencl_matches_scipy_and_brute_force(shape, sampling, density, order) -> None:
    seeds = _random_seeds(shape, density, seed=sum(shape))
    if order == "F":
        seeds = np.asfortranarray(seeds)
    elif order == "permuted":  # y slowest in memory: an axis-permuted contiguous view
        seeds = np.ascontiguousarray(seeds.transpose(1, 0, 2)).transpose(1, 0, 2)
    _check_against_scipy(seeds, sampling, brute=True)


@requires_opencl
def test_opencl_matches_scipy_on_a_larger_anisotropic_grid() -> None:
    seeds = _random_seeds((96, 80, 64), 0.002, seed=5)
    for arr in (seeds, np.asfortranarray(seeds)):
        _check_against_scipy(arr, (0.8, 1.0, 2.5), brute=False)


@requires_opencl
def test_helix_seeds_match_scipy() -> None:
    seeds = helix_seeds((48, 40, 56))
    _check_against_scipy(seeds, (1.0, 1.0, 1.5), brute=False)


@requires_opencl
@pytest.mark.parametrize("order", ["C", "F"])
def test_single_seed_everywhere(order) -> None:
    seeds = np.zeros((13, 7, 11), dtype=bool, order=order)
    seeds[4, 6, 0] = True
    got = nearest_seed(seeds, (1.0, 2.0, 0.5), backend="opencl")
    assert (got == np.ravel_multi_index((4, 6, 0), seeds.shape)).all()


@requires_opencl
def test_seeds_on_the_boundary() -> None:
    shape = (18, 15, 12)
    seeds = np.zeros(shape, dtype=bool)
    for corner in np.ndindex(2, 2, 2):
        seeds[tuple(c * (n - 1) for c, n in zip(corner, shape, strict=True))] = True
    seeds[0, 7, 5] = seeds[17, 3, 11] = seeds[9, 14, 0] = True
    for arr in (seeds, np.asfortranarray(seeds)):
        _check_against_scipy(arr, (1.0, 1.5, 0.8), brute=True)


@requires_opencl
@pytest.mark.parametrize("shape", [(1, 1, 1), (1, 1, 7), (1, 6, 1), (5, 1, 1)])
def test_degenerate_shapes(shape) -> None:
    seeds = np.zeros(shape, dtype=bool)
    seeds.flat[-1] = True
    got = nearest_seed(seeds, backend="opencl")
    assert (got == seeds.size - 1).all()


@requires_opencl
def test_every_voxel_a_seed_is_the_identity() -> None:
    seeds = np.ones((9, 4, 6), dtype=bool)
    got = nearest_seed(np.asfortranarray(seeds), backend="opencl")
    np.testing.assert_array_equal(got.ravel(), np.arange(seeds.size))


@requires_opencl
@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("order", ["C", "F"])
def test_exact_ties_go_to_the_lower_coordinate(axis, order) -> None:
    shape = [1, 1, 1]
    shape[axis] = 5
    seeds = np.zeros(shape, dtype=bool, order=order)
    seeds.flat[0] = seeds.flat[4] = True
    got = nearest_seed(seeds, backend="opencl").ravel()
    np.testing.assert_array_equal(got, [0, 0, 0, 4, 4])


@requires_opencl
def test_longest_supported_line() -> None:
    seeds = np.zeros((MAX_LINE, 2, 3), dtype=bool)
    seeds[0, 0, 0] = seeds[MAX_LINE - 1, 1, 2] = seeds[600, 1, 1] = True
    _check_against_scipy(seeds, (1.0, 1.0, 1.0), brute=True)


@requires_opencl
def test_too_long_line_raises_for_opencl_and_auto_uses_scipy() -> None:
    seeds = np.zeros((MAX_LINE + 1, 1, 1), dtype=bool)
    seeds[3] = True
    with pytest.raises(WarpError, match="backend='scipy'"):
        nearest_seed(seeds, backend="opencl")
    assert (nearest_seed(seeds, backend="auto") == 3).all()
    assert last_backend() == "scipy"


@requires_opencl
def test_auto_uses_opencl_without_warning() -> None:
    seeds = _random_seeds((10, 11, 12), 0.02, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = nearest_seed(seeds)
    assert last_backend() == "opencl"
    np.testing.assert_array_equal(got, nearest_seed(seeds, backend="opencl"))


@pytest.mark.parametrize("backend", ["scipy", "auto", "opencl"])
def test_no_seed_gives_minus_one(backend) -> None:
    if backend == "opencl" and not opencl_available():
        pytest.skip(f"no usable OpenCL device ({prop._unavailable_reason()})")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OpenCLUnavailableWarning)
        got = nearest_seed(np.zeros((4, 5, 6), dtype=bool), backend=backend)
    assert got.dtype == np.int32
    assert got.shape == (4, 5, 6)
    assert (got == -1).all()


def test_integer_seeds_are_accepted() -> None:
    seeds = np.zeros((5, 6, 7), dtype=np.uint8)
    seeds[1, 2, 3] = 1
    got = nearest_seed(seeds, backend="scipy")
    assert (got == np.ravel_multi_index((1, 2, 3), seeds.shape)).all()


@pytest.mark.parametrize(
    ("seeds", "match"),
    [
        (np.zeros((4, 4), dtype=bool), "3D"),
        (np.zeros((2, 2, 2, 2), dtype=bool), "3D"),
        (np.zeros((0, 4, 4), dtype=bool), "at least one voxel"),
        (np.zeros((3, 3, 3), dtype=np.float32), "astype"),
        (np.full((3, 3, 3), 2, dtype=np.int16), "outside"),
        (np.full((3, 3, 3), "a"), "dtype"),
    ],
)
def test_bad_seeds_raise_warp_error(seeds, match) -> None:
    for backend in ("scipy", "auto", "opencl"):
        with pytest.raises(WarpError, match=match):
            nearest_seed(seeds, backend=backend)


@pytest.mark.parametrize("sampling", [(1.0, 1.0), (1.0, 0.0, 1.0), (1.0, -2.0, 1.0), "x", np.nan])
def test_bad_sampling_raises_warp_error(sampling) -> None:
    with pytest.raises(WarpError, match="sampling"):
        nearest_seed(np.ones((2, 2, 2), dtype=bool), sampling, backend="scipy")


def test_absurd_spacing_ratio_raises_warp_error() -> None:
    with pytest.raises(WarpError, match="differ by more than"):
        nearest_seed(np.ones((2, 2, 2), dtype=bool), (1.0, 1e-9, 1.0), backend="auto")


def test_unknown_backend_raises_warp_error() -> None:
    with pytest.raises(WarpError, match="opencl"):
        nearest_seed(np.ones((2, 2, 2), dtype=bool), backend="cuda")


def test_scalar_sampling_means_isotropic() -> None:
    seeds = _random_seeds((6, 7, 8), 0.05, seed=9)
    a = nearest_seed(seeds, 2.0, backend="scipy")
    b = nearest_seed(seeds, (2.0, 2.0, 2.0), backend="scipy")
    np.testing.assert_array_equal(a, b)


def test_env_var_forces_the_scipy_fallback(monkeypatch, fresh_state) -> None:
    monkeypatch.setenv("VOXWARP_OPENCL", "0")
    assert not opencl_available()
    seeds = _random_seeds((12, 9, 10), 0.02, seed=11)
    with pytest.warns(OpenCLUnavailableWarning, match="pip install pocl-binary-distribution"):
        got = nearest_seed(seeds, (1.0, 1.5, 2.0))
    assert last_backend() == "scipy"
    np.testing.assert_array_equal(got, nearest_seed(seeds, (1.0, 1.5, 2.0), backend="scipy"))
    with warnings.catch_warnings():  # warned once per process
        warnings.simplefilter("error")
        nearest_seed(seeds, (1.0, 1.5, 2.0))
    with pytest.raises(WarpError, match="pip install pocl-binary-distribution") as err:
        nearest_seed(seeds, backend="opencl")
    assert "VOXWARP_OPENCL" in str(err.value)


def test_missing_platform_falls_back_and_opencl_raises(monkeypatch, fresh_state) -> None:
    monkeypatch.delenv("VOXWARP_OPENCL", raising=False)
    prop._cl_state = {"error": "LogicError: clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR"}
    assert not opencl_available()
    seeds = _random_seeds((5, 6, 7), 0.05, seed=2)
    with pytest.warns(OpenCLUnavailableWarning, match="OpenCL ICD"):
        got = nearest_seed(seeds)
    np.testing.assert_array_equal(got, nearest_seed(seeds, backend="scipy"))
    with pytest.raises(WarpError, match=r"PLATFORM_NOT_FOUND.*pip install pocl"):
        nearest_seed(seeds, backend="opencl")
    assert issubclass(OpenCLUnavailableWarning, RuntimeWarning)


def test_a_device_that_cannot_build_gives_way_to_the_next(monkeypatch, fresh_state) -> None:
    """A listed device whose compiler fails (pyopencl's bundled PoCL on a CPU its LLVM does
    not know) is passed over for the next one; with none left, every reason is named."""
    bad, good = SimpleNamespace(name="pthread-AMD EPYC "), SimpleNamespace(name="other CPU")

    def state(cl, device):
        if device is bad:
            raise RuntimeError("clBuildProgram failed: BUILD_PROGRAM_FAILURE\nunknown target CPU")
        return {"device": device}

    monkeypatch.setattr(prop, "_device_state", state)
    monkeypatch.setattr(prop, "_ranked_devices", lambda cl: [bad, good])
    assert prop._build_state()["device"] is good
    monkeypatch.setattr(prop, "_ranked_devices", lambda cl: [bad])
    err = prop._build_state()["error"]
    assert err == "pthread-AMD EPYC: RuntimeError: clBuildProgram failed: BUILD_PROGRAM_FAILURE"


@requires_opencl
def test_the_device_in_use_builds_the_kernels() -> None:
    """Whatever device was picked, it is one whose kernels were built."""
    st = prop._opencl_state()
    assert set(st["kernels"]) == {"pass_contig", "pass_mid", "pass_slow"}
    assert st["device"] in prop._ranked_devices(st["cl"])


@requires_opencl
def test_benchmark_reports_both_backends() -> None:
    r = benchmark_nearest_seed((24, 20, 28), sampling=(1.0, 1.0, 2.0), repeats=1)
    assert r["n_seeds"] > 0
    assert r["device"]
    assert r["opencl_s"] > 0
    assert r["scipy_s"] > 0
    assert r["speedup"] == pytest.approx(r["scipy_s"] / r["opencl_s"])
    assert r["agree"] is True


def test_benchmark_without_opencl_reports_scipy_only(monkeypatch) -> None:
    monkeypatch.setenv("VOXWARP_OPENCL", "0")
    r = benchmark_nearest_seed((12, 12, 12), repeats=1)
    assert r["scipy_s"] > 0
    assert r["opencl_s"] is None
    assert r["speedup"] is None


@requires_opencl
def test_a_wire_kernel_that_does_not_build_warns_and_numpy_takes_over() -> None:
    """A compile error in the classification kernel (e.g. a name that is an OpenCL type)
    is reported once, in one line naming the kernel, the device and the compiler's
    error, and the caller gets no kernel (it keeps the numpy path)."""
    from voxwarp.deform.wires import classify

    st = prop._opencl_state()
    broken = classify._KERNEL.replace(
        "static inline double rint_d(double x) {", "static inline double rint_d(double half) {", 1
    )
    programs: dict = {}
    with pytest.warns(RuntimeWarning, match=r"'classify' kernel did not build on .*error") as rec:
        assert classify.fp64_kernel(st, programs, broken, "classify") is None
    assert len(rec) == 1
    assert "\n" not in str(rec[0].message)
    with warnings.catch_warnings():  # kept per context: not built (nor reported) again
        warnings.simplefilter("error")
        assert classify.fp64_kernel(st, programs, broken, "classify") is None
