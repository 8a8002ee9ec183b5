"""Errors raised by voxwarp for bad input: one root, :class:`VoxwarpError`.

Every error names the problem and the fix in its message, so a user never has to
read a traceback from deep inside numpy or OpenGL. Every layer derives its errors from
:class:`VoxwarpError` (this module sits below all of them), so callers such as the GUI
catch ``VoxwarpError`` alone and a real bug still surfaces as a traceback.
"""

from __future__ import annotations


class VoxwarpError(Exception):
    """Base class of every error voxwarp raises on purpose."""

    def __str__(self) -> str:
        # one line, whatever a wrapped library's message holds (some span lines)
        return " ".join(super().__str__().split())


class VolumeError(VoxwarpError, ValueError):
    """A volume cannot be read or is not usable (format, dtype, NaN, size)."""


class VolumeTooLargeError(VolumeError):
    """A volume exceeds the GPU's 3D texture size or the memory budget."""


class SceneError(VoxwarpError, ValueError):
    """A scene description (Python arguments or scene JSON) is invalid."""


class MeshError(VoxwarpError, ValueError):
    """A mesh cannot be read or is not usable (format, empty, NaN, bad face indices)."""


class FieldError(VoxwarpError, ValueError):
    """A displacement field or transform file cannot be read or written as asked."""


class RenderError(VoxwarpError, RuntimeError):
    """The renderer could not draw (no GL context, shader failure, ...)."""


class InputError(VoxwarpError, ValueError):
    """A file named on the command line or opened in the GUI (wire file, lattice file,
    scene JSON) that does not fit; the message names the option or file and the fix."""


class MissingExtraError(VoxwarpError, ImportError):
    """A feature needs an optional dependency group (an *extra*) that is not installed."""


class OutputError(VoxwarpError, OSError):
    """A file could not be written (disk full, read-only, permission denied, ...).

    Raised by every writer (through :func:`voxwarp.core.files.atomic_output`) after it
    has removed its temporary file, so the destination keeps its previous content (or
    stays absent). The message is one line: ``cannot write PATH: CAUSE (strerror); FIX``.
    It is also an :class:`OSError` (``errno`` set when known), so code that caught the
    ``OSError`` of a failed write keeps working.
    """

    def __init__(self, message: str, *, path: str = "", errno: int | None = None) -> None:
        super().__init__(message)
        self.path = path
        self.errno = errno

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""
