"""The teaching demos (voxwarp.teaching.demos) and ``voxwarp demo NAME``.

Every demo runs once, quick and headless (its own EGL context), into a module-wide
folder; the tests then check the sheet it wrote, the numbers it returns (against the
physics and the algorithms they illustrate) and its tour file. The demos request
``gl_ctx`` only so that they skip, like every GL test, where EGL is missing.
"""

from __future__ import annotations

import itertools
import json
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from voxwarp.cli.main import main
from voxwarp.io.images import read_image
from voxwarp.teaching.chainmail_demo import gibson_sponsor
from voxwarp.teaching.demos import DEMOS, DemoError, DemoResult, run_demo
from voxwarp.teaching.tour import TOUR_FORMAT


@pytest.fixture(autouse=True)
def _keep_warning_state(monkeypatch: pytest.MonkeyPatch) -> None:
    """main() replaces warnings.formatwarning for good; undo it after each test."""
    monkeypatch.setattr(warnings, "formatwarning", warnings.formatwarning)


@pytest.fixture(scope="module")
def demos(gl_ctx: Any, tmp_path_factory: pytest.TempPathFactory) -> dict[str, DemoResult]:
    """Every demo, quick, with its tour, into one folder."""
    out = tmp_path_factory.mktemp("demos")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        results = {name: run_demo(name, out, quick=True, tour=True) for name in DEMOS}
    # matplotlib's layout gave up on a sheet (a panel's decorations outgrew it)
    assert not [w for w in caught if "constrained_layout" in str(w.message)]
    return results


# ---------------------------------------------------------------------- every demo
@pytest.mark.parametrize("name", DEMOS)
@pytest.mark.slow
def test_every_demo_writes_a_figure_sheet(demos: dict[str, DemoResult], name: str) -> None:
    res = demos[name]
    assert res.name == name
    assert res.figure == res.figures[0]
    assert res.figure.name == f"{name}.png"
    img = read_image(res.figure)
    h, w = img.shape[:2]
    assert w >= 900, img.shape  # a multi-panel sheet, not a thumbnail
    assert h >= 600, img.shape
    rgb = img[..., :3].astype(np.float64)
    # not blank: plots (white), renders (dark) and colours all present
    assert rgb.std() > 30
    assert np.mean(rgb.min(axis=-1) > 240) > 0.2  # white figure background
    assert np.mean(rgb.max(axis=-1) < 20) > 0.02  # the renders' black background
    colours = np.unique(img[..., :3].reshape(-1, 3), axis=0)
    assert len(colours) > 64
    assert res.figure.stat().st_size < 300_000
    # nothing half-written left behind
    assert not [p for p in res.figure.parent.iterdir() if p.name.startswith(".")]
    # numbers are JSON-ready (no numpy types, no NaN or infinity)
    json.dumps(res.numbers, allow_nan=False)
    assert res.numbers["quick"] is True
    assert res.numbers["gl_renderer"]
    assert res.seconds > 0


