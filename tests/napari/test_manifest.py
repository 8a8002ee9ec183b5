"""The npe2 manifest: valid for npe2 (as ``npe2 validate voxwarp --imports`` checks it),
found through the installed entry point, and in step with the code it names."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import npe2

import voxwarp.napari_plugin
from voxwarp.io.samples import sample_names

MANIFEST = Path(voxwarp.napari_plugin.__file__).with_name("napari.yaml")


def test_manifest_validates_and_its_python_names_import() -> None:
    pm = npe2.PluginManifest.from_file(MANIFEST)  # schema validation (pydantic)
    pm.validate_imports()  # every python_name imports and names an object
    assert pm.name == "voxwarp"


def test_npe2_validate_command_passes() -> None:
    # the command CI's "Done when" names: the installed entry point, imports included
    result = subprocess.run(
        [sys.executable, "-m", "npe2", "validate", "voxwarp", "--imports"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "valid!" in result.stdout


def test_entry_point_finds_this_manifest() -> None:
    pm = npe2.PluginManifest._from_package_or_name("voxwarp")  # napari.manifest entry point
    assert pm.contributions == npe2.PluginManifest.from_file(MANIFEST).contributions


def test_every_bundled_sample_is_sample_data() -> None:
    pm = npe2.PluginManifest.from_file(MANIFEST)
    assert sorted(s.key for s in pm.contributions.sample_data) == sorted(sample_names())


def test_reader_patterns_and_widget() -> None:
    pm = npe2.PluginManifest.from_file(MANIFEST)
    (reader,) = pm.contributions.readers
    assert {"*.json", "*.nrrd", "*.nhdr", "*.nii", "*.nii.gz"} <= set(reader.filename_patterns)
    assert reader.accepts_directories
    (widget,) = pm.contributions.widgets
    command = next(c for c in pm.contributions.commands if c.id == widget.command)
    assert command.python_name == "voxwarp.napari_plugin.widget:VoxwarpWidget"
