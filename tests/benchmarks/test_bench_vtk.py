"""Tests of benchmarks.vtk, the VTK side of ``python -m benchmarks render`` (skipped
without VTK)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("vtk")

from benchmarks.vtk import CameraSpec, VtkResult, render_vtk, vtk_available

N = 32
CENTRE = (N - 1) / 2
TF = [(0.0, 0.0, 0.0, 0.0, 0.0), (200.0, 1.0, 1.0, 1.0, 1.0), (255.0, 1.0, 0.0, 0.0, 1.0)]


def _sphere_volume() -> np.ndarray:
    """32³ uint8: a sphere of 200 (radius 10) in 0, plus a 255 marker at high x and high y."""
    i, j, k = np.meshgrid(np.arange(N), np.arange(N), np.arange(N), indexing="ij")
    vol = np.where((i - CENTRE) ** 2 + (j - CENTRE) ** 2 + (k - CENTRE) ** 2 < 100, 200, 0)
    vol = vol.astype(np.uint8)
    vol[24:28, 24:28, 12:20] = 255
    return vol


def _ortho_down_z() -> CameraSpec:
    """Orthographic camera on the volume's centre looking down -z, +y up, 32 mm tall view."""
    return CameraSpec(
        position=(CENTRE, CENTRE, CENTRE + 100.0),
        focal_point=(CENTRE, CENTRE, CENTRE),
        view_up=(0.0, 1.0, 0.0),
        view_angle_deg=30.0,
        parallel=True,
        parallel_scale=N / 2,
        near=1.0,
        far=200.0,
    )


def _render(**kw: object) -> VtkResult:
    """Render the sphere volume with test defaults, overridden by ``kw``."""
    args: dict[str, object] = {
        "mapper": "fixed_point",
        "mode": "mip",
        "sample_distance_mm": 1.0,
        "opacity_unit_distance_mm": 1.0,
        "size": (64, 64),
        "camera": _ortho_down_z(),
        "frames": 3,
        "warmup": 1,
    }
    args.update(kw)
    try:
        return render_vtk(_sphere_volume(), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), TF, **args)
    except RuntimeError as exc:  # no usable OpenGL context for this mapper here
        pytest.skip(f"VTK cannot render with the {args['mapper']} mapper here: {exc}")


def test_vtk_available() -> None:
    assert vtk_available()


@pytest.mark.parametrize("mapper", ["fixed_point", "gpu"])
def test_mip_sphere_renders_where_the_sphere_is(mapper: str) -> None:
    res = _render(mapper=mapper)
    img = res.image
    assert img.shape == (64, 64, 3)
    assert img.dtype == np.uint8
    # Sphere (radius 10 mm of a 32 mm view) fills the centre, white.
    assert img[28:36, 28:36].min() > 200
    # Corners lie outside the sphere and the marker.
    for corner in (img[:4, :4], img[:4, -4:], img[-4:, :4], img[-4:, -4:]):
        assert corner.max() == 0
    # The red marker (high x, high y) is at the top right: row 0 is the top, x goes right.
    marker = img[9:14, 50:55].reshape(-1, 3)
    assert (marker[:, 0] > 200).all()
    assert (marker[:, 1] < 100).all()
    assert img[50:55, 9:14].max() == 0  # nothing at the mirrored spot
    assert len(res.times_ms) == 3
    assert all(t > 0 for t in res.times_ms)
    assert res.min_ms <= res.median_ms
    assert "RayCast" in res.mapper_name


def test_dvr_rgba_image() -> None:
    res = _render(mode="dvr", size=(48, 32), rgba=True, frames=1, warmup=0)
    img = res.image
    assert img.shape == (32, 48, 4)
    assert img[16, 24, 3] > 200  # opaque over the sphere
    assert img[0, 0].max() == 0  # transparent black in the corner


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"mapper": "cuda"}, "mapper"),
        ({"mode": "iso"}, "mode"),
        ({"sample_distance_mm": 0.0}, "sample_distance_mm"),
        ({"size": (0, 64)}, "size"),
        ({"frames": 0}, "frames"),
    ],
)
def test_bad_arguments_raise_value_error(kw: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        _render(**kw)


def test_bad_volume_and_tf_raise_value_error() -> None:
    kw: dict = {
        "mapper": "fixed_point",
        "mode": "mip",
        "sample_distance_mm": 1.0,
        "opacity_unit_distance_mm": 1.0,
        "size": (8, 8),
        "camera": _ortho_down_z(),
    }
    with pytest.raises(ValueError, match="3D"):
        render_vtk(np.zeros((4, 4), np.uint8), (1, 1, 1), (0, 0, 0), TF, **kw)
    with pytest.raises(ValueError, match="r, g, b, a"):
        render_vtk(_sphere_volume(), (1, 1, 1), (0, 0, 0), [(0, 2, 0, 0, 1)], **kw)