def test_an_unknown_demo_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(DemoError, match="massspring, chainmail, wires, lattice, compare"):
        run_demo("springs", tmp_path)
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------------- mass-spring
def test_massspring_explicit_euler_gains_energy_where_semi_implicit_loses_it(
    demos: dict[str, DemoResult],
) -> None:
    n = demos["massspring"].numbers
    e0 = n["initial_energy"]
    assert e0 > 0
    # the demo's dt is beyond explicit Euler's guaranteed-stable step, within twice the
    # semi-implicit one's
    assert n["dt_s"] > 10 * n["stable_dt_s"]["explicit"]
    assert n["dt_s"] < 2 * n["stable_dt_s"]["semi-implicit"]
    explicit, semi = n["energy"]["explicit"], n["energy"]["semi-implicit"]
    assert len(semi) == n["steps"] == len(n["time_s"])
    # semi-implicit Euler never gains energy and ends far below the start (damping)...
    assert max(semi) <= e0 * (1 + 1e-9)
    assert semi[-1] < 0.5 * e0
    assert all(b <= a * (1 + 1e-9) for a, b in itertools.pairwise(semi))
    # ...explicit Euler at the same dt gains it many times over
    assert n["max_energy"]["explicit"] > 10 * e0
    assert explicit[-1] is None or explicit[-1] > 100 * semi[-1]
    # the displacement clamp bounds it below the unclamped run, but it never settles
    assert e0 < n["final_energy"]["explicit + clamp"] < n["max_energy"]["explicit"]
    # the sweep: both stable at the smallest step, both blown up at the largest, and
    # explicit Euler blows up first
    sw = n["sweep"]
    assert len(sw["dt_s"]) == len(sw["growth"]["explicit"]) == len(sw["growth"]["semi-implicit"])
    assert sw["growth"]["explicit"][0] < 1.01
    assert sw["growth"]["semi-implicit"][0] <= 1.0
    assert sw["growth"]["explicit"][-1] > 1e3
    first_bad = {k: next(i for i, g in enumerate(v) if g > 1e3) for k, v in sw["growth"].items()}
    assert first_bad["explicit"] <= first_bad["semi-implicit"]
    # the settled bend holds the dragged elements at the drag
    assert n["max_displacement_mm"] == pytest.approx(math.hypot(*n["drag_mm"]), rel=0.05)


# ---------------------------------------------------------------------- ChainMail
def test_gibson_sponsor_steps_back_along_z_then_y_then_x() -> None:
    seed = (9, 4, 1)
    assert gibson_sponsor(seed, seed) is None
    assert gibson_sponsor((7, 4, 1), seed) == (8, 4, 1)  # on the seed's x row: along x
    assert gibson_sponsor((11, 4, 1), seed) == (10, 4, 1)
    assert gibson_sponsor((7, 6, 1), seed) == (7, 5, 1)  # off in y: along y
    assert gibson_sponsor((7, 2, 1), seed) == (7, 3, 1)
    assert gibson_sponsor((7, 2, 0), seed) == (7, 2, 1)  # off in z: along z


def test_chainmail_relaxation_lowers_the_smoothness_energy(
    demos: dict[str, DemoResult],
) -> None:
    n = demos["chainmail"].numbers
    for energy in (n["smoothness_energy"], n["fish"]["smoothness_energy"]):
        assert energy[0] > energy[1] > energy[4] > 0
    curve = n["relax_curve"]["slice"]
    assert all(b <= a + 1e-9 for a, b in itertools.pairwise(curve))
    assert n["violation_after_relax_mm"] <= 1e-6  # the links stay within their limits
    # one drag, not limited: both variants move the same elements to the same state
    assert n["fraction"] == {"gibson": 1.0, "enhanced": 1.0}
    assert n["touched"]["gibson"] == n["touched"]["enhanced"] > 1
    assert n["variants_max_difference_mm"] < 1e-9
    assert n["cleanup"]["gibson"] == 0  # homogeneous material: Gibson's sponsors suffice
    # the move order starts at the dragged element and follows Gibson's sponsor lists
    for variant in ("gibson", "enhanced"):
        order = n["order"][variant]
        assert len(order) == n["touched"][variant]
        assert tuple(order[0]) == tuple(n["dragged"])
        assert len({tuple(e) for e in order}) == len(order)
    assert n["sponsor_rule_holds"] is True


# ---------------------------------------------------------------------- compare
def test_compare_massspring_spreads_the_drag_chainmail_moves_few_elements(
    demos: dict[str, DemoResult],
) -> None:
    n = demos["compare"].numbers
    ms, cm = n["massspring"], n["chainmail"]
    assert ms["moved"] > cm["moved"] > 1
    assert cm["moved_after_relax4"] > cm["moved"]  # relaxation spreads the deformation
    assert ms["settle_steps"] > 1
    assert cm["move_ms"] > 0
    tm = n["timings"]
    backends = {(r["size"], r["backend"]) for r in tm["massspring"] if r["steps_per_s"]}
    assert backends == {(8, "numpy"), (8, "gpu")}
    solvers = {(r["solver"], r["drag"]) for r in tm["chainmail"] if r["ms"]}
    assert solvers == {(s, d) for s in ("gibson", "enhanced", "gpu") for d in ("local", "large")}
    assert tm["gl_renderer"] == n["gl_renderer"]


