"""Project metadata: pyproject.toml, LICENSE, CITATION.cff, py.typed, dependency licenses.

Oracles: validate-pyproject (PyPA's JSON schemas for pyproject.toml, with PyPI's list of
trove classifiers), the Citation File Format 1.2.0 schema (``tests/data``, from the
citation-file-format project, CC-BY-4.0) and each installed dependency's own metadata.
"""

from __future__ import annotations

import importlib.metadata as md
import importlib.resources
import json
import re
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))

#: license families that combine with BSD-3-Clause code (docs/license.md says why)
COMPATIBLE = {
    "BSD-2-Clause",
    "BSD-3-Clause",
    "MIT",
    "MIT-CMU",
    "ISC",
    "Apache-2.0",
    "PSF-2.0",
    "MPL-2.0 AND MIT",
    "LGPL-3.0",
    "GPL-3.0",
}


def _license_table() -> dict[str, tuple[str, str]]:
    """docs/license.md's dependency table: normalised name -> (extra, license)."""
    text = (ROOT / "docs" / "license.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| ([\w.-]+) \| (\w+) \| ([^|]+?) \|$", text, flags=re.M)
    return {_norm(n): (extra, lic) for n, extra, lic in rows if n != "package"}


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirements() -> list[tuple[str, str]]:
    """(normalised name, extra) of every requirement except dev tools and self-references."""
    project = PYPROJECT["project"]
    reqs = [(Requirement(r).name, "core") for r in project["dependencies"]]
    for extra, items in project["optional-dependencies"].items():
        if extra != "dev":
            reqs += [(Requirement(r).name, extra) for r in items]
    return [(_norm(n), e) for n, e in reqs if _norm(n) != "voxwarp"]


def test_pyproject_is_valid_with_known_classifiers() -> None:
    from validate_pyproject import api, plugins

    validator = api.Validator(plugins.list_from_entry_points())
    validator(PYPROJECT)  # raises ValidationError naming the field
    classifiers = PYPROJECT["project"]["classifiers"]
    from trove_classifiers import classifiers as known

    assert set(classifiers) <= known, set(classifiers) - known


def test_license_file_matches_the_declared_license() -> None:
    assert PYPROJECT["project"]["license"] == "BSD-3-Clause"
    assert PYPROJECT["project"]["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    # the three clauses of the SPDX BSD-3-Clause text
    assert "Redistributions of source code must retain" in text
    assert "Redistributions in binary form must reproduce" in text
    assert "Neither the name of the copyright holder" in text


def test_installed_metadata_carries_license_and_urls() -> None:
    meta = md.metadata("voxwarp")
    assert meta["License-Expression"] == "BSD-3-Clause"
    urls = dict(u.split(", ", 1) for u in meta.get_all("Project-URL"))
    assert {"Homepage", "Documentation", "Source", "Issues"} <= set(urls)
    assert all(u.startswith("https://") for u in urls.values())


def test_package_is_marked_typed() -> None:
    assert importlib.resources.files("voxwarp").joinpath("py.typed").is_file()
    package_data = PYPROJECT["tool"]["setuptools"]["package-data"]
    assert "py.typed" in package_data["voxwarp"]


def test_citation_cff_is_valid_and_cites_the_three_papers() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    yaml = pytest.importorskip("yaml")
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    schema = json.loads((ROOT / "tests/data/citation-cff-1.2.0.schema.json").read_text())
    # dates must stay strings for the schema (YAML would read them as dates)
    cff = json.loads(json.dumps(cff, default=str))
    jsonschema.validate(cff, schema)
    assert cff["version"] == PYPROJECT["project"]["version"]
    assert cff["license"] == PYPROJECT["project"]["license"]
    years = sorted(ref["year"] for ref in cff["references"])
    assert years == [2006, 2008, 2010]
    names = {a["family-names"] for ref in cff["references"] for a in ref["authors"]}
    assert {"Knoche", "Walton", "Jones", "Knuth", "Kohlhammer", "Kuijper"} <= names


def test_every_dependency_has_a_compatible_license_listed() -> None:
    table = _license_table()
    missing = [n for n, _ in _requirements() if n not in table]
    assert not missing, f"add these to docs/license.md: {missing}"
    for name, extra in _requirements():
        assert table[name][0] == extra, (name, table[name], extra)
        assert table[name][1] in COMPATIBLE, (name, table[name][1])


@pytest.mark.parametrize("name", sorted(_license_table()))
def test_installed_dependency_metadata_agrees_with_the_table(name: str) -> None:
    try:
        meta = md.metadata(name)
    except md.PackageNotFoundError:
        pytest.skip(f"{name} is not installed here (its extra is not in .[all,dev])")
    declared = _license_table()[name][1]
    said = " ".join(
        [meta.get("License-Expression") or "", (meta.get("License") or "")[:200]]
        + [c for c in meta.get_all("Classifier") or [] if c.startswith("License")]
    )
    families = {
        "GPL": r"\bGPL|General Public License",
        "LGPL": r"LGPL|Lesser General",
        "Apache": r"Apache",
        "permissive": r"BSD|MIT|ISC|PSF|Python Software|HPND|CMU|matplotlib",
    }
    found = {f for f, pattern in families.items() if re.search(pattern, said)}
    if not found:
        return  # the package states nothing machine-readable (checked by hand in the table)
    kind = "LGPL" if declared.startswith("LGPL") else "GPL" if "GPL" in declared else None
    if kind is None:
        kind = "Apache" if declared.startswith("Apache") else "permissive"
    assert kind in found, f"{name}: table says {declared}, metadata says {said[:120]!r}"
