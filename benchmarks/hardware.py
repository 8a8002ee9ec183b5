"""The machine a benchmark ran on: GL renderer, OpenCL device, CPU, memory, Python, OS.

:func:`probe_hardware` asks a standalone headless moderngl context (EGL) for its
renderer and version strings, pyopencl (when importable) for its platforms and devices,
and ``/proc`` for the CPU model and the memory. Every part that cannot be probed says why
instead of failing: the probe never raises.
"""

from __future__ import annotations

import os
import platform
import sys
from pathlib import Path
from typing import Any

from voxwarp.core.timing import cpu_count, cpu_model, load_average


def gl_info() -> dict[str, str]:
    """``GL_RENDERER``, ``GL_VERSION`` and ``GL_VENDOR`` of a new standalone EGL context
    (released again); ``{"error": ...}`` when none can be made."""
    from voxwarp.errors import RenderError
    from voxwarp.render.context import create_context

    try:
        ctx = create_context()
    except RenderError as exc:
        return {"error": str(exc).split(". ")[0]}
    try:
        info = ctx.info
        return {
            "renderer": str(info.get("GL_RENDERER", "?")),
            "version": str(info.get("GL_VERSION", "?")),
            "vendor": str(info.get("GL_VENDOR", "?")),
        }
    finally:
        ctx.release()


def opencl_devices() -> list[str] | str:
    """``"platform: device (N compute units)"`` per OpenCL device, or why there are none."""
    try:
        import pyopencl as cl
    except ImportError:
        return "pyopencl not installed"
    try:
        out = []
        for plat in cl.get_platforms():
            for dev in plat.get_devices():
                out.append(f"{plat.name}: {dev.name} ({dev.max_compute_units} compute units)")
        return out or "no OpenCL device"
    except Exception as exc:  # pyopencl raises its own LogicError/RuntimeError kinds
        return (
            f"no OpenCL platform ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
        )


def memory_gib() -> float:
    """Physical memory in GiB (``/proc/meminfo`` MemTotal; 0 where unknown)."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) / 2**20
    except (OSError, ValueError, IndexError):
        pass
    return 0.0


def probe_hardware() -> dict[str, Any]:
    """Everything above as one JSON-ready dict (keys: gl, opencl, cpu, cores, ram_gib,
    python, os, load)."""
    return {
        "gl": gl_info(),
        "opencl": opencl_devices(),
        "cpu": cpu_model(),
        "cores": cpu_count(),
        "cores_total": os.cpu_count() or 1,
        "ram_gib": round(memory_gib(), 1),
        "python": f"{platform.python_implementation()} {sys.version.split()[0]}",
        "os": platform.platform(),
        "load": load_average(),
    }


def hardware_lines(hw: dict[str, Any]) -> list[str]:
    """Human-readable ``label: value`` lines of a :func:`probe_hardware` dict."""
    gl = hw.get("gl", {})
    gl_text = gl.get("error") or f"{gl.get('renderer', '?')} (OpenGL {gl.get('version', '?')})"
    ocl = hw.get("opencl", "?")
    ocl_text = "; ".join(ocl) if isinstance(ocl, list) else str(ocl)
    return [
        f"GL: {gl_text}",
        f"OpenCL: {ocl_text}",
        f"CPU: {hw.get('cpu', '?')}, {hw.get('cores', '?')} cores usable"
        f" ({hw.get('cores_total', '?')} online)",
        f"RAM: {hw.get('ram_gib', 0):.1f} GiB",
        f"Python: {hw.get('python', '?')}",
        f"OS: {hw.get('os', '?')}",
        f"1-minute load average at start: {hw.get('load', -1):.2f}",
    ]
