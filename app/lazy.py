"""Lazy public names for package ``__init__`` modules (PEP 562 ``__getattr__``).

``voxwarp`` and ``voxwarp.deform`` name their public API in a table ``name -> module``;
:func:`exports` returns the ``__getattr__`` and ``__dir__`` that import a name's module
on first access, so importing the package loads nothing heavy.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def exports(
    package: str,
    table: Mapping[str, str],
    computed: Mapping[str, Callable[[], Any]] | None = None,
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: ``table`` maps public names to the
    modules that define them, ``computed`` names to functions giving their value; each
    value is cached in the package on first access."""
    computed = dict(computed or {})

    def __getattr__(name: str) -> Any:
        if name in computed:
            value = computed[name]()
        elif name in table:
            value = getattr(importlib.import_module(table[name]), name)
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *table, *computed})

    return __getattr__, __dir__