# ---------------------------------------------------------------------- wires
def test_wires_coarser_fields_ignore_fewer_samples(demos: dict[str, DemoResult]) -> None:
    """Measured (full run, the 256³ fish): field voxels ignored 98.96 % at 1:1 down to
    95.72 % at 1:4096, ray samples 98.63 % down to 94.10 %, each step lower; on the quick
    run's small fish the trend holds overall, with one step up of 0.8 points."""
    n = demos["wires"].numbers
    rows = n["rows"]
    assert [r["scale"] for r in rows] == [1, 2, 4, 8, 16]
    assert [r["ratio"] for r in rows] == ["1:1", "1:8", "1:64", "1:512", "1:4096"]
    voxels = [r["voxels"] for r in rows]
    assert voxels == sorted(voxels, reverse=True)
    for key in ("percent_ignored_voxels", "percent_ignored_samples"):
        p = [r[key] for r in rows]
        assert all(0 < v < 100 for v in p)
        assert p[0] > p[-1] + 5, key  # the coarsest field ignores clearly fewer
        assert all(b < a + 1.0 for a, b in itertools.pairwise(p)), key
    for r in rows:
        assert r["swept"] > 0
        assert r["samples_ignored"] + r["samples_vacated"] + r["samples_swept"] == r["samples"]
    assert rows[0]["pixels_differing_from_1to1"] == 0.0
    assert n["render_cost"]["ratio"] > 0


def test_wires_coarse_field_error_against_the_1to1_field(demos: dict[str, DemoResult]) -> None:
    """Figure 12's trend measured: each coarse field maps the object's points where the
    1:1 field maps them, up to an error that grows with the ratio. Measured (quick run,
    96x48x40 fish, 1 mm voxels): object RMS 0.06 mm at 1:8 up to 0.41 mm at 1:4096; full
    run (256³, 0.375 mm): 0.04 up to 0.10 mm. Asserted: zero at 1:1, the coarsest field
    errs more than 1:8 both in RMS and in reclassified points, 1:8 well under a voxel."""
    n = demos["wires"].numbers
    errors = [r["error_vs_1to1"] for r in n["rows"]]
    first, fine, coarsest = errors[0], errors[1], errors[-1]
    assert first["object_points"] > 100
    assert first["object_mm"] == {"max": 0.0, "rms": 0.0, "p99": 0.0}
    assert first["percent_reclassified"] == 0.0
    voxel = min(n["spacing"])
    assert 0 < fine["object_mm"]["rms"] < 0.5 * voxel
    assert coarsest["object_mm"]["rms"] > fine["object_mm"]["rms"]
    assert coarsest["percent_reclassified"] > fine["percent_reclassified"]
    for e in errors:
        assert e["swept_mm"]["rms"] <= e["swept_mm"]["max"] <= e["object_mm"]["max"]
        assert e["object_mm"]["rms"] <= e["object_mm"]["p99"] <= e["object_mm"]["max"]


# ---------------------------------------------------------------------- lattice
def test_lattice_quotes_the_paper_and_names_the_lab_study(
    demos: dict[str, DemoResult],
) -> None:
    """The frame rates against 4x4 matrices are a full study of the lab (``python -m
    benchmarks lattice``, tested in tests/benchmarks/test_bench_lattice.py): the installed
    demo quotes the paper's range and names the command that measures it."""
    n = demos["lattice"].numbers
    assert tuple(n["paper_fps_ratio"]) == pytest.approx((14.9 / 19.5, 13.3 / 16.5))
    assert n["lab_command"] == "python -m benchmarks lattice"
    assert "throughput" not in n


