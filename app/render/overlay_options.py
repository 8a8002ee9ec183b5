"""The overlays drawn over slices and renders, named in one place.

:data:`OVERLAYS` is the tuple the command line's ``--overlay`` and the Python APIs
(``render_slice(overlay=...)``, ``Renderer.overlays``) accept; :func:`check_overlays`
turns a name, a comma list or a sequence of names into a tuple of known names.
"""

from __future__ import annotations

from collections.abc import Iterable

from voxwarp.errors import RenderError

#: overlay names: ``jacobian`` (det J colour map, :mod:`voxwarp.render.jacobian_overlay`),
#: ``grid`` and ``glyphs`` (:mod:`voxwarp.render.warp_overlays`, :mod:`voxwarp.render.warp_meshes`)
OVERLAYS: tuple[str, ...] = ("jacobian", "grid", "glyphs")


def check_overlays(names: str | Iterable[str] | None) -> tuple[str, ...]:
    """Known overlay names of ``names`` (``"a,b"``, ``["a", "b"]`` or None), in order,
    without repeats; :class:`RenderError` naming the allowed values for others."""
    if names is None:
        return ()
    items = [names] if isinstance(names, str) else list(names)
    out: list[str] = []
    for item in items:
        for name in str(item).split(","):
            name = name.strip().lower()
            if not name:
                continue
            if name not in OVERLAYS:
                raise RenderError(f"unknown overlay {name!r}; choose from {', '.join(OVERLAYS)}")
            if name not in out:
                out.append(name)
    return tuple(out)
