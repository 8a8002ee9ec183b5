"""The adaptive quality of interactive frames (voxwarp.render.adaptive_quality), a pure
unit: given frame times, the chosen level moves as specified and stays within bounds."""

from __future__ import annotations

import itertools
import math

import pytest

from voxwarp.render.adaptive_quality import (
    FINER_HEADROOM,
    FULL,
    LEVELS,
    MAX_STEP_VOXELS,
    START_LEVEL,
    AdaptiveQuality,
    AdaptiveQualityError,
    Quality,
    scene_at,
)


def test_levels_run_from_full_quality_to_coarser_and_cheaper() -> None:
    assert LEVELS[0] == FULL
    assert FULL.cost == 1.0
    assert LEVELS[START_LEVEL] == Quality(0.5, 2.0)  # half resolution, twice the distance
    costs = [q.cost for q in LEVELS]
    assert all(b < a for a, b in itertools.pairwise(costs))
    assert all(0 < q.scale <= 1 and q.step_factor >= 1 for q in LEVELS)


def test_a_slow_frame_coarsens_one_level_at_a_time_down_to_the_last() -> None:
    aq = AdaptiveQuality(target_fps=15)
    seen = [aq.level]
    for _ in range(2 * len(LEVELS)):
        aq.frame_drawn(0.5)  # far over 1/15 s
        seen.append(aq.level)
    assert seen[: len(LEVELS) - START_LEVEL] == list(range(START_LEVEL, len(LEVELS)))
    assert seen[-1] == len(LEVELS) - 1
    assert aq.quality == LEVELS[-1]


def test_a_fast_frame_refines_while_the_prediction_fits_and_stops_at_min_level() -> None:
    aq = AdaptiveQuality(target_fps=15, min_level=1)
    for _ in range(2 * len(LEVELS)):
        aq.frame_drawn(0.001)
    assert aq.level == 1  # never finer than min_level
    aq = AdaptiveQuality(target_fps=15)
    for _ in range(2 * len(LEVELS)):
        aq.frame_drawn(0.0)
    assert aq.quality == FULL  # interactive frames may reach full quality when cheap


def test_a_frame_near_the_target_keeps_its_level() -> None:
    """Hysteresis: a frame just inside the budget stays, since the finer level (about
    twice the cost) would miss it; just over the budget coarsens."""
    target = 1 / 15
    aq = AdaptiveQuality(target_fps=15)
    here, finer = LEVELS[START_LEVEL], LEVELS[START_LEVEL - 1]
    aq.frame_drawn(0.9 * target)
    assert aq.level == START_LEVEL
    # the largest time that still refines: the finer level's predicted time at the headroom
    edge = FINER_HEADROOM * target * here.cost / finer.cost
    aq.frame_drawn(1.01 * edge)
    assert aq.level == START_LEVEL
    aq.frame_drawn(0.99 * edge)
    assert aq.level == START_LEVEL - 1
    aq.frame_drawn(1.01 * target)
    assert aq.level == START_LEVEL


def test_the_level_settles_where_a_cost_model_meets_the_target() -> None:
    """A frame whose time is proportional to the level's cost (full quality 400 ms)
    settles on the finest level under 1/15 s, and stays there."""
    aq = AdaptiveQuality(target_fps=15)
    levels = []
    for _ in range(30):
        aq.frame_drawn(0.4 * aq.quality.cost)
        levels.append(aq.level)
    fitting = [i for i, q in enumerate(LEVELS) if 0.4 * q.cost <= 1 / 15]
    assert levels[-10:] == [fitting[0]] * 10
    aq.reset()
    assert aq.level == START_LEVEL


@pytest.mark.parametrize(
    "kwargs",
    [
        {"target_fps": 0},
        {"target_fps": math.nan},
        {"levels": ()},
        {"levels": (Quality(1.5, 1.0),)},
        {"levels": (Quality(0.5, 0.5),)},
        {"start": len(LEVELS)},
        {"min_level": START_LEVEL + 1},
    ],
)
def test_bad_settings_are_one_line_errors(kwargs: dict) -> None:
    with pytest.raises(AdaptiveQualityError):
        AdaptiveQuality(**kwargs)


def test_a_bad_frame_time_is_an_error() -> None:
    aq = AdaptiveQuality()
    for bad in (-1.0, math.nan):
        with pytest.raises(AdaptiveQualityError, match="frame time"):
            aq.frame_drawn(bad)


def test_scene_at_scales_the_sample_distance_within_the_scene_bound() -> None:
    from voxwarp.io.samples import load_sample
    from voxwarp.scene import Scene

    scene = Scene(load_sample("fish", shape=(16, 8, 8)), step=1.5)
    assert scene_at(scene, Quality(0.5, 1.0)) is scene  # resolution only: the scene itself
    coarse = scene_at(scene, Quality(0.5, 2.0))
    assert coarse.step == 3.0
    assert coarse.sample_distance_mm == pytest.approx(2 * scene.sample_distance_mm)
    assert scene.step == 1.5  # a copy; the scene is untouched
    assert coarse.volume is scene.volume
    assert scene_at(scene.copy(step=80.0), Quality(0.5, 3.0)).step == MAX_STEP_VOXELS
