"""GLSL sources of voxwarp, one feature per file, composed with ``#include "file.glsl"``.

This package holds shader files only; :func:`source` is the one loader (through
:mod:`importlib.resources`, so the files ship as package data). Each file is included
at most once per program (include guards are implicit).
"""

from __future__ import annotations

import re
from importlib import resources

_INCLUDE = re.compile(r'^[ \t]*#include[ \t]+"([^"]+)"[ \t]*$', re.MULTILINE)


def read(name: str) -> str:
    """Return the raw text of the shader file ``name`` (e.g. ``"raycast.frag.glsl"``)."""
    try:
        return resources.files(__name__).joinpath(name).read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"no shader file {name!r} in package {__name__!r}") from exc


def source(name: str, extra: dict[str, str] | None = None) -> str:
    """Return ``name`` with every ``#include "file"`` replaced by that file's text.

    ``extra`` maps virtual include names to generated text (e.g. the warp chain), which
    takes precedence over files. Each file is inserted once; a second include is dropped.
    """
    extra = extra or {}
    seen: set[str] = set()

    def expand(text: str, stack: tuple[str, ...]) -> str:
        def repl(match: re.Match[str]) -> str:
            inc = match.group(1)
            if inc in stack:
                raise ValueError(f"circular #include of {inc!r} via {' -> '.join(stack)}")
            if inc in seen:
                return f"// {inc} already included"
            seen.add(inc)
            body = extra[inc] if inc in extra else read(inc)
            return f"// begin {inc}\n{expand(body, (*stack, inc))}\n// end {inc}"

        return _INCLUDE.sub(repl, text)

    return expand(read(name), (name,))


def with_defines(text: str, defines: list[str]) -> str:
    """``text`` with the lines ``defines`` (e.g. ``"#define SHADING"``) put right after
    its first line, the ``#version`` directive, where GLSL requires them to follow it."""
    head, _, rest = text.partition("\n")
    return "\n".join([head, *defines, rest])
