"""Tests of the GLSL include loader (voxwarp.shaders.source / read).

The loader replaces ``#include "file"`` lines by the file's text, each file at most once
per program, refuses include cycles and names a missing file. Oracles: small virtual
shader sets (``read`` replaced by a dict lookup) whose expansion is written out by hand,
and every shipped shader file (expands, no ``#include`` left, every file once).
"""

from __future__ import annotations

import re
from importlib import resources

import pytest

from voxwarp import shaders


@pytest.fixture
def files(monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """A virtual shader folder: ``source`` reads from this dict instead of the package."""
    table: dict[str, str] = {}

    def read(name: str) -> str:
        if name not in table:
            raise FileNotFoundError(f"no shader file {name!r} in package 'virtual'")
        return table[name]

    monkeypatch.setattr(shaders, "read", read)
    return table


def test_include_is_replaced_by_the_file_text(files: dict[str, str]) -> None:
    files["main.glsl"] = 'void main() {}\n#include "a.glsl"\nint z;'
    files["a.glsl"] = "int a;"
    assert shaders.source("main.glsl") == (
        "void main() {}\n// begin a.glsl\nint a;\n// end a.glsl\nint z;"
    )


def test_a_file_included_twice_is_inserted_once(files: dict[str, str]) -> None:
    # diamond: main -> a -> common, main -> b -> common, and main -> common again
    files["main.glsl"] = '#include "a.glsl"\n#include "b.glsl"\n  #include "common.glsl"'
    files["a.glsl"] = '#include "common.glsl"\nint a;'
    files["b.glsl"] = '#include "common.glsl"\nint b;'
    files["common.glsl"] = "int common_value;"
    out = shaders.source("main.glsl")
    assert out.count("int common_value;") == 1
    assert out.count("// begin common.glsl") == 1
    assert out.count("// common.glsl already included") == 2
    # first use wins: common comes before a's own code, and a before b
    assert out.index("int common_value;") < out.index("int a;") < out.index("int b;")
    assert "#include" not in out


def test_include_inside_a_comment_line_or_with_trailing_code_is_left_alone(
    files: dict[str, str],
) -> None:
    files["main.glsl"] = '// #include "a.glsl"\n#include "a.glsl" // why\nint z;'
    files["a.glsl"] = "int a;"
    assert shaders.source("main.glsl") == files["main.glsl"]


@pytest.mark.parametrize(
    ("graph", "cycle"),
    [
        ({"main.glsl": '#include "main.glsl"'}, "main.glsl"),
        ({"main.glsl": '#include "a.glsl"', "a.glsl": '#include "main.glsl"'}, "main.glsl"),
        (
            {
                "main.glsl": '#include "a.glsl"',
                "a.glsl": '#include "b.glsl"',
                "b.glsl": '#include "c.glsl"',
                "c.glsl": '#include "a.glsl"',
            },
            "a.glsl",
        ),
    ],
    ids=["self", "two", "three-below-main"],
)
def test_include_cycles_are_refused_with_the_path(
    files: dict[str, str], graph: dict[str, str], cycle: str
) -> None:
    files.update(graph)
    with pytest.raises(ValueError, match=f"circular #include of '{re.escape(cycle)}' via main"):
        shaders.source("main.glsl")


def test_a_cycle_through_a_virtual_include_is_refused(files: dict[str, str]) -> None:
    files["main.glsl"] = '#include "warps.glsl"'
    with pytest.raises(ValueError, match=r"circular #include of 'warps\.glsl'"):
        shaders.source("main.glsl", extra={"warps.glsl": '#include "warps.glsl"'})


def test_virtual_includes_take_precedence_over_files(files: dict[str, str]) -> None:
    files["main.glsl"] = '#include "mode.glsl"'
    files["mode.glsl"] = "int from_file;"
    out = shaders.source("main.glsl", extra={"mode.glsl": "int generated;"})
    assert "int generated;" in out
    assert "from_file" not in out


def test_a_missing_include_names_the_file() -> None:
    # the real package: the error names the missing file and the package it looked in
    with pytest.raises(FileNotFoundError, match=r"no shader file 'no_such_file\.glsl'"):
        shaders.source(
            "raycast.frag.glsl",
            extra={"warps.glsl": "", "mode.glsl": '#include "no_such_file.glsl"'},
        )
    with pytest.raises(FileNotFoundError, match=r"voxwarp\.shaders"):
        shaders.read("no_such_file.glsl")


#: includes that programs generate at run time (passed as ``extra``), not files
GENERATED = {
    "chainmail_config.glsl",
    "massspring_config.glsl",
    "massspring_pass.glsl",
    "mode.glsl",
    "warps.glsl",
}


def shipped_files() -> list[str]:
    root = resources.files("voxwarp.shaders")
    return sorted(p.name for p in root.iterdir() if p.name.endswith(".glsl"))


def test_every_include_is_a_shipped_file_or_a_known_generated_one() -> None:
    named = {
        inc
        for name in shipped_files()
        for inc in re.findall(r'^[ \t]*#include[ \t]+"([^"]+)"', shaders.read(name), re.MULTILINE)
    }
    assert named - set(shipped_files()) == GENERATED


@pytest.mark.parametrize("name", shipped_files())
def test_every_shipped_shader_expands_with_each_file_once(name: str) -> None:
    """Generated includes are given empty."""
    extra = dict.fromkeys(GENERATED, "")
    out = shaders.source(name, extra=extra)
    assert not re.search(r'^[ \t]*#include[ \t]+"', out, re.MULTILINE)
    begins = re.findall(r"^// begin (\S+)$", out, re.MULTILINE)
    assert len(begins) == len(set(begins))
    for inc in begins:
        if inc not in extra:
            assert shaders.read(inc) in out


def test_with_defines_follow_the_version_line() -> None:
    text = shaders.with_defines("#version 430\nvoid main() {}\n", ["#define A", "#define B 2"])
    assert text == "#version 430\n#define A\n#define B 2\nvoid main() {}\n"
    assert shaders.with_defines("#version 430\nx\n", []) == "#version 430\nx\n"
