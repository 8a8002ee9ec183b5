"""No import cycles among voxwarp's own modules (scripts/import_cycles.py), counting imports
inside functions; the in-function imports that remain are counted in the message."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "import_cycles.py"


def _tool():
    spec = importlib.util.spec_from_file_location("import_cycles", SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("import_cycles", module)
    spec.loader.exec_module(module)
    return module


def test_no_import_cycles() -> None:
    tool = _tool()
    edges = tool.imports(tool.modules())
    found = tool.cycles(edges)
    remaining = len(tool.in_function(edges))
    assert found == [], (
        f"{len(found)} import cycle(s): {[' <-> '.join(c) for c in found]}"
        f" ({remaining} in-function imports of voxwarp modules remain);"
        " run python scripts/import_cycles.py for the links"
    )


def test_the_tool_sees_in_function_and_skips_type_checking(tmp_path: Path) -> None:
    tool = _tool()
    src = tmp_path / "mod.py"
    src.write_text(
        "from typing import TYPE_CHECKING\n"
        "from voxwarp.b import thing\n"
        "if TYPE_CHECKING:\n"
        "    from voxwarp.c import Other\n"
        "def f():\n"
        "    from voxwarp import b\n"
        "    from . import c\n",
        encoding="utf-8",
    )
    edges = tool.imports({"voxwarp.a": src, "voxwarp.b": src, "voxwarp.c": src, "voxwarp": src})
    got = {(e.importer, e.target, e.in_function) for e in edges if e.importer == "voxwarp.a"}
    assert got == {
        ("voxwarp.a", "voxwarp.b", False),
        ("voxwarp.a", "voxwarp.b", True),
        ("voxwarp.a", "voxwarp.c", True),
    }
    a_b = tool.Import("voxwarp.a", "voxwarp.b", 1, False)
    b_a = tool.Import("voxwarp.b", "voxwarp.a", 1, True)
    assert tool.cycles([a_b, b_a]) == [["voxwarp.a", "voxwarp.b"]]
