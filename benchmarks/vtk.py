"""VTK half of ``python -m benchmarks render``: time VTK's volume raycasters on the same input.

The benchmark renders one array with voxwarp and with VTK, using the same transfer
function, sample distance, image size and camera. This module is the VTK side. VTK
is an optional extra (``pip install voxwarp[bench]``), so it is imported only when a
function here is called; use :func:`vtk_available` to check first.

Two VTK mappers are supported:

* ``"fixed_point"``: ``vtkFixedPointVolumeRayCastMapper``. It casts rays on the CPU
  with VTK's thread pool and then draws the result as one textured quad.
* ``"gpu"``: ``vtkGPUVolumeRayCastMapper``, which the OpenGL2 factory makes into
  ``vtkOpenGLGPUVolumeRayCastMapper``. It casts rays in a fragment shader, so it runs
  on whatever OpenGL implementation the window got (llvmpipe included).

Rendering is always offscreen. On Linux without ``DISPLAY`` the window is a
``vtkEGLRenderWindow`` when libEGL is present; otherwise (or if the environment
variable ``VTK_DEFAULT_OPENGL_WINDOW`` is set) VTK's own factory picks the window
class, falling back from X to EGL to OSMesa by itself.
"""

from __future__ import annotations

import ctypes.util
import dataclasses
import importlib
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from benchmarks import child_env

Vec3 = tuple[float, float, float]
TfPoint = tuple[float, float, float, float, float]

_PROBE_RGB = (0.2, 0.4, 0.6)
"""Background of the probe frame that checks the window really draws and reads back."""


def vtk_available() -> bool:
    """Return True if the ``vtk`` package with its volume rendering modules can be imported."""
    try:
        _import_vtk_rendering()
    except ImportError:
        return False
    return True


def _import_vtk_rendering() -> None:
    """Import VTK's volume rendering modules.

    Importing the OpenGL2 modules registers VTK's factory overrides: the OpenGL render
    window, ``vtkOpenGLGPUVolumeRayCastMapper`` and the fixed-point mapper's display
    helper. Without them the mappers cannot draw.
    """
    for name in (
        "vtkmodules.vtkRenderingOpenGL2",
        "vtkmodules.vtkRenderingVolume",
        "vtkmodules.vtkRenderingVolumeOpenGL2",
    ):
        importlib.import_module(name)


@dataclass
class CameraSpec:
    """A camera in world millimetres, in VTK's terms.

    ``view_angle_deg`` is the full vertical field of view of a perspective camera;
    ``parallel_scale`` is half the height of the view in world units for an
    orthographic one (``parallel=True``). ``near`` and ``far`` are the clipping
    distances from ``position`` along the view direction.
    """

    position: Vec3
    focal_point: Vec3
    view_up: Vec3
    view_angle_deg: float
    parallel: bool
    parallel_scale: float
    near: float
    far: float


def camera_spec(cam: Any) -> CameraSpec:
    """A voxwarp perspective :class:`~voxwarp.core.camera.Camera` in VTK's terms (its
    near and far planes included), so both raycasters see the same view."""
    near, far = cam.near_far()
    return CameraSpec(
        position=tuple(cam.eye),
        focal_point=tuple(cam.center),
        view_up=tuple(cam.rotation[:, 1]),
        view_angle_deg=cam.fov,
        parallel=False,
        parallel_scale=cam.ortho_height / 2,
        near=near,
        far=far,
    )


