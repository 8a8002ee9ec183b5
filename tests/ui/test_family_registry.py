"""The deformation families' registries and docs/reference/layout.md's "Adding a
deformation family": the listed files exist, and the adapter, panel and animation-target
registries each hold one entry per family (no Qt window: only the registries are read)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from voxwarp.animation.targets import TARGET_FAMILIES
from voxwarp.editing.families import FAMILIES, Family

ROOT = Path(__file__).resolve().parents[2]
SECTION = "## Adding a deformation family"


def _section() -> str:
    text = (ROOT / "docs" / "reference" / "layout.md").read_text(encoding="utf-8")
    assert SECTION in text
    return text.split(SECTION, 1)[1].split("\n## ", 1)[0]


def test_the_listed_files_exist() -> None:
    rows = [r for r in _section().splitlines() if r.startswith("| ") and "`" in r]
    assert len(rows) == 7  # warp, shader, settings, adapter, panel, animation targets, CLI
    for row in rows:
        for path in re.findall(r"`([\w/]+\.(?:py|glsl))`", row):
            assert (ROOT / path).is_file(), f"layout.md names {path}, which does not exist"


def test_one_adapter_per_family_in_its_own_file() -> None:
    assert list(FAMILIES) == ["none", "massspring", "chainmail", "wires", "lattice"]
    for kind, cls in FAMILIES.items():
        assert cls.kind == kind
        assert issubclass(cls, Family)
        assert cls.__module__.startswith("voxwarp.editing.families.")


def test_one_panel_per_family() -> None:
    pytest.importorskip("PySide6")
    from voxwarp.ui.family_panels import FAMILY_PANELS

    assert list(FAMILY_PANELS) == list(FAMILIES)


def test_animation_targets_name_registered_families_once() -> None:
    named = [kind for handler in TARGET_FAMILIES for kind in handler.families]
    assert len(named) == len(set(named))
    assert set(named) <= set(FAMILIES)
    # every family with something to key has its targets (the family "none" has none)
    assert set(named) == set(FAMILIES) - {"none"}


def test_shared_editing_code_never_names_a_family() -> None:
    """The session, the state and common modules and the keyframes import no family
    adapter by name and never test the family's type."""
    for name in ("session.py", "state.py", "common.py", "keyframes.py", "model_settings.py"):
        text = (ROOT / "app" / "editing" / name).read_text(encoding="utf-8")
        imports = [line for line in text.splitlines() if line.startswith(("from ", "import "))]
        assert not [line for line in imports if "families." in line], name
        assert "isinstance(self.family" not in text, name


def test_family_adapters_never_import_the_session() -> None:
    for path in (ROOT / "app" / "editing" / "families").glob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert "editing.session import" not in text, path.name
        assert "import voxwarp.editing.session" not in text, path.name


def test_shared_gui_code_never_names_a_family() -> None:
    """The main window, the viewport and the panels import no family adapter (``families.`` of
    ``voxwarp.editing``) and no family panel module, and name no adapter class: a family's
    actions and clicks go through the generic hooks (the panel's ``window_actions``, the
    adapter's ``placing`` and ``place_point``)."""
    adapters = [cls.__name__ for cls in FAMILIES.values() if cls is not Family]
    for name in ("main_window.py", "viewport.py", "panels.py"):
        text = (ROOT / "ui" / name).read_text(encoding="utf-8")
        imports = [line for line in text.splitlines() if line.startswith(("from ", "import "))]
        assert not [line for line in imports if "families" in line], name
        assert not [cls for cls in adapters if cls in text], name
