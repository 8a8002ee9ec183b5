"""The :class:`Scene`: everything needed to reproduce an image, serialisable to JSON.

A scene holds a volume, a compositing mode, a transfer function, a view, the sample
distance, a chain of warps and optionally mesh instances (:mod:`voxwarp.core.mesh`), drawn
depth-composited with the volume. It never touches the GPU; the renderer reads it.
Scene JSON refers to the volume by path (relative to the JSON file when possible),
by bundled sample name, or embeds a small array (base64, no pickle).
"""

from __future__ import annotations

import base64
import json
import math
import numbers
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

import voxwarp.io.fields  # noqa: F401 - installs the readers of file-backed warps
from voxwarp.core import limits
from voxwarp.core.allowed_folders import allowed_folders
from voxwarp.core.camera import PROJECTIONS, Camera, Projection, View, view_rotation
from voxwarp.core.checks import (
    MAX_INTERACTIVE_DOWNSAMPLE,
    finite_box,
    finite_vector,
    interactive_downsample,
)
from voxwarp.core.comparison import Comparison
from voxwarp.core.field_check import TOLERANCE_MM
from voxwarp.core.field_grid import (
    FieldExport,
    Sampler,
    chain_field,
    export_chain,
    field_grid,
)
from voxwarp.core.files import atomic_write_text
from voxwarp.core.jacobian import JacobianMap, chain_determinant
from voxwarp.core.json_input import read_json
from voxwarp.core.levels import LEVEL_ATTRIBUTES, Level, default_level
from voxwarp.core.mesh import MeshInstance
from voxwarp.core.mesh_warp import mesh_instances_bounds
from voxwarp.core.minip_hint import minip_slab_hint
from voxwarp.core.modality import (
    default_shading,
    describe,
    display_defaults,
    iso_range_warning,
    uses_transfer_function,
)
from voxwarp.core.modes import MODES as MODES
from voxwarp.core.modes import Mode as Mode
from voxwarp.core.orientation import ANATOMICAL_VIEWS
from voxwarp.core.scene_paths import path_entry, scene_file
from voxwarp.core.scene_seal import SEAL_KEY, config_dir, seal_paths, trust_sealed
from voxwarp.core.transfer_function import TransferFunction, file_spec
from voxwarp.core.volume import Volume, check_finite
from voxwarp.deform.warp import (
    Warp,
    WarpError,
    chain_deformed_bounds,
    warp_class,
    warp_from_dict,
)
from voxwarp.errors import FieldError, MeshError, SceneError, VolumeError
from voxwarp.io.samples import load_sample
from voxwarp.io.volumes import load_volume

if TYPE_CHECKING:
    from voxwarp.deform.fields.displacement import DisplacementFieldWarp

#: Largest volume (bytes) a scene JSON embeds instead of referring to a file.
EMBED_LIMIT_BYTES = 8 * 1024 * 1024
#: Samples made by generators (their shape is stored in scene JSON).
GENERATED_SAMPLES = ("fish", "tubes", "head")
#: What a fitted camera frames: the volume's own box or the box of the warped volume.
Frame = Literal["undeformed", "deformed"]
FRAMES: tuple[str, ...] = ("undeformed", "deformed")
SCENE_FORMAT = "voxwarp-scene"
SCENE_VERSION = 1


def _finite(x: Any, what: str, positive: bool = False) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{what} must be a number; got {x!r}") from exc
    if not math.isfinite(v) or (positive and v <= 0):
        raise SceneError(f"{what} must be {'positive and ' if positive else ''}finite; got {x!r}")
    return v


def check_interactive_downsample(value: Any) -> int:
    """``value`` as an interactive downsampling factor (1..16, 1: full resolution);
    :class:`SceneError` otherwise."""
    return interactive_downsample(value, SceneError)


def _vec(x: Any, n: int, what: str) -> tuple[float, ...]:
    return tuple(float(v) for v in finite_vector(x, n, what, SceneError))


def default_view(volume: Volume) -> str:
    """The view a scene of ``volume`` starts from: ``"anterior"`` (head up) for a volume
    with a patient orientation, ``"-y"`` otherwise."""
    return "anterior" if volume.space else "-y"