@dataclass
class VtkResult:
    """Timings and final image of one :func:`render_vtk` run.

    ``image`` is ``(H, W, 3)`` (or ``(H, W, 4)`` with ``rgba=True``) ``uint8`` with
    row 0 at the top. ``renderer_string`` is ``GL_RENDERER`` of the window's context
    (empty if VTK did not report it); ``window_class`` is the VTK render window
    class that was used. ``extra`` holds ``threads`` (the fixed-point mapper's
    thread count, 0 for the GPU mapper) and ``scalar_type`` (VTK's name for the
    volume's scalar type).
    """

    median_ms: float
    min_ms: float
    times_ms: list[float]
    image: np.ndarray
    mapper_name: str
    renderer_string: str
    window_class: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def render_vtk(
    data_xyz: np.ndarray,
    spacing: Vec3 | tuple[float, ...],
    origin: Vec3 | tuple[float, ...],
    tf_points: list[TfPoint],
    *,
    mapper: Literal["fixed_point", "gpu"],
    mode: Literal["dvr", "mip"],
    sample_distance_mm: float,
    opacity_unit_distance_mm: float,
    size: tuple[int, int],
    camera: CameraSpec,
    frames: int = 10,
    warmup: int = 2,
    background: Vec3 | tuple[float, ...] = (0.0, 0.0, 0.0),
    rgba: bool = False,
    shading: tuple[float, float, float, float] | None = None,
) -> VtkResult:
    """Render ``data_xyz`` with a VTK volume mapper offscreen and time ``frames`` renders.

    Args:
        data_xyz: scalar volume indexed ``data[i, j, k]`` with ``i`` along x, shape
            ``(nx, ny, nz)``. Voxel ``(i, j, k)`` is centred at
            ``origin + spacing * (i, j, k)``.
        spacing: voxel size in mm along x, y, z.
        origin: world position (mm) of the centre of voxel ``(0, 0, 0)``.
        tf_points: transfer function control points ``(value, r, g, b, a)``; ``value``
            is in data units, colour and alpha in ``[0, 1]``. Alpha is the opacity
            accumulated over ``opacity_unit_distance_mm``. Linear in between, clamped
            to the end points outside.
        mapper: ``"fixed_point"`` (CPU raycaster) or ``"gpu"`` (OpenGL raycaster).
        mode: ``"dvr"`` (front-to-back compositing) or ``"mip"`` (maximum intensity).
        sample_distance_mm: distance between samples along a ray, in mm.
        opacity_unit_distance_mm: distance over which a TF alpha applies.
        size: image ``(width, height)`` in pixels.
        camera: the camera; see :class:`CameraSpec`.
        frames: number of timed frames (at least 1).
        warmup: untimed frames rendered first (shader compile, texture upload).
        background: background RGB in ``[0, 1]``.
        rgba: return an ``(H, W, 4)`` image whose alpha is the volume's coverage
            instead of ``(H, W, 3)``.
        shading: ``(ambient, diffuse, specular, specular power)`` to shade as voxwarp
            does (gradient-lit), or None for no shading.

    Each timed frame is ``Render()`` followed by ``WaitForCompletion()`` (a
    ``glFinish``), so GPU work is included; the image is read back once, after the
    last frame, and is not part of the timings.

    Raises:
        ImportError: VTK is not installed.
        ValueError: an argument is malformed.
        RuntimeError: VTK cannot render here (no usable OpenGL context, GPU mapper
            unsupported, or VTK reported an error while rendering). Callers should
            report this as a skipped measurement.
    """
    if not vtk_available():
        raise ImportError("VTK is not installed; install it with `pip install voxwarp[bench]`")
    volume_arr = _check_volume(data_xyz)
    spacing3 = _vec3(spacing, "spacing")
    origin3 = _vec3(origin, "origin")
    if min(spacing3) <= 0:
        raise ValueError(f"spacing must be positive, got {spacing3}")
    _check_tf(tf_points)
    if mapper not in ("fixed_point", "gpu"):
        raise ValueError(f"mapper must be 'fixed_point' or 'gpu', got {mapper!r}")
    if mode not in ("dvr", "mip"):
        raise ValueError(f"mode must be 'dvr' or 'mip', got {mode!r}")
    if not sample_distance_mm > 0 or not opacity_unit_distance_mm > 0:
        raise ValueError(
            "sample_distance_mm and opacity_unit_distance_mm must be positive, got "
            f"{sample_distance_mm} and {opacity_unit_distance_mm}"
        )
    width, height = (int(s) for s in size)
    if width < 1 or height < 1:
        raise ValueError(f"size must be (width, height) >= 1, got {size}")
    if frames < 1 or warmup < 0:
        raise ValueError(f"need frames >= 1 and warmup >= 0, got {frames} and {warmup}")
    _check_camera(camera)
    bg = _vec3(background, "background")
    options = {
        "spacing": list(spacing3),
        "origin": list(origin3),
        "tf_points": [[float(v) for v in p] for p in tf_points],
        "mapper": mapper,
        "mode": mode,
        "sample_distance_mm": float(sample_distance_mm),
        "opacity_unit_distance_mm": float(opacity_unit_distance_mm),
        "size": [width, height],
        "camera": dataclasses.asdict(camera),
        "frames": int(frames),
        "warmup": int(warmup),
        "background": list(bg),
        "rgba": bool(rgba),
        "shading": None if shading is None else [float(v) for v in shading],
    }
    return _render_in_child(volume_arr, options)


