"""Find import cycles among voxwarp's own modules, as the package installs.

Every module of the installed package (laid out by pyproject's ``package-dir``, as
``scripts/lint_imports.py`` does) is parsed; each import of a voxwarp module counts, also
inside functions (those only defer the cycle to run time), but not under
``if TYPE_CHECKING:``. ``from voxwarp.x import y`` is module ``voxwarp.x.y`` when that is
a submodule, else ``voxwarp.x``; relative imports are resolved against the importing
module. The strongly connected components of more than one module are the cycles.

It also counts the imports of voxwarp modules that stay inside functions (the second
number printed). Usage: ``python scripts/import_cycles.py [--functions [PREFIX ...]]``:
``--functions`` lists those in-function imports (of modules under the PREFIXes, e.g.
``voxwarp.deform voxwarp.render``). Exit status 1 when there is a cycle.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from lint_imports import installed_files

PACKAGE = "voxwarp"


@dataclass(frozen=True)
class Import:
    """One import of a voxwarp module: who imports what, where, and whether in a function."""

    importer: str
    target: str
    line: int
    in_function: bool


def modules() -> dict[str, Path]:
    """Installed module name -> source file, for every module of the package."""
    root = Path("/installed")
    out = {}
    for src, dest in installed_files(root).items():
        parts = dest.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = src
    return out


def _is_type_checking(test: ast.expr) -> bool:
    if isinstance(test, ast.Name):
        return test.id == "TYPE_CHECKING"
    return isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"


def _walk(node: ast.AST, in_function: bool = False) -> Iterator[tuple[ast.AST, bool]]:
    """Import statements under ``node`` (skipping ``if TYPE_CHECKING:`` bodies), each with
    whether it sits inside a function."""
    for child in ast.iter_child_nodes(node):
        yield from _walk_one(child, in_function)


def _walk_one(node: ast.AST, in_function: bool) -> Iterator[tuple[ast.AST, bool]]:
    if isinstance(node, ast.Import | ast.ImportFrom):
        yield node, in_function
        return
    inner = in_function or isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
    if isinstance(node, ast.If) and _is_type_checking(node.test):
        for sub in node.orelse:
            yield from _walk_one(sub, inner)
        return
    yield from _walk(node, inner)


def _owning(name: str, known: set[str]) -> str | None:
    """``name`` or its longest prefix that is a known module."""
    parts = name.split(".")
    while parts:
        if ".".join(parts) in known:
            return ".".join(parts)
        parts.pop()
    return None


def _targets(node: ast.AST, module: str, is_package: bool, known: set[str]) -> list[str]:
    """The voxwarp modules one import statement loads."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
        found = [_owning(n, known) for n in names if n.split(".")[0] == PACKAGE]
        return [f for f in found if f]
    assert isinstance(node, ast.ImportFrom)
    if node.level:
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        source = ".".join([*base, node.module] if node.module else base)
    else:
        source = node.module or ""
    if source.split(".")[0] != PACKAGE:
        return []
    out = []
    for alias in node.names:
        sub = f"{source}.{alias.name}"
        target = sub if sub in known else _owning(source, known)
        if target:
            out.append(target)
    return out


def imports(mods: dict[str, Path]) -> list[Import]:
    """Every import of a voxwarp module by a voxwarp module (not under TYPE_CHECKING)."""
    known = set(mods)
    out = []
    for module, src in sorted(mods.items()):
        tree = ast.parse(src.read_text(encoding="utf-8"), filename=str(src))
        is_package = src.name == "__init__.py"
        for node, in_function in _walk(tree):
            for target in dict.fromkeys(_targets(node, module, is_package, known)):
                if target != module:
                    out.append(Import(module, target, node.lineno, in_function))  # type: ignore[attr-defined]
    return out


def cycles(edges: list[Import]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    graph: dict[str, set[str]] = {}
    for e in edges:
        graph.setdefault(e.importer, set()).add(e.target)
        graph.setdefault(e.target, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    top = stack.pop()
                    on_stack.discard(top)
                    component.append(top)
                    if top == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def in_function(edges: list[Import], prefixes: tuple[str, ...] = ()) -> list[Import]:
    """The in-function imports, of importers under any of ``prefixes`` (all without)."""
    return [
        e
        for e in edges
        if e.in_function
        and (
            not prefixes or any(e.importer == p or e.importer.startswith(p + ".") for p in prefixes)
        )
    ]


def main(argv: list[str]) -> int:
    mods = modules()
    edges = imports(mods)
    found = cycles(edges)
    for component in found:
        inside = {(e.importer, e.target, e.line) for e in edges if e.importer in component}
        links = sorted(f"{a}:{line} -> {b}" for a, b, line in inside if b in component)
        print(f"cycle: {' <-> '.join(component)}")
        for link in links:
            print(f"    {link}")
    print(f"{len(found)} import cycle(s) among {len(mods)} modules")
    if argv and argv[0] == "--functions":
        prefixes = tuple(argv[1:])
        listed = in_function(edges, prefixes)
        for e in listed:
            print(f"in function: {e.importer}:{e.line} -> {e.target}")
        print(f"{len(listed)} in-function import(s) of voxwarp modules under {prefixes or 'all'}")
    print(f"{len(in_function(edges))} in-function import(s) of voxwarp modules in all")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
