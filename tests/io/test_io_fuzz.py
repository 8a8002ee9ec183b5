"""Hypothesis fuzzing of the raw+sidecar and npz loaders.

Whatever the sidecar, the bytes or the arrays hold, ``load_volume`` must either
return a Volume of the declared shape or raise VolumeError; any other exception is
a bug (a raw numpy/json/KeyError/TypeError traceback reaching the user).
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from voxwarp.core.volume import Volume
from voxwarp.errors import VolumeError
from voxwarp.io.volumes import load_volume

FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)

ITEMSIZE = {"uint8": 1, "int8": 1, "uint16": 2, "int16": 2, "int32": 4, "uint32": 4}
ITEMSIZE |= {"float32": 4, "float64": 8}

json_scalar = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
)
json_value = st.recursive(
    json_scalar,
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=3), children)
    ),
    max_leaves=6,
)


def mostly(valid: st.SearchStrategy, invalid: st.SearchStrategy) -> st.SearchStrategy:
    """``valid`` about seven times in eight, else ``invalid``."""
    return st.sampled_from([True] * 7 + [False]).flatmap(lambda ok: valid if ok else invalid)


dims = mostly(
    st.lists(st.integers(1, 5), min_size=3, max_size=3),
    st.one_of(
        st.lists(st.integers(-2, 6), max_size=5),
        st.lists(
            st.one_of(st.integers(1, 4), st.floats(0.5, 4), st.booleans(), st.text(max_size=2))
        ),
        json_value,
    ),
)
dtype_name = mostly(
    st.sampled_from(sorted(ITEMSIZE)),
    st.one_of(
        st.sampled_from(["complex64", "float16", "O", "V8", "<u2", "uint64", "bool", "", "UINT16"]),
        json_scalar,
    ),
)
byte_order = mostly(st.sampled_from(["little", "big"]), st.one_of(st.just("native"), json_value))
header_bytes = mostly(st.integers(0, 32), st.one_of(st.integers(-3, 2**40), json_scalar))
triple = mostly(
    st.one_of(st.lists(st.floats(0.1, 10), min_size=3, max_size=3), st.floats(0.1, 10)),
    st.one_of(
        st.floats(allow_nan=True, allow_infinity=True),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=4),
        st.lists(st.text(max_size=3), max_size=3),
        json_value,
    ),
)
optional_keys = {
    "byte_order": byte_order,
    "header_bytes": header_bytes,
    "spacing": triple,
    "origin": triple,
    "units": st.one_of(st.text(max_size=4), json_scalar),
    "junk": json_value,
}
sidecar = mostly(
    # mostly sidecars with dims and dtype, so that many examples get past the first checks
    st.fixed_dictionaries({"dims": dims, "dtype": dtype_name}, optional=optional_keys),
    st.fixed_dictionaries({}, optional={"dims": dims, "dtype": dtype_name, **optional_keys}),
)


def load_or_error(path: Path, **kwargs: Any) -> tuple[Volume | None, str | None]:
    """``(volume, None)`` or ``(None, message)`` for a VolumeError; anything else propagates."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            vol = load_volume(path, **kwargs)
    except VolumeError as exc:
        event("VolumeError")
        return None, str(exc)
    event("loaded")
    return vol, None


def expected_bytes(meta: dict[str, Any]) -> int | None:
    """Bytes a valid sidecar asks for, or None when the sidecar is surely invalid."""
    d = meta.get("dims")
    if not (isinstance(d, list) and len(d) == 3 and all(type(v) is int and v > 0 for v in d)):
        return None
    if meta.get("dtype") not in ITEMSIZE:
        return None
    header = meta.get("header_bytes", 0)
    header = header if type(header) is int and 0 <= header < 4096 else 0
    return header + d[0] * d[1] * d[2] * ITEMSIZE[meta["dtype"]]


@st.composite
def raw_cases(draw: st.DrawFn) -> tuple[bytes, bytes, int, str, str]:
    meta = draw(sidecar)
    text_kind = draw(st.sampled_from(["json"] * 8 + ["text", "binary"]))
    if text_kind == "json":
        side = json.dumps(meta).encode()
    elif text_kind == "text":
        side = draw(st.text(max_size=40)).encode("utf-8", "surrogatepass")
    else:
        side = draw(st.binary(max_size=40))
    exact = expected_bytes(meta)
    mode = draw(st.sampled_from(["exact", "exact", "exact", "short", "long", "random"]))
    if exact is None or mode == "random":
        n = draw(st.integers(0, 3000))
    elif mode == "exact":
        n = exact
    elif mode == "short":
        n = draw(st.integers(0, max(0, exact - 1)))
    else:
        n = exact + draw(st.integers(1, 64))
    seed = draw(st.integers(0, 2**32 - 1))
    sidecar_name = draw(st.sampled_from(["vol.raw.json", "vol.json"]))
    raw_name = draw(st.sampled_from(["vol.raw", "vol.bin"]))
    return side, np.random.default_rng(seed).bytes(n), n, sidecar_name, raw_name


