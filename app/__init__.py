"""voxwarp application layer: volume I/O, scene, camera, transfer functions, renderer, CLI.

>>> from app import load_volume, Scene, OffscreenRenderer
>>> vol = load_volume("sample:fish")
>>> scene = Scene(vol, mode="dvr", transfer_function="ct-bone", view="+z", step=1.0)
>>> with OffscreenRenderer(512, 512) as r:
...     img = r.render(scene)          # (512, 512, 4) uint8, row 0 = top
"""

from app.camera import Camera
from app.errors import (
    MeshError,
    RenderError,
    SceneError,
    VolumeError,
    VolumeTooLargeError,
    VoxwarpError,
)
from app.image_io import read_image, write_image
from app.io import load_volume, save_volume, volume_info, volume_summary
from app.mesh import Mesh, MeshInstance, instances_from_scene_graph, load_mesh
from app.render import OffscreenRenderer, Renderer, create_context
from app.samples import load_sample, sample_names
from app.scene import MODES, Scene
from app.transfer_function import PRESETS, TransferFunction
from app.volume import Volume

__all__ = [
    "MODES",
    "PRESETS",
    "Camera",
    "Mesh",
    "MeshError",
    "MeshInstance",
    "OffscreenRenderer",
    "RenderError",
    "Renderer",
    "Scene",
    "SceneError",
    "TransferFunction",
    "Volume",
    "VolumeError",
    "VolumeTooLargeError",
    "VoxwarpError",
    "create_context",
    "instances_from_scene_graph",
    "load_mesh",
    "load_sample",
    "load_volume",
    "read_image",
    "sample_names",
    "save_volume",
    "volume_info",
    "volume_summary",
    "write_image",
]