class Scene:
    """A renderable scene description: what to draw and how, but no GPU state.

    Build one from a volume and pass it to
    :meth:`voxwarp.render.offscreen.OffscreenRenderer.render`; :meth:`copy` makes a
    variant with some arguments changed, and :meth:`save` / :meth:`load` write and read
    it as scene JSON. Invalid values raise :class:`~voxwarp.errors.SceneError`.

    Parameters
    ----------
    volume
        The :class:`~voxwarp.core.volume.Volume` to render.
    mode
        Compositing mode: ``dvr`` (emission-absorption), ``mip``, ``minip``,
        ``average`` (mean along the ray), ``xray`` (radiograph: line integral over a
        fixed length; see :mod:`voxwarp.core.modes`), ``flm`` (first local maximum) or
        ``iso`` (shaded isosurface).
    transfer_function
        Preset name (see :data:`voxwarp.core.transfer_function.PRESETS`), a matplotlib
        colour-map name (``"viridis"``: a ramp over the volume's window), a list of
        ``(value, r, g, b, a)`` control points in data units, or a
        :class:`~voxwarp.core.transfer_function.TransferFunction` (files of voxwarp,
        ParaView and 3D Slicer: :meth:`TransferFunction.load
        <voxwarp.core.transfer_function.TransferFunction.load>`); ``None`` (default)
        picks one for the volume's modality (:mod:`voxwarp.core.modality`: ``ct-bone``
        for CT in HU, ``mri`` for MR, a percentile ramp for other data).
    view
        ``"+x"``, ``"-x"``, ``"+y"``, ``"-y"``, ``"+z"``, ``"-z"`` (the side the camera is
        on) or ``(azimuth, elevation)`` in degrees.
    projection
        ``"perspective"`` or ``"orthographic"``.
    step
        Sample distance in voxels (of the smallest spacing).
    warps
        Chain of :class:`voxwarp.deform.warp.Warp` applied in order (deformed -> original).
    window
        ``(level, width)`` in data units for the grey-value modes; default from robust
        percentiles of the voxels inside the field of view, per mode
        (:func:`voxwarp.core.modality.display_defaults`).
    clip_box
        ``((x0, y0, z0), (x1, y1, z1))`` in deformed world mm; rays are cut to it.
    jitter
        Jitter ray starts per pixel (deterministic hash of pixel and ``seed``) against
        wood-grain artefacts.
    seed
        Jitter seed.
    shading
        Blinn-Phong shading from gradients; ``None`` means on for ``iso``/``flm``, and for
        ``dvr`` on where the transfer function is a preset that shows surfaces
        (:data:`voxwarp.core.modality.SURFACE_PRESETS`), off otherwise.
    iso_value
        Isovalue for ``iso`` (data units); default from the histogram: the split of
        object and background (MR and other data: the object's outer surface), on a CT
        where the transfer function's opacity first reaches a quarter of its maximum,
        never below that split (:mod:`voxwarp.core.levels`).
    flm_threshold
        Threshold for ``flm`` (data units); default as ``iso_value``, with the lowest
        value the transfer function shows on a CT (:mod:`voxwarp.core.levels`).
    background
        RGBA background in [0, 1].
    camera
        An explicit :class:`~voxwarp.core.camera.Camera`; ``None`` fits one to the volume from
        ``view``, ``projection``, ``fov`` and ``zoom``.
    frame
        What the fitted camera frames: ``"undeformed"`` (default: the volume's own box,
        so images before and after a deformation share the framing and a translation
        shows as a shift) or ``"deformed"`` (the box of the warped volume, refitted to
        every deformation). An explicit ``camera`` ignores it.
    zoom, fov
        Magnification and vertical field of view (degrees) of the fitted camera.
    meshes
        :class:`~voxwarp.core.mesh.MeshInstance` objects drawn with the volume, depth-composited
        (rays stop at opaque mesh surfaces; the volume is composited over the meshes).
        The fitted camera then frames the volume and the meshes. A mesh-only picture
        still needs a volume: use a tiny empty one (e.g. ``Volume(np.zeros((2, 2, 2),
        np.uint8))`` with a transfer function that shows nothing).
    fixed
        A registration's fixed image (a Volume, a volume path or ``"sample:NAME"``, on
        any grid): renders and slices then compare the volume seen through the warps
        (the moving image) with it at the same world points, as ``compare`` says
        (:mod:`voxwarp.core.comparison`); None (default): no comparison. Kept as the
        settable attribute ``comparison`` (a :class:`~voxwarp.core.comparison.Comparison`
        or None); ``fixed`` reads its volume. Scene JSON stores it in ``"fixed"`` (as
        the volume: a path relative to the scene file, a sample or embedded) and
        ``"compare"``.
    compare
        ``"checkerboard"`` (default: cubes of ``checker_mm`` alternate moving and
        fixed), ``"difference"`` (3D: ``|moving - fixed|`` through the transfer
        function) or ``"blend"``.
    blend
        The fixed image's weight for ``compare="blend"`` (0 = moving, 1 = fixed).
    checker_mm
        Checker cell size in mm; None: about 1/8 of the fixed image's longest side.
    interactive_downsample
        The volume resolution of interactive frames (the thesis's setting, section 3.2):
        the GUI and the notebook viewer draw frames taken while the user drags or orbits
        from the volume reduced by this factor per axis (over the same box:
        :mod:`voxwarp.render.interaction_volume`); 1 (default) keeps full resolution.
        Stills (the view at rest, screenshots, ``voxwarp render``, exports) always draw
        the full volume.
    """

    def __init__(
        self,
        volume: Volume,
        mode: Mode = "dvr",
        transfer_function: Any = None,
        view: View | None = None,
        projection: Projection = "perspective",
        step: float = 1.0,
        warps: Sequence[Warp] | None = None,
        *,
        window: tuple[float, float] | None = None,
        clip_box: tuple[Sequence[float], Sequence[float]] | None = None,
        jitter: bool = True,
        seed: int = 0,
        shading: bool | None = None,
        iso_value: float | None = None,
        flm_threshold: float | None = None,
        background: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
        camera: Camera | None = None,
        zoom: float = 1.0,
        fov: float = 30.0,
        meshes: Sequence[MeshInstance] | None = None,
        frame: Frame = "undeformed",
        fixed: Any = None,
        compare: str = "checkerboard",
        blend: float = 0.5,
        checker_mm: float | None = None,
        interactive_downsample: int = 1,
    ) -> None:
        if not isinstance(volume, Volume):
            raise SceneError(
                f"Scene needs a Volume (from app.load_volume); got {type(volume).__name__}"
            )
        self.volume = volume
        self.mode = mode
        self.transfer_function = _scene_transfer_function(transfer_function, volume, mode)
        self.view = default_view(volume) if view is None else view
        self.projection = projection
        self.step = step
        self.warps: list[Warp] = list(warps or [])
        self.window = window
        self.clip_box = clip_box
        self.jitter = bool(jitter)
        self.seed = int(seed)
        self.shading = shading
        self.iso_value = iso_value
        if mode == "iso" and iso_value is not None:
            _warn_iso_range(volume, iso_value)
        self.flm_threshold = flm_threshold
        self.background = background
        self.camera = camera
        self.zoom = zoom
        self.fov = fov
        self.meshes = meshes
        self.frame = frame
        self.interactive_downsample = interactive_downsample
        self.comparison: Comparison | None = None
        if fixed is not None:
            self.comparison = Comparison(as_fixed_volume(fixed), compare, blend, checker_mm)

    @property
    def fixed(self) -> Volume | None:
        """The fixed image of the comparison (None without one); see ``Scene(fixed=)``."""
        return None if self.comparison is None else self.comparison.fixed

    # ------------------------------------------------------------------ validated attributes
    @property
    def mode(self) -> str:
        """Compositing mode, one of :data:`MODES`."""
        return self._mode

    @mode.setter
    def mode(self, value: str) -> None:
        if value not in MODES:
            raise SceneError(f"mode must be one of {', '.join(MODES)}; got {value!r}")
        self._mode = value

    @property
    def interactive_downsample(self) -> int:
        """Per-axis reduction of the volume in interactive frames (1: full resolution);
        see ``Scene(interactive_downsample=)``."""
        return self._interactive_downsample

    @interactive_downsample.setter
    def interactive_downsample(self, value: int) -> None:
        self._interactive_downsample = check_interactive_downsample(value)

    @property
    def frame(self) -> str:
        """What the fitted camera frames, one of :data:`FRAMES`."""
        return self._frame

    @frame.setter
    def frame(self, value: str) -> None:
        if value not in FRAMES:
            raise SceneError(f"frame must be one of {', '.join(FRAMES)}; got {value!r}")
        self._frame = value

    @property
    def view(self) -> View:
        """Standard view name or (azimuth, elevation)."""
        return self._view

    @view.setter
    def view(self, value: View) -> None:
        if not isinstance(value, str):
            try:
                value = tuple(float(v) for v in value)  # type: ignore[assignment]
            except (TypeError, ValueError) as exc:
                raise SceneError(
                    "view must be one of +x, -x, +y, -y, +z, -z, an anatomical view"
                    f" (anterior, posterior, ...) or (azimuth, elevation) degrees; got {value!r}"
                ) from exc
        view_rotation(value)  # validates
        if value in ANATOMICAL_VIEWS and not self.volume.space:
            raise SceneError(
                f"view {value!r} needs a patient orientation, and volume {self.volume.name!r}"
                " has none (an array or a file without orientation); use an axis view"
                " (+x, -x, +y, -y, +z, -z) or load a NIfTI, NRRD or DICOM file"
            )
        self._view = value

    @property
    def projection(self) -> str:
        """``perspective`` or ``orthographic``."""
        return self._projection

    @projection.setter
    def projection(self, value: str) -> None:
        if value not in PROJECTIONS:
            raise SceneError(f"projection must be one of {', '.join(PROJECTIONS)}; got {value!r}")
        self._projection = value

    @property
    def step(self) -> float:
        """Sample distance in voxels of the smallest spacing."""
        return self._step

    @step.setter
    def step(self, value: float) -> None:
        v = _finite(value, "step", positive=True)
        if not 0.01 <= v <= 100:
            raise SceneError(f"step must be between 0.01 and 100 voxels; got {v}")
        self._step = v

    @property
    def window(self) -> tuple[float, float]:
        """``(level, width)`` for grey-value modes."""
        if self._window is not None:
            return self._window
        return display_defaults(self.volume, self.mode).window

    @window.setter
    def window(self, value: tuple[float, float] | None) -> None:
        if value is None:
            self._window = None
            return
        level, width = _vec(value, 2, "window (level, width)")
        if width <= 0:
            raise SceneError(f"window width must be positive; got {width}")
        self._window = (level, width)

    @property
    def window_given(self) -> bool:
        """Whether :attr:`window` was set (argument, setter or scene JSON), not a default."""
        return self._window is not None

    @property
    def clip_box(self) -> tuple[tuple[float, ...], tuple[float, ...]] | None:
        """Clipping box in deformed world mm, or None."""
        return self._clip_box

    @clip_box.setter
    def clip_box(self, value: Any) -> None:
        if value is None:
            self._clip_box = None
            return
        lo, hi = finite_box(value, "clip_box", SceneError)
        self._clip_box = (tuple(map(float, lo)), tuple(map(float, hi)))

    @property
    def background(self) -> tuple[float, float, float, float]:
        """RGBA background in [0, 1]."""
        return self._background

    @background.setter
    def background(self, value: Sequence[float]) -> None:
        if not hasattr(value, "__len__") or len(value) not in (3, 4):
            raise SceneError(
                f"background must be (r, g, b) or (r, g, b, a) in [0, 1]; got {value!r}"
            )
        v = (
            _vec(value, 4, "background (r, g, b, a)")
            if len(value) == 4
            else (
                *_vec(value, 3, "background (r, g, b)"),
                1.0,
            )
        )
        if any(c < 0 or c > 1 for c in v):
            raise SceneError(f"background components must lie in [0, 1]; got {v}")
        self._background = v  # type: ignore[assignment]

    @property
    def zoom(self) -> float:
        """Magnification of the fitted camera, in [:data:`~voxwarp.core.limits.MIN_ZOOM`,
        :data:`~voxwarp.core.limits.MAX_ZOOM`]."""
        return self._zoom

    @zoom.setter
    def zoom(self, value: float) -> None:
        zoom = _finite(value, "zoom", positive=True)
        if not limits.MIN_ZOOM <= zoom <= limits.MAX_ZOOM:
            raise SceneError(
                f"zoom must lie in [{limits.MIN_ZOOM:g}, {limits.MAX_ZOOM:g}] (1 frames the"
                f" volume); got {zoom:g}"
            )
        self._zoom = zoom

    @property
    def fov(self) -> float:
        """Vertical field of view (degrees) of the fitted camera."""
        return self._fov

    @fov.setter
    def fov(self, value: float) -> None:
        v = _finite(value, "fov", positive=True)
        if v >= 179:
            raise SceneError(f"fov must be below 179 degrees; got {v}")
        self._fov = v

    @property
    def meshes(self) -> list[MeshInstance]:
        """Mesh instances drawn with the volume (a new list; assign to change)."""
        return list(self._meshes)

    @meshes.setter
    def meshes(self, value: Sequence[MeshInstance] | None) -> None:
        if value is None:
            self._meshes: list[MeshInstance] = []
            return
        if isinstance(value, MeshInstance) or not isinstance(value, Sequence):
            raise SceneError(
                f"meshes must be a list of voxwarp.MeshInstance; got {type(value).__name__}"
            )
        for i, m in enumerate(value):
            if not isinstance(m, MeshInstance):
                raise SceneError(
                    f"meshes[{i}] must be an voxwarp.core.mesh.MeshInstance (wrap a Mesh:"
                    f" MeshInstance(mesh)); got {type(m).__name__}"
                )
        self._meshes = list(value)

    # ------------------------------------------------------------------ derived values
    @property
    def sample_distance_mm(self) -> float:
        """Sample distance along rays in mm."""
        return self.step * min(self.volume.spacing)

    @property
    def opacity_reference_mm(self) -> float:
        """Distance (mm) that transfer-function opacities refer to: one smallest voxel."""
        return min(self.volume.spacing)

    def use_shading(self) -> bool:
        """Whether this scene shades (resolves ``shading=None``)."""
        if self.shading is None:
            return default_shading(self.mode, self.transfer_function)
        return bool(self.shading)

    def display_note(self) -> str:
        """One line: the volume's modality and what this scene draws with (transfer
        function and shading, or window), and its padding (see
        :mod:`voxwarp.core.modality`); ``voxwarp render`` prints it, the GUI shows it."""
        return describe(
            self.volume,
            self.mode,
            self.transfer_function,
            self.window,
            self.use_shading(),
            window_given=self._window is not None,
            level=self.resolved_level().text(self.mode) if self.mode in LEVEL_ATTRIBUTES else None,
            hint=self._minip_hint() if self.mode == "minip" else None,
        )

    def _minip_hint(self) -> str | None:
        """The slab a nearly all dark ``minip`` needs (:mod:`voxwarp.core.minip_hint`)."""
        back = self.resolved_camera().rotation[:, 2]
        return minip_slab_hint(self.volume, self.window, back, self.ray_bounds())

    def resolved_iso_value(self) -> float:
        """The isovalue used by ``iso`` (given, or :func:`~voxwarp.core.levels.default_level`)."""
        return self.resolved_level("iso").value

    def resolved_flm_threshold(self) -> float:
        """The first-local-maximum threshold used by ``flm`` (given, or the default)."""
        return self.resolved_level("flm").value

    def resolved_level(self, mode: str | None = None) -> Level:
        """The level of threshold ``mode`` (default this scene's; ``"iso"`` or ``"flm"``)
        and why: the given ``iso_value`` / ``flm_threshold``, else the histogram's
        (:func:`voxwarp.core.levels.default_level`)."""
        mode = self.mode if mode is None else mode
        if mode not in LEVEL_ATTRIBUTES:
            raise SceneError(f"mode {mode!r} has no level; the threshold modes are iso and flm")
        name = LEVEL_ATTRIBUTES[mode]
        given = getattr(self, name)
        if given is not None:
            return Level(_finite(given, name), "given")
        return default_level(self.volume, self.transfer_function, mode)

    def deformed_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Box in deformed space holding the warped volume (before clipping)."""
        lo, hi = self.volume.bounds
        return chain_deformed_bounds(self.warps, lo, hi)

    def ray_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Deformed-space box the rays march in: warped volume box ∩ clipping box."""
        lo, hi = self.deformed_bounds()
        if self.clip_box is not None:
            lo = np.maximum(lo, self.clip_box[0])
            hi = np.minimum(hi, self.clip_box[1])
        return lo, hi

    def resolved_camera(self) -> Camera:
        """The explicit camera, or one fitted to the volume (its own box, or the warped box
        with ``frame="deformed"``) and the meshes."""
        if self.camera is not None:
            return self.camera
        lo, hi = self.deformed_bounds() if self.frame == "deformed" else self.volume.bounds
        if self._meshes:
            warps = self.warps if self.frame == "deformed" else ()
            mlo, mhi = mesh_instances_bounds(self._meshes, warps)  # type: ignore[misc]
            lo, hi = np.minimum(lo, mlo), np.maximum(hi, mhi)
        return Camera.fit(lo, hi, self.view, self.projection, fov=self.fov, zoom=self.zoom)

    def copy(self, **changes: Any) -> Scene:
        """A shallow copy with some constructor arguments changed."""
        kw = self._kwargs()
        kw.update(changes)
        return Scene(**kw)

    def _kwargs(self) -> dict[str, Any]:
        return {
            "volume": self.volume,
            "mode": self.mode,
            "transfer_function": self.transfer_function,
            "view": self.view,
            "projection": self.projection,
            "step": self.step,
            "warps": list(self.warps),
            "window": self._window,
            "clip_box": self.clip_box,
            "jitter": self.jitter,
            "seed": self.seed,
            "shading": self.shading,
            "iso_value": self.iso_value,
            "flm_threshold": self.flm_threshold,
            "background": self.background,
            "camera": self.camera,
            "zoom": self.zoom,
            "fov": self.fov,
            "meshes": list(self._meshes),
            "frame": self.frame,
            "interactive_downsample": self.interactive_downsample,
            **_comparison_kwargs(self.comparison),
        }

    # ------------------------------------------------------------------ serialisation
    def to_dict(self, base_dir: str | os.PathLike | None = None) -> dict[str, Any]:
        """JSON-serialisable description; volume paths relative to ``base_dir`` if given."""
        d: dict[str, Any] = {
            "format": SCENE_FORMAT,
            "version": SCENE_VERSION,
            "volume": _volume_to_dict(self.volume, base_dir),
            "mode": self.mode,
            "transfer_function": self.transfer_function.to_dict(),
            "view": self.view if isinstance(self.view, str) else list(self.view),
            "projection": self.projection,
            "step": self.step,
            "warps": [_warp_entry(w, base_dir) for w in self.warps],
            "window": list(self._window) if self._window is not None else None,
            "clip_box": [list(c) for c in self.clip_box] if self.clip_box else None,
            "jitter": self.jitter,
            "seed": self.seed,
            "shading": self.shading,
            "iso_value": self.iso_value,
            "flm_threshold": self.flm_threshold,
            "background": list(self.background),
            "camera": self.camera.to_dict() if self.camera is not None else None,
            "zoom": self.zoom,
            "fov": self.fov,
            "frame": self.frame,
        }
        if self.interactive_downsample != 1:  # absent at full resolution (older files)
            d["interactive_downsample"] = self.interactive_downsample
        if self.comparison is not None:  # absent without a fixed image
            d["fixed"] = _volume_to_dict(self.comparison.fixed, base_dir)
            d["compare"] = self.comparison.settings_dict()
        if self._meshes:  # absent without meshes: scene JSON stays as before
            try:
                d["meshes"] = [m.to_dict(base_dir) for m in self._meshes]
            except MeshError as exc:
                raise SceneError(f"cannot save the scene's meshes: {exc}") from exc
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], base_dir: str | os.PathLike | None = None) -> Scene:
        """Rebuild a scene from :meth:`to_dict` output; raises :class:`SceneError`."""
        if not isinstance(d, Mapping):
            raise SceneError("a scene must be a JSON object")
        if d.get("format", SCENE_FORMAT) != SCENE_FORMAT:
            raise SceneError(f"not a voxwarp scene (format {d.get('format')!r})")
        version = d.get("version", SCENE_VERSION)
        if not isinstance(version, int) or isinstance(version, bool):
            raise SceneError(f"scene 'version' must be an integer; got {version!r}")
        if version > SCENE_VERSION:
            raise SceneError(
                f"scene version {version!r} is newer than this voxwarp understands"
                f" ({SCENE_VERSION}); upgrade voxwarp"
            )
        if "volume" not in d:
            raise SceneError("the scene has no 'volume' entry")
        check_scene_json(d)
        volume = _volume_from_dict(d["volume"], base_dir)
        try:
            warps = [warp_from_dict(_resolved_warp(w, base_dir)) for w in (d.get("warps") or [])]
            for w in warps:
                w.bind_volume(volume)
        except (WarpError, FieldError, TypeError) as exc:
            raise SceneError(f"invalid warp in scene: {exc}") from exc
        tf = d.get("transfer_function")  # absent: the modality's default
        if isinstance(tf, str) and file_spec(tf) is not None:
            raise SceneError(
                f"scene 'transfer_function' {tf!r} names a file; a scene JSON holds a preset,"
                " a colour-map name or control points: render it with --tf FILE, or save the"
                " scene from voxwarp to store the file's points in it"
            )
        if isinstance(tf, Mapping):
            tf = TransferFunction.from_dict(tf, volume)
        camera = d.get("camera")
        if camera is not None:
            if not isinstance(camera, Mapping):
                raise SceneError("scene 'camera' must be an object")
            camera = Camera.from_dict(dict(camera))
        view = d.get("view", "-y")
        if isinstance(view, list):
            view = tuple(view)
        meshes = d.get("meshes") or []
        if not isinstance(meshes, list):
            raise SceneError("scene 'meshes' must be a list of mesh instance objects")
        try:
            meshes = [MeshInstance.from_dict(m, base_dir) for m in meshes]
        except (WarpError, TypeError, ValueError) as exc:  # MeshError is a ValueError
            raise SceneError(f"invalid mesh in scene: {exc}") from exc
        kwargs: dict[str, Any] = {
            "mode": d.get("mode", "dvr"),
            "transfer_function": tf,
            "view": view,
            "projection": d.get("projection", "perspective"),
            "step": d.get("step", 1.0),
            "warps": warps,
            "window": d.get("window"),
            "clip_box": d.get("clip_box"),
            "jitter": d.get("jitter", True),
            "seed": d.get("seed", 0),
            "shading": d.get("shading"),
            "iso_value": d.get("iso_value"),
            "flm_threshold": d.get("flm_threshold"),
            "background": d.get("background", (0, 0, 0, 1)),
            "camera": camera,
            "zoom": d.get("zoom", 1.0),
            "fov": d.get("fov", 30.0),
            "meshes": meshes,
            "frame": d.get("frame", "undeformed"),  # scenes written before it: undeformed
            "interactive_downsample": d.get("interactive_downsample", 1),
            **_comparison_from_dict(d, base_dir),
        }
        for key in ("jitter",):
            if not isinstance(kwargs[key], bool):
                raise SceneError(f"scene '{key}' must be true or false")
        if not isinstance(kwargs["seed"], int) or isinstance(kwargs["seed"], bool):
            raise SceneError("scene 'seed' must be an integer")
        if kwargs["shading"] is not None and not isinstance(kwargs["shading"], bool):
            raise SceneError("scene 'shading' must be true, false or null")
        try:
            return cls(volume, **kwargs)
        except SceneError:
            raise
        except (TypeError, ValueError) as exc:
            raise SceneError(f"invalid scene: {exc}") from exc

    def save(self, path: str | os.PathLike) -> Path:
        """Write the scene as JSON, atomically (temp file + rename)."""
        return write_scene_json(path, self.to_dict, indent=2)

    @classmethod
    def load(
        cls, path: str | os.PathLike, allow_dirs: Sequence[str | os.PathLike] | None = None
    ) -> Scene:
        """Read a scene JSON written by :meth:`save`; raises :class:`SceneError`.

        The files it names must lie in its folder (or subfolders), the bundled samples or
        an allowed folder: ``allow_dirs`` adds folders for this call
        (:mod:`voxwarp.core.allowed_folders`)."""
        path = Path(path)
        with allowed_folders(allow_dirs):
            return cls.from_dict(read_scene_dict(path), base_dir=path.parent.resolve())

    def displacement_field(self, spacing: Any = None, box: Any = None) -> DisplacementFieldWarp:
        """The warp chain sampled as a displacement field, ``u(p) = warps(p) - p``.

        ITK's pull-back convention (as SimpleITK's ``DisplacementFieldTransform``, ANTs
        and 3D Slicer read it once saved by
        :func:`voxwarp.io.fields.save_displacement_field`): a point ``p`` of the deformed
        picture takes the original volume's value at ``p + u(p)``, so
        ``Resample(volume, DisplacementFieldTransform(field))`` reproduces the volume
        voxwarp draws deformed. Between nodes the field is trilinear, so the export is
        exact only where the chain is smooth at the node spacing (:meth:`export_field`
        measures that and refines the spacing). Nodes the chain does not carry (a rigid
        wire's vacated space) hold their nearest carried node's vector, so they cannot
        bleed into their neighbours' interpolation.

        Parameters
        ----------
        spacing
            ``None`` (default): the volume's own grid (its affine, direction included).
            One number or three (mm): nodes at that spacing over the volume's box,
            keeping its direction.
        box
            ``(lo, hi)`` in world mm: sample this axis-aligned box instead, at
            ``spacing`` (default the smallest voxel size).

        Raises :class:`SceneError` for a bad ``spacing`` or ``box`` or a grid over the
        memory budget.
        """
        affine, shape = field_grid(self.volume, spacing, box)
        return chain_field(self.warps, affine, shape)[0]

    def export_field(
        self,
        spacing: Any = None,
        box: Any = None,
        tolerance: float = TOLERANCE_MM,
        grid: str = "volume",
        sampler: Sampler | None = None,
    ) -> FieldExport:
        """:meth:`displacement_field` with its interpolation measured (``voxwarp export-field``).

        At cell centres inside the deformed volume, ITK's trilinear value is compared
        with the chain; with ``spacing=None`` the spacing is made finer until that is
        within ``tolerance`` mm where the chain is smooth (up to a node cap). The result
        holds the field, its outside nodes (not carried by the chain), the nodes that
        border a tear (a discontinuity no spacing interpolates) and the measured error:
        see :func:`voxwarp.core.field_grid.export_chain`. ``grid="input"`` indexes the
        nodes in the input file's axis order (its affine), ``"volume"`` in voxwarp's
        closest-RAS order (:func:`voxwarp.core.field_grid.field_grid`). ``sampler``
        samples the chain on the grid: the CPU by default, or
        :class:`voxwarp.render.field_sampling.GpuFieldSampler` (the raycaster's GLSL chain).
        """
        return export_chain(self.volume, self.warps, spacing, box, tolerance, grid, sampler)

    def jacobian_determinant(
        self,
        spacing: Any = None,
        box: Any = None,
        tolerance: float = TOLERANCE_MM,
        grid: str = "volume",
    ) -> JacobianMap:
        """``det J`` of the warp chain on the grid :meth:`export_field` writes
        (``voxwarp export-field --jacobian``).

        Evaluated from the warps' analytic Jacobians (chain rule) at every node: the
        determinant of the pull-back map ``x -> chain(x)``, i.e. ``det(I + grad u)`` of
        the exported field ``u`` as ITK's ``DisplacementFieldJacobianDeterminantFilter``
        defines it (the same in RAS and LPS). ``spacing``, ``box``, ``tolerance`` and
        ``grid`` pick the grid as in :meth:`export_field` (``spacing=None``: its refined
        default, which runs the field check). Nodes the chain does not carry are NaN. See
        :mod:`voxwarp.core.jacobian`.
        """
        if spacing is None:
            f = self.export_field(box=box, tolerance=tolerance, grid=grid).field
            affine, shape = f.affine, f.shape
        else:
            affine, shape = field_grid(self.volume, spacing, box, grid)
        return JacobianMap(chain_determinant(self.warps, affine, shape), np.asarray(affine))

    def __repr__(self) -> str:
        return (
            f"Scene(volume={self.volume.name!r}, mode={self.mode!r},"
            f" tf={self.transfer_function.name!r}, view={self.view!r},"
            f" projection={self.projection!r}, step={self.step}, warps={len(self.warps)}"
            + (f", meshes={len(self._meshes)})" if self._meshes else ")")
        )


