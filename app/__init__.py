"""voxwarp: deform 3D volumes and meshes at render time, without resampling the volume.

```python
from voxwarp import load_volume, Scene, OffscreenRenderer
vol = load_volume("sample:fish")
scene = Scene(vol, mode="dvr", transfer_function="ct-bone", view="+z", step=1.0)
with OffscreenRenderer(512, 512) as r:
    img = r.render(scene)  # (512, 512, 4) uint8, row 0 = top
```

The deformation models are in :mod:`voxwarp.deform`. Names load on first use, so
``import voxwarp`` stays cheap (no numba, scipy, OpenCL or Qt until they are needed).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from voxwarp.huge_pages import small_pages
from voxwarp.lazy import exports

small_pages()

#: public name -> module that defines it (imported on first access)
_PUBLIC: dict[str, str] = {
    "Camera": "voxwarp.core.camera",
    "MeshError": "voxwarp.errors",
    "RenderError": "voxwarp.errors",
    "SceneError": "voxwarp.errors",
    "VolumeError": "voxwarp.errors",
    "VolumeTooLargeError": "voxwarp.errors",
    "VoxwarpError": "voxwarp.errors",
    "FieldError": "voxwarp.errors",
    "load_displacement_field": "voxwarp.io.fields",
    "load_transform": "voxwarp.io.fields",
    "save_displacement_field": "voxwarp.io.fields",
    "read_image": "voxwarp.io.images",
    "write_image": "voxwarp.io.images",
    "load_volume": "voxwarp.io.volumes",
    "save_volume": "voxwarp.io.volumes",
    "volume_info": "voxwarp.io.volumes",
    "volume_summary": "voxwarp.io.volumes",
    "Mesh": "voxwarp.core.mesh",
    "MeshInstance": "voxwarp.core.mesh",
    "instances_from_scene_graph": "voxwarp.core.mesh",
    "load_mesh": "voxwarp.core.mesh",
    "mesh_from_labels": "voxwarp.core.labels_mesh",
    "OffscreenRenderer": "voxwarp.render.offscreen",
    "Renderer": "voxwarp.render.raycaster",
    "create_context": "voxwarp.render.context",
    "load_sample": "voxwarp.io.samples",
    "sample_names": "voxwarp.io.samples",
    "MODES": "voxwarp.scene",
    "Scene": "voxwarp.scene",
    "PRESETS": "voxwarp.core.transfer_function",
    "TransferFunction": "voxwarp.core.transfer_function",
    "Volume": "voxwarp.core.volume",
}

__all__ = ["__version__", *sorted(_PUBLIC)]


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("voxwarp")
    except metadata.PackageNotFoundError:  # running from a source tree that is not installed
        return "0+unknown"


__getattr__, __dir__ = exports(__name__, _PUBLIC, {"__version__": _version})


def _scene_png(scene: object) -> bytes | None:
    # loaded by name on first use, as the _PUBLIC names are: the package's face hands on
    # to the layer that draws (voxwarp.notebook) without tying the layers below to it
    from importlib import import_module

    return import_module("voxwarp.notebook.display").scene_png(scene)


def _show_scenes_inline() -> None:
    """In a running IPython (Jupyter), a cell ending in a ``Scene`` shows a small render
    of it from ``import voxwarp`` on: the formatter is registered by the class's name, so
    nothing is imported until a scene is shown (:mod:`voxwarp.notebook.display`)."""
    import sys

    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    if shell is not None:
        formatter = shell.display_formatter.formatters["image/png"]
        formatter.for_type_by_name("voxwarp.scene", "Scene", _scene_png)


_show_scenes_inline()


if TYPE_CHECKING:  # for type checkers and IDEs; at run time __getattr__ loads these
    from voxwarp.core.camera import Camera
    from voxwarp.core.labels_mesh import mesh_from_labels
    from voxwarp.core.mesh import Mesh, MeshInstance, instances_from_scene_graph, load_mesh
    from voxwarp.core.transfer_function import PRESETS, TransferFunction
    from voxwarp.core.volume import Volume
    from voxwarp.errors import (
        FieldError,
        MeshError,
        RenderError,
        SceneError,
        VolumeError,
        VolumeTooLargeError,
        VoxwarpError,
    )
    from voxwarp.io.fields import load_displacement_field, load_transform, save_displacement_field
    from voxwarp.io.images import read_image, write_image
    from voxwarp.io.samples import load_sample, sample_names
    from voxwarp.io.volumes import load_volume, save_volume, volume_info, volume_summary
    from voxwarp.render.context import create_context
    from voxwarp.render.offscreen import OffscreenRenderer
    from voxwarp.render.raycaster import Renderer
    from voxwarp.scene import MODES, Scene
