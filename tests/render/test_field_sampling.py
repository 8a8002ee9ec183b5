"""The GPU field sampler (``voxwarp export-field --sampler gpu``) against the CPU one.

Oracles:

* **CPU/GPU agreement.** :class:`~voxwarp.render.field_sampling.GpuFieldSampler` (the
  raycaster's GLSL chain, float32, half-float wire fields) gives the same vectors as
  :func:`~voxwarp.core.field_check.sample_carried` (the exact numpy chain) within
  :data:`GPU_CPU_MM` on every family's chain (mass-spring, ChainMail, rigid and
  smooth-ended wires, lattice, an imported displacement field, a chain of several)
  on an oblique grid that is not the volume's.
* **Outside mask.** The nodes either path leaves out (a rigid wire's vacated space) are
  the same, but for nodes within one node of the vacated border (where the border
  falls between the GPU's float32 and the CPU's float64 is a matter of rounding).
* **Which sampler.** Planes split over several draws give the same field bitwise;
  :class:`~voxwarp.render.field_sampling.FieldSampler` (the default ``--sampler``)
  gives the CPU's field bitwise under its node count and the GPU's at it, on a given
  context or its own, and the CPU's (with one note) where no context opens.
* **SimpleITK.** ``voxwarp export-field --sampler gpu`` of the fish's wires and
  mass-spring, read by SimpleITK's ``DisplacementFieldTransform``, stays within the
  0.5 mm tolerance of the chain off the nodes (the interpolation test's oracle), and
  ``--sampler cpu`` writes the same field within :data:`GPU_CPU_MM` (but at most 0.1 %
  of the nodes: those at the vacated border, filled from another side).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

from tests.cli.test_export_field_fast import FAMILIES, _wire
from voxwarp.core.field_check import sample_carried
from voxwarp.core.volume import Volume
from voxwarp.deform.fields.displacement import DisplacementFieldWarp
from voxwarp.deform.warp import Warp, rotation_matrix
from voxwarp.render.field_sampling import GpuFieldSampler

sitk = pytest.importorskip("SimpleITK")

#: Largest |GPU - CPU| vector difference allowed (mm); measured up to about 1e-3 mm.
GPU_CPU_MM = 0.05


@pytest.fixture(scope="module")
def volume() -> Volume:
    """A 30 x 26 x 22 blob at 1 x 1.2 x 1.5 mm, off the origin."""
    idx = np.indices((30, 26, 22)).astype(float)
    r = np.sqrt(((idx[0] - 15) / 12) ** 2 + ((idx[1] - 13) / 10) ** 2 + ((idx[2] - 11) / 8) ** 2)
    data = (1000 * (r < 1) + 50 * idx[0]).astype(np.int16)
    return Volume(data, (1.0, 1.2, 1.5), (-10.0, 5.0, 3.0), name="blob")


def _imported(vol: Volume) -> list[Warp]:
    """A smooth displacement field on a coarse grid of its own, tilted."""
    idx = np.indices((9, 8, 7)).astype(float).transpose(1, 2, 3, 0)
    u = np.stack([np.sin(idx[..., 1]), np.cos(idx[..., 2]), 0.5 * idx[..., 0] - 2], axis=-1)
    a = np.eye(4)
    rot = rotation_matrix((1, 1, 0), 20.0)
    a[:3, :3] = rot * 4.0
    a[:3, 3] = np.asarray(vol.center) - a[:3, :3] @ np.array([4.0, 3.5, 3.0])
    return [DisplacementFieldWarp(u.astype(np.float32), a)]


CHAINS = {
    **FAMILIES,
    "wire-smooth-ends": lambda v: _wire(v, "smooth"),
    "imported-field": _imported,
    "imported+wire": lambda v: [*_imported(v), *_wire(v)],
}


def _oblique_grid(vol: Volume) -> tuple[np.ndarray, tuple[int, int, int]]:
    """A grid over the volume at 0.9 mm, rotated 15 degrees, with unequal sides."""
    shape = (33, 29, 27)
    rot = rotation_matrix((0.3, 1.0, 0.2), 15.0)
    a = np.eye(4)
    a[:3, :3] = rot * 0.9
    a[:3, 3] = np.asarray(vol.center) - a[:3, :3] @ ((np.asarray(shape) - 1) / 2.0)
    return a, shape


@pytest.mark.parametrize("name", list(CHAINS))
def test_gpu_and_cpu_samplers_agree(name: str, volume: Volume, gl_ctx: object) -> None:
    warps = CHAINS[name](volume)
    affine, shape = _oblique_grid(volume)
    u_cpu, out_cpu = sample_carried(warps, affine, shape)
    sampler = GpuFieldSampler(gl_ctx)
    try:
        u_gpu, out_gpu = sampler(warps, affine, shape)
    finally:
        sampler.release()
    assert u_gpu.shape == u_cpu.shape
    assert u_gpu.dtype == np.float32
    assert float(np.abs(u_cpu).max()) > 1.0  # the chain moves something
    border = ndimage.binary_dilation(out_cpu, iterations=1) & ~ndimage.binary_erosion(
        out_cpu, iterations=1, border_value=1
    )
    assert np.array_equal(out_gpu[~border], out_cpu[~border])
    both = ~out_cpu & ~out_gpu
    diff = np.linalg.norm(u_gpu[both] - u_cpu[both], axis=1)
    print(f"{name}: max |GPU - CPU| {diff.max():.2e} mm, {int(out_cpu.sum())} outside")
    assert diff.max() <= GPU_CPU_MM, f"{name}: {diff.max():.3g} mm"
    if name in ("wire-rigid", "imported+wire"):
        assert out_cpu.any()
        assert out_gpu.any()


@pytest.mark.slow
@pytest.mark.parametrize("name", ["wires-rigid", "massspring"])
def test_gpu_sampled_field_reproduces_the_chain_in_simpleitk(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture, gl_ctx: object
) -> None:
    from tests.cli.test_export_field_interpolation import (
        TOLERANCE,
        _export,
        _scene,
        off_node_errors,
    )

    scene = _scene(name, tmp_path)
    gpu, cpu = tmp_path / "gpu.nii.gz", tmp_path / "cpu.nii.gz"
    assert "field check: trilinear within" in _export(scene, gpu, capsys, "--sampler", "gpu")
    _export(scene, cpu, capsys, "--sampler", "cpu")
    errors, drawn = off_node_errors(scene, gpu)
    assert errors.size > drawn // 4
    assert errors.max() <= TOLERANCE, f"{name}: max {errors.max():.3f} mm"
    a, b = (sitk.GetArrayFromImage(sitk.ReadImage(str(f))) for f in (gpu, cpu))
    assert a.shape == b.shape
    off = np.linalg.norm(a - b, axis=-1) > GPU_CPU_MM  # only where the vacated border
    assert off.mean() <= 1e-3  # falls differently (the filled vectors differ there)


def test_planes_split_over_draws_give_the_same_field(
    volume: Volume, gl_ctx: object, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Planes stacked in one draw or a few per draw (the last draw short) agree exactly."""
    from voxwarp.render import field_sampling

    warps = CHAINS["imported+wire"](volume)
    affine, shape = _oblique_grid(volume)
    sampler = GpuFieldSampler(gl_ctx)
    try:
        whole = sampler(warps, affine, shape)
        monkeypatch.setattr(field_sampling, "DRAW_NODES", 2 * shape[1] * shape[2])
        split = sampler(warps, affine, shape)
    finally:
        sampler.release()
    np.testing.assert_array_equal(split[0], whole[0])
    np.testing.assert_array_equal(split[1], whole[1])