def _render_in_child(volume_arr: np.ndarray, options: dict[str, Any]) -> VtkResult:
    """Run :func:`_render_here` in a child Python process and return its result.

    VTK's EGL render window terminates the EGL display when it is finalized, which
    destroys every other EGL context of the process on that display (a voxwarp
    renderer's, a test session's); in its own process it harms nobody. Inputs and
    outputs travel as ``.npy`` + JSON files in a temporary folder (no pickle)."""
    import json
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="voxwarp-vtk-") as tmp:
        folder = Path(tmp)
        np.save(folder / "volume.npy", volume_arr, allow_pickle=False)
        (folder / "options.json").write_text(json.dumps(options), encoding="utf-8")
        proc = subprocess.run(
            [sys.executable, "-m", "benchmarks.vtk", str(folder)],
            env=child_env(),
            capture_output=True,
            text=True,
            check=False,
        )
        result_file = folder / "result.json"
        if not result_file.is_file():
            tail = (proc.stderr or proc.stdout or "").strip().splitlines()[-1:] or ["no output"]
            raise RuntimeError(f"the VTK child process failed (exit {proc.returncode}): {tail[0]}")
        result = json.loads(result_file.read_text(encoding="utf-8"))
        if "error" in result:
            kind = {"ValueError": ValueError, "ImportError": ImportError}.get(
                result["error"], RuntimeError
            )
            raise kind(result["message"])
        image = np.load(folder / "image.npy", allow_pickle=False)
    return VtkResult(image=image, **result)


def _child_main(folder: str) -> int:
    """The child side of :func:`_render_in_child`: render, write the result files."""
    import json

    where = Path(folder)
    options = json.loads((where / "options.json").read_text(encoding="utf-8"))
    volume_arr = np.load(where / "volume.npy", allow_pickle=False)
    options["camera"] = CameraSpec(**options["camera"])
    try:
        res = _render_here(volume_arr, **options)
    except (ValueError, RuntimeError, ImportError) as exc:
        out = {"error": type(exc).__name__, "message": str(exc)}
    else:
        np.save(where / "image.npy", res.image, allow_pickle=False)
        out = {k: v for k, v in dataclasses.asdict(res).items() if k != "image"}
    (where / "result.json").write_text(json.dumps(out), encoding="utf-8")
    return 0