@FUZZ
@given(case=raw_cases(), via_json=st.booleans(), nan_policy=st.sampled_from(["raise", "mask"]))
def test_raw_loader_returns_volume_or_volume_error(case, via_json: bool, nan_policy: str) -> None:
    side, payload, n, sidecar_name, raw_name = case
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        raw_path = folder / raw_name
        side_path = folder / sidecar_name
        if sidecar_name == "vol.raw.json" and raw_name == "vol.bin":
            side_path = folder / "vol.bin.json"
        raw_path.write_bytes(payload)
        side_path.write_bytes(side)
        vol, error = load_or_error(side_path if via_json else raw_path, nan_policy=nan_policy)
    if error is not None:
        assert error  # a message for the user
        return
    assert isinstance(vol, Volume)
    meta = json.loads(side)
    dims = tuple(meta["dims"])
    assert vol.shape == dims
    assert n >= np.prod(dims)
    name = meta["dtype"].strip().lower()
    if name in ("uint8", "uint16", "int16"):
        order = "<" if meta.get("byte_order", "little") == "little" else ">"
        dt = np.dtype(order + {"uint8": "u1", "uint16": "u2", "int16": "i2"}[name])
        expected = np.frombuffer(
            payload, dt, count=int(np.prod(dims)), offset=meta.get("header_bytes", 0)
        ).reshape(dims, order="F")
        np.testing.assert_array_equal(vol.data, expected)


NPZ_DTYPES = [
    np.uint8,
    np.int8,
    np.int16,
    np.uint16,
    np.int32,
    np.int64,
    np.uint64,
    np.float16,
    np.float32,
    np.float64,
    np.complex64,
    np.bool_,
    np.dtype("U3"),
    np.dtype("S2"),
    np.dtype("datetime64[s]"),
]
any_shape = hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=4)
arrays = st.sampled_from(NPZ_DTYPES).flatmap(lambda dt: hnp.arrays(dt, any_shape))
VOLUME_DTYPES = [np.uint8, np.int16, np.uint16, np.int32, np.float32, np.float64, np.bool_]
volumes = st.sampled_from(VOLUME_DTYPES).flatmap(
    lambda dt: hnp.arrays(
        dt,
        hnp.array_shapes(min_dims=3, max_dims=3, min_side=1, max_side=4),
        elements=st.floats(-1e3, 1e3, width=32) if np.dtype(dt).kind == "f" else None,
    )
)
small_floats = hnp.arrays(np.float64, st.sampled_from([(), (1,), (3,)]), elements=st.floats(0.1, 9))
KEYS = ["data", "arr_0", "spacing", "origin", "units", "x"]
npz_content = st.one_of(
    st.fixed_dictionaries(
        {"data": mostly(volumes, arrays)},
        optional={
            "spacing": mostly(small_floats, arrays),
            "origin": mostly(small_floats, arrays),
            "units": mostly(st.just(np.array("HU")), arrays),
            "x": arrays,
        },
    ),
    st.dictionaries(st.sampled_from(KEYS), st.one_of(volumes, arrays), max_size=4),
)


@FUZZ
@given(
    content=npz_content,
    npy=st.booleans(),
    truncate=mostly(st.none(), st.floats(0, 1)),
    nan_policy=st.sampled_from(["raise", "mask"]),
    axis_order=st.sampled_from(["xyz", "zyx"]),
)
def test_npz_loader_returns_volume_or_volume_error(
    content: dict[str, np.ndarray],
    npy: bool,
    truncate: float | None,
    nan_policy: str,
    axis_order: str,
) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        if npy:
            path = Path(tmp) / "v.npy"
            if not content:
                return
            content = {"data": next(iter(content.values()))}
            np.save(path, content["data"])
        else:
            path = Path(tmp) / "v.npz"
            np.savez(path, **content)
        if truncate is not None:
            blob = path.read_bytes()
            path.write_bytes(blob[: int(len(blob) * truncate)])
        vol, error = load_or_error(path, nan_policy=nan_policy, axis_order=axis_order)
    if error is not None:
        assert error
        return
    assert isinstance(vol, Volume)
    if "data" in content:
        key = "data"
    else:
        (key,) = (k for k in content if k not in ("spacing", "origin", "units"))
    shape = content[key].shape  # a 4th axis of length 1 is a single frame (io.frames)
    assert vol.shape == (shape[:3] if axis_order == "xyz" else shape[len(shape) - 3 :][::-1])
    assert vol.dtype.kind in "uif"
