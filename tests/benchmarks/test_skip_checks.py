"""``python -m benchmarks.skip_checks`` on a tiny image: a row per scene with one time per
schedule, and bad schedules refused before anything is drawn."""

from __future__ import annotations

import pytest

from benchmarks.skip_checks import main, measure


def test_a_row_has_a_time_per_schedule_and_their_ratios() -> None:
    row = measure("fish", "dvr", False, [1, 2, 3], frames=1, size=48)
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[:3] == ["fish", "dvr", "off"]
    assert all(float(c) > 0 for c in cells[3:6])  # ms of 1, 2 and 3 samples per check
    assert cells[6].endswith("x")
    assert cells[7].endswith("x")
    assert len(cells) == 9  # and the load average


@pytest.mark.parametrize("bad", ["0,1", "1,5", ""])
def test_schedules_outside_one_to_four_are_refused(bad: str) -> None:
    with pytest.raises(SystemExit):
        main(["--per-check", bad])