def _render_here(
    volume_arr: np.ndarray,
    *,
    spacing: list[float],
    origin: list[float],
    tf_points: list[list[float]],
    mapper: str,
    mode: str,
    sample_distance_mm: float,
    opacity_unit_distance_mm: float,
    size: list[int],
    camera: CameraSpec,
    frames: int,
    warmup: int,
    background: list[float],
    rgba: bool,
    shading: list[float] | None,
) -> VtkResult:
    """:func:`render_vtk` in this process (its arguments checked)."""
    spacing3, origin3, bg = tuple(spacing), tuple(origin), tuple(background)
    width, height = size
    _import_vtk_rendering()
    from vtkmodules.vtkCommonCore import vtkOutputWindow, vtkStringOutputWindow
    from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
    from vtkmodules.vtkRenderingCore import (
        vtkColorTransferFunction,
        vtkRenderer,
        vtkVolume,
        vtkVolumeProperty,
    )
    from vtkmodules.vtkRenderingVolume import (
        vtkFixedPointVolumeRayCastMapper,
        vtkGPUVolumeRayCastMapper,
    )

    previous_output = vtkOutputWindow.GetInstance()
    log = vtkStringOutputWindow()
    vtkOutputWindow.SetInstance(log)
    ren_win = None
    try:
        image_data = _make_image_data(volume_arr, spacing3, origin3)

        color = vtkColorTransferFunction()
        opacity = vtkPiecewiseFunction()
        for value, r, g, b, a in sorted(tf_points, key=lambda p: p[0]):
            color.AddRGBPoint(float(value), float(r), float(g), float(b))
            opacity.AddPoint(float(value), float(a))
        color.ClampingOn()
        opacity.ClampingOn()

        prop = vtkVolumeProperty()
        prop.SetColor(color)
        prop.SetScalarOpacity(opacity)
        prop.SetScalarOpacityUnitDistance(float(opacity_unit_distance_mm))
        prop.SetInterpolationTypeToLinear()
        if shading is None:
            prop.ShadeOff()
        else:
            prop.ShadeOn()
            prop.SetAmbient(shading[0])
            prop.SetDiffuse(shading[1])
            prop.SetSpecular(shading[2])
            prop.SetSpecularPower(shading[3])
        prop.DisableGradientOpacityOn()
        prop.SetIndependentComponents(True)

        if mapper == "fixed_point":
            vmapper = vtkFixedPointVolumeRayCastMapper()
            vmapper.SetInteractiveSampleDistance(float(sample_distance_mm))
            vmapper.SetMinimumImageSampleDistance(1.0)
            vmapper.SetMaximumImageSampleDistance(1.0)
        else:
            vmapper = vtkGPUVolumeRayCastMapper()
        vmapper.SetInputData(image_data)
        vmapper.AutoAdjustSampleDistancesOff()
        vmapper.LockSampleDistanceToInputSpacingOff()
        vmapper.SetSampleDistance(float(sample_distance_mm))
        vmapper.SetImageSampleDistance(1.0)
        if mode == "mip":
            vmapper.SetBlendModeToMaximumIntensity()
        else:
            vmapper.SetBlendModeToComposite()

        volume = vtkVolume()
        volume.SetMapper(vmapper)
        volume.SetProperty(prop)

        ren_win = _make_render_window(width, height, rgba=rgba)
        renderer = vtkRenderer()
        ren_win.AddRenderer(renderer)
        _probe_window(ren_win, renderer, width, height)
        renderer_string = _gl_renderer_string(ren_win)

        if mapper == "gpu" and not vmapper.IsRenderSupported(ren_win, prop):
            raise RuntimeError(
                "VTK's GPU volume mapper is not supported by this OpenGL context "
                f"({renderer_string or 'unknown renderer'})"
            )

        renderer.SetBackground(*bg)
        renderer.SetBackgroundAlpha(0.0 if rgba else 1.0)
        renderer.AddVolume(volume)
        vcam = renderer.GetActiveCamera()
        _apply_camera(vcam, camera)
        log_start = len(log.GetOutput() or "")

        # glFinish; Render() of the fixed-point mapper is synchronous anyway.
        finish = getattr(ren_win, "WaitForCompletion", None) or (lambda: None)
        times_ms: list[float] = []
        for n in range(warmup + frames):
            vcam.Modified()
            t0 = time.perf_counter()
            ren_win.Render()
            finish()
            dt = (time.perf_counter() - t0) * 1000.0
            if n == 0:
                _raise_on_vtk_error(log, log_start, mapper)
            if n >= warmup:
                times_ms.append(dt)
        _raise_on_vtk_error(log, log_start, mapper)

        image = _read_back(ren_win, rgba=rgba)
        if image.shape[:2] != (height, width):
            raise RuntimeError(
                f"VTK returned a {image.shape[1]}x{image.shape[0]} image for a "
                f"{width}x{height} window"
            )
        return VtkResult(
            median_ms=float(statistics.median(times_ms)),
            min_ms=float(min(times_ms)),
            times_ms=times_ms,
            image=image,
            mapper_name=vmapper.GetClassName(),
            renderer_string=renderer_string,
            window_class=ren_win.GetClassName(),
            extra={
                "threads": int(vmapper.GetNumberOfThreads()) if mapper == "fixed_point" else 0,
                "scalar_type": image_data.GetScalarTypeAsString(),
            },
        )
    finally:
        if ren_win is not None:
            ren_win.Finalize()
        vtkOutputWindow.SetInstance(previous_output)