def test_the_default_sampler_takes_the_cpu_below_its_node_count(
    volume: Volume, gl_ctx: object
) -> None:
    """``FieldSampler`` gives the CPU's field bitwise under ``min_nodes`` and the GPU's
    at or over it, on the caller's context or on one it opens itself."""
    from voxwarp.render.field_sampling import FieldSampler

    warps = CHAINS["massspring"](volume)
    affine, shape = _oblique_grid(volume)
    nodes = int(np.prod(shape))
    cpu = sample_carried(warps, affine, shape)
    gpu_sampler = GpuFieldSampler(gl_ctx)
    try:
        gpu = gpu_sampler(warps, affine, shape)
    finally:
        gpu_sampler.release()
    assert not np.array_equal(gpu[0], cpu[0])  # half-float offsets: the two differ a little
    for ctx, at_least, expected in ((gl_ctx, nodes + 1, cpu), (gl_ctx, nodes, gpu), (None, 0, gpu)):
        sampler = FieldSampler(ctx, min_nodes=at_least, required=True)
        try:
            got = sampler(warps, affine, shape)
        finally:
            sampler.release()
        np.testing.assert_array_equal(got[0], expected[0])
        np.testing.assert_array_equal(got[1], expected[1])


def test_without_a_context_the_default_sampler_takes_the_cpu(
    volume: Volume, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where no context opens, the default sampler says so once and gives the CPU's
    field; ``required`` (``--sampler gpu``) raises the context's error instead."""
    from voxwarp.errors import RenderError
    from voxwarp.render import offscreen
    from voxwarp.render.field_sampling import FieldSampler

    def no_context(*_args: object, **_kw: object) -> None:
        raise RenderError("no EGL display")

    monkeypatch.setattr(offscreen, "OffscreenRenderer", no_context)
    warps = CHAINS["lattice"](volume)
    affine, shape = _oblique_grid(volume)
    notes: list[str] = []
    sampler = FieldSampler(min_nodes=0, log=notes.append)
    got = [sampler(warps, affine, shape) for _ in range(2)]
    sampler.release()
    cpu = sample_carried(warps, affine, shape)
    for u, outside in got:
        np.testing.assert_array_equal(u, cpu[0])
        np.testing.assert_array_equal(outside, cpu[1])
    assert notes == ["no OpenGL context: the CPU samples the chain"]
    with pytest.raises(RenderError, match="no EGL display"):
        FieldSampler(min_nodes=0, required=True)(warps, affine, shape)
