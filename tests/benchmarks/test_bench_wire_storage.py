"""``python -m benchmarks wires --storage`` (benchmarks.wire_storage) on small phantoms: its
rows hold what the layouts and propagation modes really store, and the command writes
its report."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks import wire_storage as ws
from benchmarks import wires as bw
from tests.deform.wires.test_wires import axis_points, cylinder, wire


@pytest.fixture(scope="module")
def cyl_rows() -> tuple[list[ws.StorageRow], ws.PropagateRow]:
    vol = cylinder()
    wires = [wire(modified=axis_points(dy=3.0, dz=-3.0), twist=[(0, 0), (1, 3.0)])]
    rows = ws.storage_rows("cylinder", vol, wires, 2)
    mode = ws.propagate_row("cylinder", vol, wires, 2, 1, ctx=None, log=lambda s: None)
    return rows, mode


def test_storage_rows_hold_the_layouts_sizes(cyl_rows: Any) -> None:
    rows, _ = cyl_rows
    assert [r.layout for r in rows] == ["float", "packed", "paper"]
    assert [r.bytes_per_voxel for r in rows] == [5.0, 2.0, 2.0]
    voxels = int(np.prod(rows[0].field_shape))
    assert rows[2].field_bytes == 2 * voxels
    # the masks do not depend on the layout; the float layout is its own reference
    assert len({r.mask_bytes for r in rows}) == 1
    assert rows[0].mask_bytes[0] > 0
    assert rows[0].max_mm == 0.0
    # the 2-byte layouts round t: they differ from float, by a fraction of a voxel
    for r in rows[1:]:
        assert 0.0 < r.median_mm < r.max_mm < 1.0


def test_propagate_row_compares_the_same_field(cyl_rows: Any) -> None:
    _, m = cyl_rows
    assert m.swept[0] == m.swept[1] > 0
    assert m.vacated[0] == m.vacated[1] > 0
    assert m.state_differs == 0
    assert m.image_max is None  # no context: no images
    assert m.ratio == pytest.approx(m.flagged_s / m.region_s)
    text = ws.markdown([cyl_rows[0][2]], [m], "voxwarp x")
    assert text.startswith("Command: `voxwarp x`")
    assert "| cylinder | 2 |" in text
    assert "| paper | 2 |" in text


def test_cli_storage_writes_the_report(
    cyl_rows: Any, tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: Any
) -> None:
    rows, mode = cyl_rows
    seen: dict[str, Any] = {}

    def fake(repeats: int, images: bool, frames: int, log: Any) -> Any:
        seen.update(repeats=repeats, images=images, frames=frames)
        return rows, [mode]

    monkeypatch.setattr(ws, "bench_storage", fake)
    monkeypatch.setattr(sys, "argv", ["pytest"])
    p = argparse.ArgumentParser(prog="python -m benchmarks")
    bw.add_bench_wires_parser(p.add_subparsers(dest="bench"))
    out = tmp_path / "storage.md"
    argv = ["wires", "--storage", "--repeats", "2", "--frames", "3", "--no-render"]
    args = p.parse_args([*argv, "--markdown", str(out)])
    assert args.func(args) == 0
    assert seen == {"repeats": 2, "images": False, "frames": 3}
    text = out.read_text()
    assert text in capsys.readouterr().out
    assert "--storage" in text.splitlines()[0]
    assert "mask bytes" in text


def test_render_summary_names_the_paper_layout_and_mask_bytes(tmp_path: Path) -> None:
    from tests.cli.test_cli_wires import wire_file
    from voxwarp.cli.deformation import _wire_warp
    from voxwarp.core.volume import Volume

    data = np.zeros((24, 24, 24), dtype=np.float32)
    data[8:16, 2:22, 8:16] = 500.0
    args = argparse.Namespace(
        wires=str(wire_file(tmp_path)), field_scale=None, layout="paper", masks=None
    )
    warp, summary = _wire_warp(args, Volume(data))
    st = warp.deformer.stats
    assert warp.field.layout == "paper"
    assert f"paper), {st.planes - st.planes_dropped} planes" in summary
    assert f"({st.mask_bytes_total} bytes of masks)" in summary
    assert st.mask_bytes_total > 0


def test_storage_rows_time_each_layouts_render(gl_ctx: Any, monkeypatch: Any) -> None:
    monkeypatch.setattr(ws, "RENDER_SIZE", (64, 32))  # small: the rows, not the speed
    vol = cylinder()
    wires = [wire(modified=axis_points(dy=3.0, dz=-3.0))]
    rows = ws.storage_rows("cylinder", vol, wires, 2, ctx=gl_ctx, frames=1, log=lambda s: None)
    for r in rows:
        assert r.frame_ms is not None
        assert r.frame_ms > 0
        assert r.render_ratio is not None
        assert r.render_ratio > 0
    assert "x |" in ws.markdown(rows, [], "voxwarp x")  # the ratio column is filled