# --------------------------------------------------------------------------- helpers


def _vec3(v: Any, name: str) -> Vec3:
    """Return ``v`` as a tuple of three finite floats or raise ValueError."""
    try:
        t = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be three numbers, got {v!r}") from None
    if len(t) != 3 or not all(np.isfinite(t)):
        raise ValueError(f"{name} must be three finite numbers, got {v!r}")
    return (t[0], t[1], t[2])


def _check_volume(data: np.ndarray) -> np.ndarray:
    """Validate the volume and return it in a dtype VTK accepts (bool becomes uint8)."""
    arr = np.asarray(data)
    if arr.ndim != 3 or min(arr.shape) < 2:
        raise ValueError(f"data_xyz must be 3D with every side >= 2, got shape {arr.shape}")
    if arr.dtype == np.bool_:
        arr = arr.astype(np.uint8)
    if arr.dtype.kind not in "uif" or arr.dtype.itemsize > 8:
        raise ValueError(f"data_xyz must be an integer or float array, got dtype {arr.dtype}")
    return arr


def _check_tf(tf_points: list[TfPoint]) -> None:
    """Raise ValueError unless ``tf_points`` is a non-empty list of 5-tuples in range."""
    if len(tf_points) == 0:
        raise ValueError("tf_points must hold at least one (value, r, g, b, a) point")
    for p in tf_points:
        if len(p) != 5 or not all(np.isfinite(p)):
            raise ValueError(f"transfer function point {p!r} is not (value, r, g, b, a)")
        if not all(0.0 <= float(c) <= 1.0 for c in p[1:]):
            raise ValueError(f"transfer function point {p!r}: r, g, b, a must be in [0, 1]")


def _check_camera(cam: CameraSpec) -> None:
    """Raise ValueError for a camera VTK cannot use."""
    pos = np.array(_vec3(cam.position, "camera.position"))
    foc = np.array(_vec3(cam.focal_point, "camera.focal_point"))
    up = np.array(_vec3(cam.view_up, "camera.view_up"))
    d = foc - pos
    if np.linalg.norm(d) == 0:
        raise ValueError("camera.position and camera.focal_point coincide")
    if np.linalg.norm(np.cross(d, up)) <= 1e-9 * np.linalg.norm(d) * max(np.linalg.norm(up), 1):
        raise ValueError("camera.view_up is zero or parallel to the view direction")
    if not 0 < cam.near < cam.far:
        raise ValueError(f"need 0 < camera.near < camera.far, got {cam.near}, {cam.far}")
    if cam.parallel:
        if not cam.parallel_scale > 0:
            raise ValueError(f"camera.parallel_scale must be > 0, got {cam.parallel_scale}")
    elif not 0 < cam.view_angle_deg < 180:
        raise ValueError(f"camera.view_angle_deg must be in (0, 180), got {cam.view_angle_deg}")


