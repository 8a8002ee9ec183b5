"""Two holes a mutation audit found (issue 33), closed:

* resume must vouch for a frame file by its bytes (SHA-256), not its size: a frame
  corrupted in place to the same size is re-rendered;
* a frame writer that writes a readable but different image must fail the frame (the
  read-back comparison in :func:`render_frame_to_file`), leaving no file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.animation import frames
from voxwarp.animation.frames import file_record, render_frame_to_file
from voxwarp.animation.movie import FrameFolder, FrameJob, frame_name
from voxwarp.errors import OutputError
from voxwarp.io import images


def _finished_folder(folder: Path, count: int = 3) -> list[FrameJob]:
    """A frame folder whose manifest vouches for ``count`` frame files."""
    ff = FrameFolder(folder, count, ".png")
    jobs = []
    for i in range(count):
        path = folder / frame_name(i, ".png")
        images.write_image(path, np.full((6, 8, 4), 40 * i, np.uint8))
        job = FrameJob(i, {}, str(path), f"digest{i}")
        ff.record(job, *file_record(path))
        jobs.append(job)
    ff.write_manifest()
    return jobs


def test_same_size_corruption_is_not_resumed(tmp_path: Path) -> None:
    jobs = _finished_folder(tmp_path)
    path = Path(jobs[1].path)
    data = bytearray(path.read_bytes())
    data[-20] ^= 0xFF  # one byte flipped: the size is the same
    path.write_bytes(bytes(data))
    ff = FrameFolder(tmp_path, len(jobs), ".png")
    assert ff.changed == 1
    assert ff.keep(jobs[0])
    assert ff.keep(jobs[2])
    assert not ff.keep(jobs[1])
    assert not path.exists()  # nothing vouches for it: deleted, rendered again


def test_a_readable_but_different_frame_fails(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    rendered = np.full((6, 8, 4), 200, np.uint8)
    rendered[..., 3] = 255  # opaque, as frames are (PNG alpha is unassociated)
    real_write = images.write_image

    def wrong_writer(path: Any, image: np.ndarray) -> Any:
        other = image.copy()
        other[2, 3, 0] ^= 1  # a valid PNG of another image
        return real_write(path, other)

    monkeypatch.setattr(frames, "render_frame", lambda header, scene: rendered)
    monkeypatch.setattr(images, "write_image", wrong_writer)
    out = tmp_path / "frame_00000.png"
    with pytest.raises(OutputError, match="does not read back as written"):
        render_frame_to_file({}, {}, out)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(images, "write_image", real_write)
    assert render_frame_to_file({}, {}, out)["size"] == out.stat().st_size