def _scene_transfer_function(tf: Any, volume: Volume, mode: str) -> TransferFunction:
    """``tf`` resolved against ``volume``; None: the modality's default. A mode that
    draws without it (mip, minip, average, xray) leaves out the HU-preset warning."""
    if tf is None:
        return display_defaults(volume, mode).transfer_function
    if isinstance(tf, str) and file_spec(tf) is not None:
        return TransferFunction.load(tf, volume)  # FILE or FILE:NAME
    if uses_transfer_function(mode):
        return TransferFunction.coerce(tf, volume)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return TransferFunction.coerce(tf, volume)


def _warn_iso_range(volume: Volume, iso_value: Any) -> None:
    """Warn (one line) when the iso value lies outside the data range."""
    try:
        iso = float(iso_value)
    except (TypeError, ValueError):
        return  # resolved_iso_value names the bad value
    message = iso_range_warning(volume, iso)
    if message is not None:
        warnings.warn(message, stacklevel=2)  # one location: shown once per message


def read_scene_dict(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON object of a scene file, with its extra entries (``"editor"``,
    ``"animation"``); :class:`SceneError` naming the file and the problem."""
    p = Path(path)
    try:
        d = read_json(p)
    except FileNotFoundError as exc:
        raise SceneError(f"no such scene file: {p}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene file {p}: {exc}") from exc
    except ValueError as exc:
        raise SceneError(f"{p} is not valid JSON: {json_error_text(exc)}") from exc
    if not isinstance(d, dict):
        raise SceneError(f"{p}: a scene must be a JSON object")
    trust_sealed(d)
    return d


def json_error_text(exc: ValueError) -> str:
    """What is wrong with a JSON text and where (line and column), in one line."""
    if isinstance(exc, json.JSONDecodeError):
        return f"{exc.msg} at line {exc.lineno}, column {exc.colno}; fix the JSON syntax there"
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


#: Entries of scene JSON beside the scene's own: notes, the editor's and animation's, and
#: the seal of the paths it names (:mod:`voxwarp.core.scene_seal`).
SCENE_EXTRA_KEYS = ("description", "editor", "animation", SEAL_KEY)
_NUMBER = "a number (e.g. 1.5)"
#: Scene JSON entry -> (JSON types it may hold, what the error says it must be).
SCENE_TYPES: dict[str, tuple[tuple[str, ...], str]] = {
    "format": (("str",), f"the string {SCENE_FORMAT!r}"),
    "version": (("int",), "an integer"),
    "volume": (("object",), "an object with 'path', 'sample' or 'embedded'"),
    "mode": (("str",), f"one of the strings {', '.join(MODES)}"),
    "transfer_function": (("str", "list", "object", "null"), "a preset name, a list or an object"),
    "view": (("str", "pair"), "a view name or [azimuth, elevation] numbers"),
    "projection": (("str",), f"one of the strings {', '.join(PROJECTIONS)}"),
    "step": (("number",), _NUMBER),
    "warps": (("list", "null"), "a list of warp objects"),
    "window": (("pair", "null"), "[level, width] numbers or null"),
    "clip_box": (("box", "null"), "[[x0, y0, z0], [x1, y1, z1]] numbers or null"),
    "jitter": (("bool",), "true or false"),
    "seed": (("int",), "an integer"),
    "shading": (("bool", "null"), "true, false or null"),
    "iso_value": (("number", "null"), f"{_NUMBER} or null"),
    "flm_threshold": (("number", "null"), f"{_NUMBER} or null"),
    "background": (("rgba",), "[r, g, b] or [r, g, b, a] numbers in [0, 1]"),
    "camera": (("object", "null"), "a camera object or null"),
    "zoom": (("number",), _NUMBER),
    "fov": (("number",), _NUMBER),
    "frame": (("str",), f"one of the strings {', '.join(FRAMES)}"),
    "interactive_downsample": (
        ("int",),
        f"an integer from 1 (full resolution) to {MAX_INTERACTIVE_DOWNSAMPLE}",
    ),
    "meshes": (("list", "null"), "a list of mesh instance objects"),
    "fixed": (("object", "null"), "an object with 'path', 'sample' or 'embedded', or null"),
    "compare": (("object", "null"), "an object with 'show', 'blend', 'checker_mm', or null"),
}
#: Every key a scene JSON object may hold.
SCENE_KEYS: tuple[str, ...] = (*SCENE_TYPES, *SCENE_EXTRA_KEYS)


def _is_json_number(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool | np.bool_)


def _is_list(v: Any) -> bool:
    return isinstance(v, list | tuple | np.ndarray)


def _numbers(v: Any, n: int) -> bool:
    return _is_list(v) and len(v) == n and all(_is_json_number(x) for x in v)


_JSON_TYPE_CHECKS: dict[str, Callable[[Any], bool]] = {
    "str": lambda v: isinstance(v, str),
    "int": lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool | np.bool_),
    "number": _is_json_number,
    "bool": lambda v: isinstance(v, bool | np.bool_),
    "null": lambda v: v is None,
    "list": _is_list,
    "object": lambda v: isinstance(v, Mapping),
    "pair": lambda v: _numbers(v, 2),
    "rgba": lambda v: _numbers(v, 3) or _numbers(v, 4),
    "box": lambda v: _is_list(v) and len(v) == 2 and all(_numbers(c, 3) for c in v),
}


def check_scene_json(d: Mapping[str, Any]) -> None:
    """Check a scene JSON object's keys and the JSON types of its values, strictly:
    ``"step": "1"`` (a string) or ``"jitter": 1`` is an error, as is a key scene JSON does
    not have (a typo would otherwise be ignored); :class:`SceneError` naming the key, what
    it must be and the keys allowed. Values are checked further by :class:`Scene`."""
    unknown = sorted(str(k) for k in d if k not in SCENE_KEYS)
    if unknown:
        raise SceneError(
            f"unknown scene key{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))};"
            f" a scene JSON holds only {', '.join(SCENE_KEYS)}"
        )
    for key, (kinds, expected) in SCENE_TYPES.items():
        if key in d and not any(_JSON_TYPE_CHECKS[k](d[key]) for k in kinds):
            got = _short_json(d[key])
            raise SceneError(f"scene '{key}' must be {expected}; got {_json_kind(d[key])} {got}")


def _json_kind(value: Any) -> str:
    """The JSON type of ``value`` in words ("a string", "a number", ...)."""
    if isinstance(value, bool) or value is None:
        return "the literal"
    if isinstance(value, str):
        return "the string"
    if _is_json_number(value):
        return "the number"
    return "the list" if _is_list(value) else "the object"


def _short_json(value: Any) -> str:
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def write_scene_json(
    path: str | os.PathLike, to_dict: Callable[..., dict[str, Any]], indent: int
) -> Path:
    """Write ``to_dict(base_dir=<path's folder>)`` to ``path`` as JSON, atomically (a
    failed write keeps the old file); volume paths in it are relative to that folder."""
    path = Path(path)
    d = to_dict(base_dir=path.parent.resolve())
    if not seal_paths(d):
        warnings.warn(
            f"{path} names files outside its folder and could not be sealed (no writable key"
            f" in {config_dir()}): reopening it needs their folders allowed (--allow-dir)",
            stacklevel=3,
        )
    atomic_write_text(path, json.dumps(d, indent=indent))
    return path


def _volume_to_dict(volume: Volume, base_dir: str | os.PathLike | None) -> dict[str, Any]:
    d: dict[str, Any] = {
        "spacing": list(volume.spacing),
        "origin": list(volume.origin),
        "direction": volume.direction.tolist(),
        "space": volume.space,
        "name": volume.name,
        "units": volume.units,
    }
    src = volume.source
    if src is not None and src.startswith("sample:"):
        d["sample"] = src.split(":", 1)[1]
        d["shape"] = list(volume.shape)
        return d
    if src is not None and os.path.exists(src):
        d["path"] = path_entry(src, base_dir)
        d["shape"] = list(volume.shape)  # a downsampled file is loaded downsampled again
        d.update(volume.frame_choice)  # the time point / channel of a 4-D file
        return d
    if volume.nbytes > EMBED_LIMIT_BYTES:
        raise SceneError(
            f"volume {volume.name!r} ({volume.nbytes / 2**20:.1f} MB) has no file and is too"
            f" large to embed in scene JSON (limit {EMBED_LIMIT_BYTES / 2**20:.0f} MB); save it"
            " first with app.save_volume(volume, 'vol.nrrd') and load it from there"
        )
    d["embedded"] = {
        "dtype": str(volume.dtype),
        "shape": list(volume.shape),
        "order": "F",
        "data": base64.b64encode(volume.data.tobytes(order="F")).decode("ascii"),
    }
    return d


def _with_stated_shape(volume: Volume, shape: Any, what: str, spacing: Any = None) -> Volume:
    """``volume`` reduced to the scene's ``shape`` when the scene was saved from a
    downsampled copy (``--downsample``: an integer factor per axis); a shape that no
    factor explains, or a factor while the scene states the file's own voxel size
    (``spacing``: a downsampled copy's voxels are larger), means the file changed since
    the scene was saved."""
    if shape is None:
        return volume
    try:
        want = np.asarray([int(v) for v in shape])
    except (TypeError, ValueError) as exc:
        raise SceneError(f"scene volume 'shape' must be three integers; got {shape!r}") from exc
    have = np.asarray(volume.shape)
    if want.shape != (3,) or np.any(want < 1):
        raise SceneError(f"scene volume 'shape' must be three positive integers; got {shape!r}")
    if np.array_equal(want, have):
        return volume
    factor = have // want
    stated = np.asarray(spacing if spacing is not None else [], dtype=float).reshape(-1)
    own_size = stated.shape == (3,) and bool(np.allclose(stated, volume.spacing))
    if np.any(factor < 1) or not np.array_equal(have // factor, want) or own_size:
        raise SceneError(
            f"{what} has {tuple(have.tolist())} voxels but the scene was saved with"
            f" {tuple(want.tolist())}; the file changed since: save the scene again"
        )
    return volume.downsample(tuple(int(f) for f in factor))


def _with_stated_geometry(volume: Volume, spacing: Any, origin: Any) -> Volume:
    """``volume`` with the scene's spacing/origin where they differ from the file's (a
    scene saved after ``--spacing``); the file's own geometry otherwise."""
    changes: dict[str, Any] = {}
    if spacing is not None and not np.allclose(np.asarray(spacing, float), volume.spacing):
        changes.update(spacing=spacing, spacing_source="given")
    if origin is not None and not np.allclose(np.asarray(origin, float), volume.origin):
        changes["origin"] = origin
    return volume.with_geometry(**changes) if changes else volume


def _warp_entry(warp: Warp, base_dir: str | os.PathLike | None) -> dict[str, Any]:
    """``warp.to_dict()`` with its file paths (:attr:`Warp.file_keys`) relative to the
    scene's folder."""
    d = warp.to_dict()
    for key in warp.file_keys:
        if isinstance(d.get(key), str):
            d[key] = path_entry(d[key], base_dir)
    return d


def _resolved_warp(d: Any, base_dir: str | os.PathLike | None) -> Any:
    """A scene's warp entry with its file paths resolved against the scene's folder
    (:func:`~voxwarp.core.scene_paths.scene_file`: the file must exist)."""
    keys = warp_class(d).file_keys
    if not any(k in d for k in keys):
        return d

    out = dict(d)
    for key in keys:
        if key in out:
            out[key] = str(scene_file(out[key], base_dir, f"{d['type']} warp", SceneError))
    return out


def _volume_from_dict(d: Any, base_dir: str | os.PathLike | None) -> Volume:
    if not isinstance(d, Mapping):
        raise SceneError("scene 'volume' must be an object with 'path', 'sample' or 'embedded'")
    spacing = d.get("spacing")
    origin = d.get("origin")
    try:
        if "embedded" in d:
            e = d["embedded"]
            if not isinstance(e, Mapping):
                raise SceneError("scene volume 'embedded' must be an object")
            try:
                dtype = np.dtype(str(e["dtype"]))
                shape = tuple(int(s) for s in e["shape"])
                raw = base64.b64decode(str(e["data"]), validate=True)
            except (KeyError, TypeError, ValueError) as exc:
                raise SceneError(f"scene volume 'embedded' is malformed: {exc}") from exc
            if dtype.kind not in "uif" or dtype.hasobject:
                raise SceneError(f"embedded volume dtype {dtype} is not a numeric type")
            if len(shape) != 3 or min(shape) < 1:
                raise SceneError(f"embedded volume shape must be 3 positive ints; got {shape}")
            need = dtype.itemsize * math.prod(shape)
            if len(raw) != need:
                raise SceneError(
                    f"embedded volume holds {len(raw)} bytes; shape {shape} of {dtype} needs {need}"
                )
            data = check_finite(
                np.frombuffer(raw, dtype=dtype).reshape(shape, order="F"),
                "raise",
                "embedded volume",
            )
            return Volume(
                data,
                spacing if spacing is not None else (1, 1, 1),
                origin if origin is not None else (0, 0, 0),
                name=str(d.get("name", "embedded")),
                units=str(d.get("units", "")),
                direction=d.get("direction"),
                space=str(d.get("space", "")),
            )
        if "sample" in d:
            name = str(d["sample"])
            kwargs: dict[str, Any] = {}
            if name in GENERATED_SAMPLES and d.get("shape") is not None:
                kwargs["shape"] = tuple(int(v) for v in d["shape"])
            if kwargs:
                return load_sample(name, spacing=spacing, origin=origin, **kwargs)
            vol = _with_stated_shape(load_sample(name), d.get("shape"), f"sample:{name}", spacing)
            return _with_stated_geometry(vol, spacing, origin)
        if "path" in d:
            p = scene_file(d["path"], base_dir, "volume", SceneError)
            pick = {k: d[k] for k in ("frame_index", "channel") if d.get(k) is not None}
            vol = _with_stated_shape(load_volume(p, **pick), d.get("shape"), str(p), spacing)
            return _with_stated_geometry(vol, spacing, origin)
    except SceneError:
        raise  # names the scene volume already
    except (VolumeError, TypeError, ValueError, OverflowError) as exc:
        raise SceneError(f"scene volume: {exc}") from exc
    raise SceneError("scene 'volume' needs one of 'path', 'sample' or 'embedded'")


def _comparison_kwargs(comparison: Comparison | None) -> dict[str, Any]:
    """``Scene`` arguments that rebuild ``comparison`` (none without one)."""
    if comparison is None:
        return {}
    return {"fixed": comparison.fixed, **_compare_args(comparison.settings_dict())}


def _compare_args(settings: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "compare": settings.get("show", "checkerboard"),
        "blend": settings.get("blend", 0.5),
        "checker_mm": settings.get("checker_mm"),
    }


def _comparison_from_dict(d: Mapping[str, Any], base_dir: Any) -> dict[str, Any]:
    """Scene JSON's ``fixed`` (a volume entry, resolved as the scene's volume is) and
    ``compare`` settings -> ``Scene`` arguments."""
    if d.get("fixed") is None:
        return {}
    settings = d.get("compare") or {}
    unknown = sorted(set(settings) - {"show", "blend", "checker_mm"})
    if unknown:
        raise SceneError(
            f"scene 'compare' holds only show, blend and checker_mm; drop {', '.join(unknown)}"
        )
    try:
        fixed = _volume_from_dict(d["fixed"], base_dir)
    except SceneError as exc:
        raise SceneError(f"scene 'fixed': {exc}") from exc
    return {"fixed": fixed, **_compare_args(settings)}


def as_fixed_volume(fixed: Any) -> Volume:
    """A fixed image given as a Volume, a path or ``"sample:NAME"`` -> the Volume."""
    if isinstance(fixed, Volume):
        return fixed
    if isinstance(fixed, str | os.PathLike):
        return load_volume(fixed)
    raise SceneError(
        f"fixed must be a Volume, a volume file path or 'sample:NAME'; got {type(fixed).__name__}"
    )
