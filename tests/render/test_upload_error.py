"""A failed volume upload names its real cause (issue 33): only moderngl's GL errors are
"the GPU could not allocate the texture"; any other error is reported as itself."""

from __future__ import annotations

from typing import Any

import moderngl
import numpy as np
import pytest

from voxwarp.core.volume import Volume
from voxwarp.errors import RenderError, VolumeTooLargeError
from voxwarp.render import raycaster
from voxwarp.render.raycaster import Renderer, upload_error
from voxwarp.scene import Scene

VOL = Volume(np.zeros((8, 8, 8), np.uint8))


def test_gl_errors_are_allocation_failures() -> None:
    err = upload_error(VOL, moderngl.Error("GL_OUT_OF_MEMORY"))
    assert isinstance(err, VolumeTooLargeError)
    assert "could not allocate" in str(err)
    assert "GL_OUT_OF_MEMORY" in str(err)


def test_other_errors_keep_their_cause() -> None:
    err = upload_error(VOL, ValueError("bad stride\n  in upload"))
    assert isinstance(err, RenderError)
    assert "could not allocate" not in str(err)
    assert "ValueError: bad stride in upload" in str(err)
    mem = upload_error(VOL, MemoryError())
    assert isinstance(mem, VolumeTooLargeError)
    assert "not enough memory" in str(mem)


def test_draw_reports_the_real_cause(
    gl_ctx: Any, offscreen: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    def broken(*args: Any, **kwargs: Any) -> Any:
        raise KeyError("component 'r'")

    monkeypatch.setattr(raycaster, "_VolumeGPU", broken)
    renderer = Renderer(gl_ctx, sampling="texture3d")
    try:
        with pytest.raises(RenderError, match="KeyError") as info:
            renderer.draw(Scene(VOL, transfer_function="grayscale"), offscreen(8, 8).framebuffer)
    finally:
        renderer.release()
    assert "could not allocate" not in str(info.value)