def _make_image_data(arr: np.ndarray, spacing: Vec3, origin: Vec3) -> Any:
    """Build a ``vtkImageData`` whose point ``(i, j, k)`` holds ``arr[i, j, k]``."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkCommonDataModel import vtkImageData

    nx, ny, nz = arr.shape
    flat = np.ascontiguousarray(arr.ravel(order="F"))  # VTK wants x fastest
    scalars = numpy_support.numpy_to_vtk(flat, deep=True)
    scalars.SetName("scalars")
    img = vtkImageData()
    img.SetDimensions(nx, ny, nz)
    img.SetSpacing(*spacing)
    img.SetOrigin(*origin)
    img.GetPointData().SetScalars(scalars)
    return img


def _make_render_window(width: int, height: int, *, rgba: bool) -> Any:
    """Create an offscreen render window, preferring EGL on Linux without a display."""
    import vtkmodules.vtkRenderingOpenGL2 as gl2
    from vtkmodules.vtkRenderingCore import vtkRenderWindow

    headless_linux = sys.platform.startswith("linux") and not os.environ.get("DISPLAY")
    if (
        headless_linux
        and not os.environ.get("VTK_DEFAULT_OPENGL_WINDOW")
        and hasattr(gl2, "vtkEGLRenderWindow")
        and ctypes.util.find_library("EGL") is not None
    ):
        # Skips the factory's X attempt (and its "bad X server connection" warning).
        ren_win = gl2.vtkEGLRenderWindow()
    else:
        ren_win = vtkRenderWindow()
    ren_win.SetOffScreenRendering(1)
    ren_win.SetMultiSamples(0)
    ren_win.SetAlphaBitPlanes(1 if rgba else 0)
    ren_win.SetSize(width, height)
    return ren_win


def _probe_window(ren_win: Any, renderer: Any, width: int, height: int) -> None:
    """Render an empty frame in a known colour and read it back; raise if that fails."""
    if not ren_win.SupportsOpenGL():
        raise RuntimeError(
            f"VTK could not create an OpenGL context with {ren_win.GetClassName()} "
            "(set VTK_DEFAULT_OPENGL_WINDOW to vtkEGLRenderWindow or vtkOSOpenGLRenderWindow "
            "to choose another backend)"
        )
    renderer.SetBackground(*_PROBE_RGB)
    ren_win.Render()
    ren_win.WaitForCompletion()
    img = _read_back(ren_win, rgba=False)
    want = np.round(np.array(_PROBE_RGB) * 255)
    if img.shape[:2] != (height, width) or np.abs(img[height // 2, width // 2] - want).max() > 2:
        raise RuntimeError(
            f"VTK's {ren_win.GetClassName()} does not render offscreen here "
            "(probe frame did not read back its background colour)"
        )


def _gl_renderer_string(ren_win: Any) -> str:
    """Return ``GL_RENDERER`` as reported by VTK, or ``""``."""
    try:
        caps = ren_win.ReportCapabilities() or ""
    except Exception:
        return ""
    for line in caps.splitlines():
        if "renderer string" in line.lower():
            return line.split(":", 1)[1].strip()
    return ""


def _apply_camera(vcam: Any, cam: CameraSpec) -> None:
    """Copy a :class:`CameraSpec` onto a ``vtkCamera``."""
    vcam.SetPosition(*_vec3(cam.position, "camera.position"))
    vcam.SetFocalPoint(*_vec3(cam.focal_point, "camera.focal_point"))
    vcam.SetViewUp(*_vec3(cam.view_up, "camera.view_up"))
    vcam.OrthogonalizeViewUp()
    vcam.SetUseHorizontalViewAngle(False)
    vcam.SetViewAngle(float(cam.view_angle_deg))
    vcam.SetParallelProjection(bool(cam.parallel))
    vcam.SetParallelScale(float(cam.parallel_scale))
    vcam.SetClippingRange(float(cam.near), float(cam.far))


def _read_back(ren_win: Any, *, rgba: bool) -> np.ndarray:
    """Read the last rendered frame (no re-render) as ``(H, W, C)`` uint8, row 0 on top."""
    from vtkmodules.util import numpy_support
    from vtkmodules.vtkRenderingCore import vtkWindowToImageFilter

    w2i = vtkWindowToImageFilter()
    w2i.SetInput(ren_win)
    w2i.ShouldRerenderOff()
    w2i.ReadFrontBufferOff()
    if rgba:
        w2i.SetInputBufferTypeToRGBA()
    else:
        w2i.SetInputBufferTypeToRGB()
    w2i.Update()
    out = w2i.GetOutput()
    nx, ny, _ = out.GetDimensions()
    scalars = out.GetPointData().GetScalars()
    if scalars is None:
        raise RuntimeError("VTK returned no pixels from the render window")
    pix = numpy_support.vtk_to_numpy(scalars)
    channels = 1 if pix.ndim == 1 else pix.shape[1]
    pix = pix.reshape(ny, nx, channels)
    return np.ascontiguousarray(pix[::-1]).astype(np.uint8, copy=False)


def _raise_on_vtk_error(log: Any, start: int, mapper: str) -> None:
    """Raise RuntimeError if VTK logged an error after character ``start`` of ``log``."""
    text = (log.GetOutput() or "")[start:]
    if "ERROR" in text:
        raise RuntimeError(f"VTK {mapper} mapper failed to render: {text.strip()[:2000]}")


if __name__ == "__main__":
    sys.exit(_child_main(sys.argv[1]))