def test_lattice_times_the_papers_own_scenes(demos: dict[str, DemoResult]) -> None:
    """GRAPP 2010 section 6's three scenes, with its counts, timed in both variants; their
    frames are the demo's second sheet."""
    res = demos["lattice"]
    rows = res.numbers["grapp_scenes"]
    counts = [(r["scene"], r["objects"], r["triangles"]) for r in rows]
    assert counts == [
        ("spheres", 185, 1_500_000),
        ("helix_4617", 4617, 164_000),
        ("helix_2566", 2566, 656_000),
    ]
    for r in rows:
        assert r["linear_fps"] > 0
        assert r["trilinear_fps"] > 0
    assert [(r["paper_linear_fps"], r["paper_trilinear_fps"]) for r in rows] == [
        (19.5, 14.9),
        (16.5, 13.3),
        (10.8, 8.4),
    ]
    assert [f.name for f in res.figures] == ["lattice.png", "lattice_grapp.png"]
    img = read_image(res.figures[1])[..., :3]
    assert img.shape[1] >= 900
    assert np.mean(img.max(axis=-1) < 20) > 0.1  # the six renders' black backgrounds
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 64  # coloured spheres drawn


# ---------------------------------------------------------------------- tours
@pytest.mark.parametrize("name", DEMOS)
def test_every_tour_lists_steps_with_scenes(demos: dict[str, DemoResult], name: str) -> None:
    res = demos[name]
    assert res.tour is not None
    assert res.tour.name == f"{name}_tour.json"
    doc = json.loads(res.tour.read_text(encoding="utf-8"))
    assert doc["format"] == TOUR_FORMAT
    assert doc["version"] == 1
    assert doc["demo"] == name
    assert (res.tour.parent / doc["figure"]).resolve() == res.figure.resolve()
    assert len(doc["steps"]) >= 3
    scenes = 0
    for step in doc["steps"]:
        assert step["title"]
        assert len(step["text"]) > 40
        if step["scene"] is not None:
            scene = json.loads((res.tour.parent / step["scene"]).read_text(encoding="utf-8"))
            assert scene["format"] == "voxwarp-scene"
            scenes += 1
    assert scenes >= 1


def test_a_tour_scene_resumes_in_the_editor(demos: dict[str, DemoResult]) -> None:
    """The GUI's EditSession takes over the model of a tour step (here: the settled
    mass-spring bend), with the state the step showed."""
    from voxwarp.editing.session import EditSession

    res = demos["massspring"]
    assert res.tour is not None
    doc = json.loads(res.tour.read_text(encoding="utf-8"))
    step = next(s for s in doc["steps"] if s["title"] == "Settled")
    session = EditSession.load(res.tour.parent / step["scene"])
    try:
        assert session.kind == "massspring"
        u = session.model.displacements()
        assert np.abs(u).max() == pytest.approx(12.0, rel=1e-3)  # the tail drag
    finally:
        session.close()


# ---------------------------------------------------------------------- CLI
@pytest.mark.gl
@pytest.mark.slow
def test_cli_demo_name_writes_the_sheet(
    gl_ctx: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sheets"
    assert main(["demo", "massspring", "--quick", "--out", str(out)]) == 0
    sheet = out / "massspring.png"
    assert read_image(sheet).shape[2] == 3
    assert capsys.readouterr().out.strip().splitlines() == [str(sheet)]
    assert not (out / "massspring_tour.json").exists()  # only with --gui


class _NoRendering:
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        raise AssertionError("this test must fail before rendering")


def test_cli_unknown_demo_name_is_a_one_line_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("voxwarp.render.offscreen.OffscreenRenderer", _NoRendering)
    assert main(["demo", "springs", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("voxwarp: error: 'springs' is neither a demo")
    for name in DEMOS:
        assert name in err[0]
    assert not (tmp_path / "o").exists()


def test_cli_quick_and_gui_need_a_demo_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("voxwarp.render.offscreen.OffscreenRenderer", _NoRendering)
    for flag in ("--quick", "--gui"):
        assert main(["demo", "sample:fish", flag, "--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1
        assert "teaching demos" in err[0]
