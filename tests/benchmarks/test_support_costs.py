"""Tests of the lab's study of what a warped ray pays for (benchmarks.support_costs).

Oracles: every variant's text edit still finds its text in the shaders it edits (a
variant that no longer applies would time the shipped program under another name),
and the ``seed`` variant is what ``OffsetFieldWarp(iterations=0)`` generates.
"""

from __future__ import annotations

import numpy as np

from benchmarks.support_costs import VARIANTS, _state, _with_defines
from voxwarp import shaders
from voxwarp.deform.elements.offset_field import OffsetFieldWarp
from voxwarp.deform.warp import compose_glsl

LO, HI = np.zeros(3), np.full(3, 30.0)


def _program(**kw: object) -> str:
    field = np.zeros((4, 4, 4, 3))
    warp = OffsetFieldWarp(LO, HI, field, inverse="baked", **kw)  # type: ignore[arg-type]
    extra = {"warps.glsl": compose_glsl([warp]), "mode.glsl": shaders.read("mode_dvr.glsl")}
    return shaders.source("raycast.frag.glsl", extra=extra)


def test_every_variant_edits_the_warped_program() -> None:
    src = _program()
    for name, edits in VARIANTS.items():
        for old, _ in edits:
            assert src.count(old) == 1, f"variant {name}: {old[:40]!r}"


def test_the_seed_variant_is_the_seed_alone() -> None:
    # the edit drops the one use of the corrections' macro, which iterations=0 empties
    edited = _program().replace(*VARIANTS["seed"][0])
    assert "\n    w0_ITERATE" in _program()
    assert "\n    w0_ITERATE" not in edited
    assert "#define w0_ITERATE \n" in _program(iterations=0)


def test_variants_leave_straight_programs_alone() -> None:
    src = _program()
    edit = _with_defines(lambda s, d: s)
    assert edit(src, ["#define LINEAR_PATH"]) == src
    assert edit(src, ["#define SUPPORT_MAP"]) == src  # "current": no edits
    gradient = shaders.read("gradient.comp.glsl")  # no warp chain: never edited
    _state["variant"] = "seed"
    try:
        assert edit(gradient, []) == gradient
        assert edit(src, []) != src
    finally:
        _state["variant"] = "current"
