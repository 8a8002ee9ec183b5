"""The fuzz suite's session summary: how many generated inputs each fuzz test ran and
how they ended (``ok``: accepted; ``error``: a one-line VoxwarpError)."""

from __future__ import annotations

from typing import Any

from tests.fuzz._support import CASES, OUTCOMES


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if not CASES:
        return
    tr = terminalreporter
    tr.section("fuzz cases (generated inputs)")
    for name in sorted(CASES):
        how = ", ".join(f"{k} {v}" for k, v in sorted(OUTCOMES.get(name, {}).items()))
        tr.write_line(f"{name}: {CASES[name]} ({how})")
    tr.write_line(f"total: {sum(CASES.values())} generated inputs")
