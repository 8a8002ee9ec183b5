"""The documentation's pictures and links: the gallery page agrees with the script that
makes it, its commands are real ``voxwarp`` command lines, and every image or page a
page (or the README) points at exists. ``make docs`` builds the site itself
(``mkdocs build --strict``); these checks need no build."""

from __future__ import annotations

import importlib.util
import re
import shlex
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted([ROOT / "README.md", *DOCS.rglob("*.md")])
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

#: ![alt](target) and <img src="target">
IMAGE = re.compile(r"!\[[^\]]*\]\(([^)\s]+)[^)]*\)|<img[^>]*\bsrc=\"([^\"]+)\"")
#: [text](target) that is not an image
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)")


def _gallery_module():
    path = ROOT / "scripts" / "make_gallery.py"
    spec = importlib.util.spec_from_file_location("make_gallery", path)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_gallery"] = module  # dataclasses look the module up while decorating
    spec.loader.exec_module(module)
    return module


GALLERY = _gallery_module()


def _text_outside_code(path: Path) -> str:
    """The page without fenced code blocks and code spans (their brackets are not links)."""
    text = re.sub(r"```.*?```", "", path.read_text(encoding="utf-8"), flags=re.S)
    return re.sub(r"`[^`\n]*`", "", text)


def _local(target: str) -> bool:
    return not re.match(r"[a-z]+:", target) and not target.startswith("#")


def test_gallery_page_is_the_one_the_script_writes() -> None:
    assert (DOCS / "gallery.md").read_text(encoding="utf-8") == GALLERY.page()


#: the gallery's entries and the concept pages' figures: the same checks for both
ALL_ENTRIES = GALLERY.GALLERY + GALLERY.FIGURES


def test_gallery_names_are_unique_and_commands_start_with_voxwarp() -> None:
    names = [e.name for e in ALL_ENTRIES]
    assert len(names) == len(set(names))
    assert 10 <= len(GALLERY.GALLERY) <= 16
    for e in ALL_ENTRIES:
        assert e.commands, e.name
        assert all(shlex.split(c)[0] == "voxwarp" for c in e.commands), e.name
        folder = e.image.rsplit("/", 1)[0]
        assert folder in e.commands[-1], f"{e.name}: the last command must write {e.image}"


@pytest.mark.parametrize("entry", ALL_ENTRIES, ids=lambda e: e.name)
def test_gallery_image_is_a_small_png(entry) -> None:
    folder = "figures" if entry in GALLERY.FIGURES else "gallery"
    path = DOCS / folder / f"{entry.name}.png"
    data = path.read_bytes()
    assert data.startswith(PNG_MAGIC), path
    assert len(data) <= GALLERY.MAX_BYTES * 1.05, f"{path}: {len(data)} bytes"
    if entry.readme:
        readme = DOCS / "images" / f"readme_{entry.name}.png"
        assert readme.read_bytes().startswith(PNG_MAGIC), readme
        assert f"docs/images/readme_{entry.name}.png" in (ROOT / "README.md").read_text()


def test_gallery_folder_holds_only_listed_images() -> None:
    listed = {f"{e.name}.png" for e in GALLERY.GALLERY}
    assert {p.name for p in (DOCS / "gallery").iterdir()} == listed
    figures = {f"{e.name}.png" for e in GALLERY.FIGURES}
    assert {p.name for p in (DOCS / "figures").iterdir()} == figures


@pytest.mark.parametrize("entry", ALL_ENTRIES, ids=lambda e: e.name)
def test_gallery_commands_parse(entry) -> None:
    """Each command is a real subcommand with valid options (parsed, not run), and every
    repository file it reads exists."""
    from voxwarp.cli.main import build_parser
    from voxwarp.cli.options import (  # what main() does before parsing
        join_negative_views as _join_negative_views,
    )

    parser = build_parser()
    for argv in entry.argvs():
        args = parser.parse_args(_join_negative_views(argv))
        assert callable(args.func), argv
        for word in argv:
            if word.startswith(("sample_volumes/", "docs/", "scripts/")):
                assert (ROOT / word).is_file(), f"{entry.name}: {word} does not exist"


def test_gallery_command_parse_check_rejects_a_bad_option() -> None:
    from voxwarp.cli.main import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["render", "sample:stent", "--no-such-option"])


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_images_exist(page: Path) -> None:
    for match in IMAGE.finditer(_text_outside_code(page)):
        target = match[1] or match[2]
        if _local(target):
            assert (page.parent / target).is_file(), f"{page.name}: image {target} is missing"


def test_readme_links_to_existing_files() -> None:
    """mkdocs checks the links inside docs/; the README is not part of the site."""
    readme = ROOT / "README.md"
    for match in LINK.finditer(_text_outside_code(readme)):
        target = match[1].split("#")[0]
        if target and _local(match[1]):
            assert (ROOT / target).exists(), f"README.md links to missing {target}"


def test_readme_shows_top_images_before_the_quick_start() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    top = text[: text.index("## Quick start")]
    assert 3 <= top.count('<img src="docs/images/readme_') <= 4


def test_gallery_page_shows_each_command_word_for_word() -> None:
    """The page breaks long commands into backslash-continued lines; a shell reading
    them gets the same words as the command the script runs."""
    for e in ALL_ENTRIES:
        for command in e.commands:
            shown = GALLERY.shell_lines(command)
            assert max(len(line) for line in shown.splitlines()) <= 78, shown
            assert shlex.split(shown.replace("\\\n", " ")) == shlex.split(command)
