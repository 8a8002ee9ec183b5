"""Transfer functions imported from ParaView, 3D Slicer and matplotlib (voxwarp.core.tf_formats).

The test files are written the way those tools write them:

* ParaView: a JSON list of colour-map objects as in Kitware/ParaView
  ``Remoting/Views/ColorMaps.json`` ("Cool to Warm", "Black-Body Radiation", "X Ray" with
  their RGBPoints copied from it) and as the Choose Preset dialog's *Export* writes a
  user's map (jsoncpp's styled writer: 3-space indent, ``"Key" : value``; ``Points`` saved
  with the opacity function, fields as in ``vtkSMTransferFunctionProxy::GetStateAsPreset``).
* Slicer: ``<VolumeProperty>`` elements copied from
  Slicer/Slicer ``Modules/Loadable/VolumeRendering/Resources/presets.xml`` (CT-AAA,
  CT-Bone, MR-Default verbatim), ``.vp`` files in the line order of
  ``vtkMRMLVolumePropertyStorageNode::WriteData`` (Libs/MRML/Core in older Slicer,
  Modules/Loadable/VolumeRendering/MRML now) including Slicer's own test file
  ``Testing/Data/Input/VolumeProperty.vp``, and ``.vp.json`` as
  ``vtkMRMLVolumePropertyJsonStorageNode`` writes it.

Oracles: the imported function evaluated at the file's control values equals the file's
colours and opacities (opacity converted by the stated unit-distance rule); matplotlib
colours at the sample points equal ``matplotlib.colormaps[name](t)`` within 1/255.
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from voxwarp.core import tf_curves, tf_formats
from voxwarp.core import transfer_function as tfmod
from voxwarp.core.transfer_function import PRESETS, TransferFunction, file_spec
from voxwarp.core.volume import Volume
from voxwarp.errors import SceneError
from voxwarp.io.samples import load_sample

# ---------------------------------------------------------------------------- files
PRESETS_XML = """<?xml version="1.0" encoding="utf-8"?>
<MRML>
  <VolumeProperty selected="false" hideFromEditors="false" name="CT-AAA" gradientOpacity="4 0 1 255 1" userTags="" specularPower="10" scalarOpacity="12 -3024 0 143.556 0 166.222 0.686275 214.389 0.696078 419.736 0.833333 3071 0.803922" id="vtkMRMLVolumePropertyNode1" specular="0.2" shade="1" ambient="0.1" colorTransfer="24 -3024 0 0 0 143.556 0.615686 0.356863 0.184314 166.222 0.882353 0.603922 0.290196 214.389 1 1 1 419.736 1 0.937033 0.954531 3071 0.827451 0.658824 1" selectable="true" diffuse="0.9" interpolation="1"/>
  <VolumeProperty selected="false" hideFromEditors="false" name="CT-Bone" gradientOpacity="4 0 1 255 1" userTags="" specularPower="10" scalarOpacity="8 -3024 0 -16.4458 0 641.385 0.715686 3071 0.705882" id="vtkMRMLVolumePropertyNode3" specular="0.2" shade="1" ambient="0.1" colorTransfer="16 -3024 0 0 0 -16.4458 0.729412 0.254902 0.301961 641.385 0.905882 0.815686 0.552941 3071 1 1 1" selectable="true" diffuse="0.9" interpolation="1"/>
  <VolumeProperty selected="false" hideFromEditors="false" name="MR-Default" gradientOpacity="4 0 1 255 1" userTags="" specularPower="1" scalarOpacity="12 0 0 20 0 40 0.15 120 0.3 220 0.375 1024 0.5" id="vtkMRMLVolumePropertyNode22" specular="0" shade="1" ambient="0.2" colorTransfer="24 0 0 0 0 20 0.168627 0 0 40 0.403922 0.145098 0.0784314 120 0.780392 0.607843 0.380392 220 0.847059 0.835294 0.788235 1024 1 1 1" selectable="true" diffuse="1" interpolation="1"/>
</MRML>
"""  # noqa: E501 (copied verbatim from Slicer's presets.xml)
CT_BONE_OPACITY = [(-3024, 0), (-16.4458, 0), (641.385, 0.715686), (3071, 0.705882)]
CT_BONE_COLOUR = [
    (-3024, 0, 0, 0),
    (-16.4458, 0.729412, 0.254902, 0.301961),
    (641.385, 0.905882, 0.815686, 0.552941),
    (3071, 1, 1, 1),
]

#: From ParaView's ColorMaps.json (0..1 ranges, no opacity).
PARAVIEW_PRESETS = [
    {
        "ColorSpace": "Diverging",
        "Name": "Cool to Warm",
        "NanColor": [1, 1, 0],
        "DefaultMap": True,
        "RGBPoints": [0, 0.23137254902, 0.298039215686, 0.752941176471, 0.5, 0.865, 0.865,
                      0.865, 1, 0.705882352941, 0.0156862745098, 0.149019607843],
    },
    {
        "ColorSpace": "RGB",
        "Name": "Black-Body Radiation",
        "DefaultMap": True,
        "NanColor": [0, 0.498039215686, 1],
        "RGBPoints": [0, 0, 0, 0, 0.4, 0.901960784314, 0, 0, 0.8, 0.901960784314,
                      0.901960784314, 0, 1, 1, 1, 1],
    },
    {
        "ColorSpace": "RGB",
        "Name": "X Ray",
        "DefaultMap": True,
        "NanColor": [1, 0, 0],
        "RGBPoints": [0, 1, 1, 1, 1, 0, 0, 0],
    },
]  # fmt: skip

#: A user's map exported with its opacity, in data units (HU).
PARAVIEW_EXPORT = [
    {
        "ColorSpace": "RGB",
        "Creator": "voxwarp test",
        "Name": "bone-hu",
        "NanColor": [1, 1, 0],
        "Points": [-1000.0, 0.0, 0.5, 0.0, 200.0, 0.0, 0.5, 0.0, 700.0, 0.6, 0.5, 0.0,
                   2000.0, 0.8, 0.5, 0.0],
        "RGBPoints": [-1000.0, 0.0, 0.0, 0.0, 200.0, 0.6, 0.3, 0.2, 700.0, 0.95, 0.9, 0.8,
                      2000.0, 1.0, 1.0, 1.0],
    }
]  # fmt: skip


def paraview_json(maps: list[dict]) -> str:
    """As ParaView's export writes it (jsoncpp StyledWriter: 3 spaces, ' : ')."""
    return json.dumps(maps, indent=3, separators=(",", " : ")) + "\n"


def vp_text(opacity: str, colour: str) -> str:
    """A Slicer .vp: interpolation, shade, diffuse, ambient, specular, specular power,
    scalar opacity, gradient opacity, colour transfer (WriteData's order)."""
    return "\n".join(["1", "1", "0.9", "0.1", "0.2", "10", opacity, "4 0 1 255 1", colour]) + "\n"


def write(tmp_path: Path, name: str, text: str) -> str:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return str(p)


def hu_volume(spacing: float = 1.0) -> Volume:
    data = np.linspace(-1000, 2000, 16 * 16 * 8).reshape(16, 16, 8).astype(np.int16)
    return Volume(data, spacing=(spacing, spacing, spacing), name="hu", units="HU")


def window(volume: Volume) -> tuple[float, float]:
    level, width = volume.default_window()
    return level - width / 2, level + width / 2


# ---------------------------------------------------------------------------- Slicer
def test_slicer_preset_by_name_matches_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "presets.xml", PRESETS_XML)
    tf = TransferFunction.load(f"{path}:CT-Bone", hu_volume(1.0))
    assert tf.name == "CT-Bone"
    for x, r, g, b in CT_BONE_COLOUR:
        np.testing.assert_allclose(tf(x)[:3], (r, g, b), atol=1e-9)
    for x, a in CT_BONE_OPACITY:  # 1 mm voxels: Slicer's 1 mm unit distance, unchanged
        assert tf(x)[3] == pytest.approx(a, abs=1e-9)


def test_slicer_opacity_follows_the_unit_distance(tmp_path: Path) -> None:
    path = write(tmp_path, "presets.xml", PRESETS_XML)
    tf = TransferFunction.load(path, hu_volume(0.5), name="CT-Bone")
    for x, a in CT_BONE_OPACITY:  # half-mm reference sample: 1 - (1 - a) ** 0.5
        assert tf(x)[3] == pytest.approx(1 - (1 - a) ** 0.5, abs=1e-9)
    assert tf(641.385)[3] < 0.715686


def test_slicer_ct_preset_on_a_volume_that_is_not_hu_warns(tmp_path: Path) -> None:
    path = write(tmp_path, "presets.xml", PRESETS_XML)
    grey = Volume(np.linspace(0, 255, 16 * 16 * 8).reshape(16, 16, 8).astype(np.uint8), name="u8")
    with pytest.warns(UserWarning, match="'CT-Bone' is in Hounsfield units but volume 'u8'"):
        tf = TransferFunction.load(f"{path}:CT-Bone", grey)
    assert tf.value_range == (-3024.0, 3071.0)  # kept
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an MR preset on it, or a CT preset on HU: no warning
        TransferFunction.load(f"{path}:MR-Default", grey)
        TransferFunction.load(f"{path}:CT-Bone", load_sample("fish"))  # HU


def test_slicer_file_without_a_name_takes_the_first_with_a_warning(tmp_path: Path) -> None:
    path = write(tmp_path, "presets.xml", PRESETS_XML)
    with pytest.warns(UserWarning, match="CT-AAA.*CT-Bone, MR-Default"):
        tf = TransferFunction.load(path)
    assert tf.name == "CT-AAA"
    assert TransferFunction.map_names(path) == ["CT-AAA", "CT-Bone", "MR-Default"]


def test_unknown_map_name_lists_the_names(tmp_path: Path) -> None:
    path = write(tmp_path, "presets.xml", PRESETS_XML)
    with pytest.raises(SceneError) as info:
        TransferFunction.load(f"{path}:CT-Bones")
    msg = str(info.value)
    assert "\n" not in msg
    assert "'CT-Bones'" in msg
    assert "CT-AAA, CT-Bone, MR-Default" in msg
    # case-insensitive as a fallback
    assert TransferFunction.load(f"{path}:ct-bone").name == "CT-Bone"


def test_slicer_vp_file(tmp_path: Path) -> None:
    opacity = "8 -3024 0 -16.4458 0 641.385 0.715686 3071 0.705882"
    colour = (
        "16 -3024 0 0 0 -16.4458 0.729412 0.254902 0.301961 641.385 0.905882 0.815686"
        " 0.552941 3071 1 1 1"
    )
    path = write(tmp_path, "bone.vp", vp_text(opacity, colour))
    tf = TransferFunction.load(path, hu_volume(1.0))
    assert tf.name == "bone"
    for x, r, g, b in CT_BONE_COLOUR:
        np.testing.assert_allclose(tf(x)[:3], (r, g, b), atol=1e-9)
    for x, a in CT_BONE_OPACITY:
        assert tf(x)[3] == pytest.approx(a, abs=1e-9)
    assert TransferFunction.map_names(path) == ["bone"]


#: Slicer's test file Modules/Loadable/VolumeRendering/Testing/Data/Input/VolumeProperty.vp
SLICER_TEST_VP = """1
1
0.42
0.44
0.46
38.5
8 -17 0 13 0 103 1 235 1
4 -17 1 235 1
28 -17 1 0 0.498039215686275 13 1 0.333333333333333 1 35.5882339477539 1 0.333333333333333 0.498039215686275 58.1764717102051 1 0.333333333333333 1 80.7647094726563 1 1 0.498039215686275 103 0.333333333333333 0.666666666666667 1 235 1 1 1
"""  # noqa: E501


def test_slicers_own_vp_test_file(tmp_path: Path) -> None:
    tf = TransferFunction.load(write(tmp_path, "VolumeProperty.vp", SLICER_TEST_VP), hu_volume())
    np.testing.assert_allclose(tf(-17)[:3], (1, 0, 0.498039215686275), atol=1e-9)
    np.testing.assert_allclose(tf(103)[:3], (0.333333333333333, 0.666666666666667, 1), atol=1e-9)
    assert tf(13)[3] == pytest.approx(0.0)
    assert tf(58)[3] == pytest.approx(0.5)  # halfway between (13, 0) and (103, 1)
    assert tf(235)[3] == pytest.approx(1.0)


def slicer_vp_json(unit: float, mid: float = 0.5) -> str:
    """A .vp.json as vtkMRMLVolumePropertyJsonStorageNode writes it (rapidjson, 4 spaces)."""

    def pts(rows: list, key: str) -> list:
        return [{"x": x, key: v, "midpoint": mid if k == 0 else 0.5, "sharpness": 0.0}
                for k, (x, v) in enumerate(rows)]  # fmt: skip

    component = {
        "componentWeight": 1.0,
        "shade": True,
        "lighting": {"diffuse": 0.9, "ambient": 0.1, "specular": 0.2, "specularPower": 10.0},
        "disableGradientOpacity": False,
        "scalarOpacityUnitDistance": unit,
        "rgbTransferFunction": {
            "type": "colorTransferFunction",
            "points": pts([(x, [r, g, b]) for x, r, g, b in CT_BONE_COLOUR], "color"),
        },
        "scalarOpacity": {"type": "piecewiseLinearFunction", "points": pts(CT_BONE_OPACITY, "y")},
        "gradientOpacity": {
            "type": "piecewiseLinearFunction",
            "points": pts([(0, 1.0), (255, 1.0)], "y"),
        },
    }
    doc = {
        "@schema": "https://raw.githubusercontent.com/slicer/slicer/main/Modules/Loadable/"
        "VolumeRendering/Resources/Schema/volume-property-schema-v1.0.0.json#",
        "volumeProperties": [
            {
                "effectiveRange": [-16.4458, 641.385],
                "isoSurfaceValues": [],
                "independentComponents": True,
                "interpolationType": "linear",
                "useClippedVoxelIntensity": False,
                "clippedVoxelIntensity": -10000000000.0,
                "scatteringAnisotropy": 0.0,
                "components": [component],
            }
        ],
    }
    return json.dumps(doc, indent=4)


def test_slicer_vp_json_uses_its_unit_distance(tmp_path: Path) -> None:
    path = write(tmp_path, "bone.vp.json", slicer_vp_json(unit=2.0))
    tf = TransferFunction.load(path, hu_volume(1.0))
    assert tf.name == "bone"
    for x, r, g, b in CT_BONE_COLOUR:
        np.testing.assert_allclose(tf(x)[:3], (r, g, b), atol=1e-9)
    for x, a in CT_BONE_OPACITY:  # per 2 mm in the file, per 1 mm voxel here
        assert tf(x)[3] == pytest.approx(1 - (1 - a) ** 0.5, abs=1e-9)
    assert TransferFunction.map_names(path) == ["bone"]


def test_slicer_vp_json_colour_midpoint(tmp_path: Path) -> None:
    path = write(tmp_path, "mid.vp.json", slicer_vp_json(unit=1.0, mid=0.25))
    tf = TransferFunction.load(path, hu_volume(1.0))
    x0, x1 = CT_BONE_COLOUR[0][0], CT_BONE_COLOUR[1][0]
    halfway = 0.5 * (np.array(CT_BONE_COLOUR[0][1:]) + CT_BONE_COLOUR[1][1:])
    np.testing.assert_allclose(tf(x0 + 0.25 * (x1 - x0))[:3], halfway, atol=1e-9)


@pytest.mark.parametrize(
    ("edit", "pattern"),
    [
        (lambda d: d.update(volumeProperties=[]), "non-empty list"),
        (lambda d: d["volumeProperties"][0].pop("components"), "no 'components'"),
        (lambda d: d["volumeProperties"][0]["components"][0].update(scalarOpacityUnitDistance=0),
         "must be positive"),
        (lambda d: d["volumeProperties"][0]["components"][0]["scalarOpacity"]["points"][1]
         .update(y="NaN"), "not a number"),
        (lambda d: d["volumeProperties"][0]["components"][0]["rgbTransferFunction"]["points"][0]
         .update(color=[1, 0]), "3 value"),
        (lambda d: d["volumeProperties"][0]["components"][0].pop("scalarOpacity"), "points"),
    ],
)  # fmt: skip
def test_hostile_slicer_vp_json(tmp_path: Path, edit: object, pattern: str) -> None:
    doc = json.loads(slicer_vp_json(1.0))
    edit(doc)  # type: ignore[operator]
    with pytest.raises(SceneError, match=pattern) as info:
        TransferFunction.load(write(tmp_path, "x.vp.json", json.dumps(doc)))
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------- ParaView
def test_paraview_export_in_data_units(tmp_path: Path) -> None:
    path = write(tmp_path, "bone.json", paraview_json(PARAVIEW_EXPORT))
    tf = TransferFunction.load(path, hu_volume())
    rgb = np.reshape(PARAVIEW_EXPORT[0]["RGBPoints"], (-1, 4))
    pts = np.reshape(PARAVIEW_EXPORT[0]["Points"], (-1, 4))
    assert tf.name == "bone-hu"
    for x, r, g, b in rgb:
        np.testing.assert_allclose(tf(x)[:3], (r, g, b), atol=1e-9)
    for x, a, _mid, _sharp in pts:  # ParaView opacities are taken per reference sample
        assert tf(x)[3] == pytest.approx(a, abs=1e-9)


def test_paraview_normalised_map_is_stretched_onto_the_window(tmp_path: Path) -> None:
    path = write(tmp_path, "ColorMaps.json", paraview_json(PARAVIEW_PRESETS))
    vol = hu_volume()
    lo, hi = window(vol)
    tf = TransferFunction.load(f"{path}:Black-Body Radiation", vol)
    rgb = np.reshape(PARAVIEW_PRESETS[1]["RGBPoints"], (-1, 4))
    for t, r, g, b in rgb:
        np.testing.assert_allclose(tf(lo + t * (hi - lo))[:3], (r, g, b), atol=1e-9)
    # no Points: the opacity ramp, 0 at the bottom to RAMP_OPACITY at the top
    assert tf(lo)[3] == pytest.approx(0.0)
    assert tf(hi)[3] == pytest.approx(tf_formats.RAMP_OPACITY)
    assert tf(0.5 * (lo + hi))[3] == pytest.approx(0.5 * tf_formats.RAMP_OPACITY)


def test_paraview_minus_one_to_one_is_normalised_too(tmp_path: Path) -> None:
    m = {"Name": "sym", "ColorSpace": "RGB", "RGBPoints": [-1, 0, 0, 1, 0, 1, 1, 1, 1, 1, 0, 0]}
    path = write(tmp_path, "sym.json", paraview_json([m]))
    vol = hu_volume()
    lo, hi = window(vol)
    tf = TransferFunction.load(path, vol)
    np.testing.assert_allclose(tf(0.5 * (lo + hi))[:3], (1, 1, 1), atol=1e-9)
    np.testing.assert_allclose(tf(lo)[:3], (0, 0, 1), atol=1e-9)
    # without a volume the file's own units stay
    assert TransferFunction.load(path).value_range == (-1.0, 1.0)


def test_paraview_midpoint_adds_a_halfway_point(tmp_path: Path) -> None:
    m = {
        "Name": "mid",
        "RGBPoints": [0, 0, 0, 0, 10, 1, 1, 1],
        "Points": [0, 0.0, 0.25, 0.0, 10, 0.8, 0.5, 0.0],
    }
    tf = TransferFunction.load(write(tmp_path, "mid.json", paraview_json([m])))
    assert tf(2.5)[3] == pytest.approx(0.4)  # halfway opacity at 25 % of the segment
    assert tf(10)[3] == pytest.approx(0.8)


def test_paraview_sharpness_and_colour_space_are_reported(tmp_path: Path) -> None:
    m = {**PARAVIEW_PRESETS[0], "ColorSpace": "Lab/CIEDE2000", "Name": "de2000"}
    path = write(tmp_path, "de.json", paraview_json([m]))
    with pytest.warns(UserWarning, match="'de2000'") as caught:
        TransferFunction.load(path)
    text = " ".join(str(w.message) for w in caught)
    assert "Lab/CIEDE2000 colour space interpolated in RGB" in text


#: VTK 9.7.2's vtkPiecewiseFunction (AddPoint(x, y, midpoint, sharpness), GetValue):
#: name -> (points, [[x, opacity], ...]).
VTK_OPACITIES = {
    "mid 0.25": (
        [(0, 0.0, 0.25, 0.0), (10, 0.8, 0.5, 0.0)],
        [[1.25, 0.2], [2.5, 0.4], [3.75, 0.466667], [5.0, 0.533333], [6.25, 0.6], [7.5, 0.666667],
         [8.75, 0.733333]],
    ),
    "sharp 0.7": (
        [(0, 0.0, 0.5, 0.7), (10, 0.8, 0.5, 0.0)],
        [[1.25, 2e-06], [2.5, 0.000475], [3.75, 0.016083], [5.0, 0.4], [6.25, 0.783917],
         [7.5, 0.799525], [8.75, 0.799998]],
    ),
    "sharp 0.3 mid 0.7 falling": (
        [(0, 0.9, 0.7, 0.3), (4, 0.1, 0.5, 0.0), (10, 0.6, 0.5, 0.0)],
        [[1.25, 0.888598], [2.5, 0.664756], [3.75, 0.100528], [5.0, 0.183333], [6.25, 0.2875],
         [7.5, 0.391667], [8.75, 0.495833]],
    ),
    "sharpness 1": (
        [(0, 0.1, 0.4, 1.0), (10, 0.7, 0.5, 0.0)],
        [[1.25, 0.1], [2.5, 0.100015], [3.75, 0.190958], [5.0, 0.692214], [6.25, 0.699985],
         [7.5, 0.7], [8.75, 0.7]],
    ),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(VTK_OPACITIES))
def test_paraview_opacity_midpoint_and_sharpness_match_vtk(tmp_path: Path, name: str) -> None:
    pts, expected = VTK_OPACITIES[name]
    m = {
        "Name": name,
        "RGBPoints": [0, 1, 1, 1, 10, 1, 1, 1],
        "Points": [v for p in pts for v in p],
    }
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # reproduced: no note
        tf = TransferFunction.load(write(tmp_path, "o.json", paraview_json([m])))
    for x, a in expected:
        assert tf(x)[3] == pytest.approx(a, abs=1 / 255), f"{name} at {x}"


def test_paraview_lab_maps_interpolate_in_lab(tmp_path: Path) -> None:
    from skimage import color  # an independent sRGB <-> CIE Lab (D65)

    c0, c1 = np.array([0.05, 0.1, 0.4]), np.array([0.95, 0.85, 0.2])
    m = {"Name": "lab", "ColorSpace": "Lab", "RGBPoints": [0, *c0, 10, *c1]}
    tf = TransferFunction.load(write(tmp_path, "lab.json", paraview_json([m])))
    for t in (0.25, 0.5, 0.8):
        lab = (1 - t) * color.rgb2lab(c0[None]) + t * color.rgb2lab(c1[None])
        want = color.lab2rgb(lab)[0]
        assert np.all((want > 0.01) & (want < 0.99))  # inside the gamut: no clipping rule
        np.testing.assert_allclose(tf(10 * t)[:3], want, atol=1 / 255)
    # the RGB line would be off by far more than that
    assert np.abs(tf(5)[:3] - 0.5 * (c0 + c1)).max() > 10 / 255
    grey = TransferFunction.load(
        write(tmp_path, "bw.json", paraview_json([{**m, "RGBPoints": [0, 0, 0, 0, 1, 1, 1, 1]}]))
    )
    np.testing.assert_allclose(grey(0.5)[:3], color.lab2rgb([[50.0, 0, 0]])[0], atol=1 / 255)


def test_categorical_maps_in_a_file_are_left_out_until_picked(tmp_path: Path) -> None:
    cat = {"Name": "KAAMS", "IndexedColors": [1, 1, 1, 1, 0, 0], "Annotations": ["0", "zero"]}
    path = write(tmp_path, "mixed.json", paraview_json([cat, *PARAVIEW_PRESETS]))
    assert TransferFunction.map_names(path) == ["Cool to Warm", "Black-Body Radiation", "X Ray"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert TransferFunction.load(path).name == "Cool to Warm"
    assert any("holds 3 maps" in str(w.message) for w in caught)
    with pytest.raises(SceneError, match="'KAAMS' is a categorical"):
        TransferFunction.load(f"{path}:KAAMS")
    with pytest.raises(SceneError, match="1 categorical or broken maps left out"):
        TransferFunction.load(f"{path}:nope")


def test_trailing_commas_as_in_paraviews_own_file(tmp_path: Path) -> None:
    text = '[\n  {\n    "Name": "X Ray",\n    "RGBPoints": [0, 1, 1, 1, 1, 0, 0, 0,]\n  },\n]\n'
    assert TransferFunction.load(write(tmp_path, "tc.json", text)).name == "X Ray"


#: VTK 9.7.2's vtkColorTransferFunction (SetColorSpaceTo<space>, AddRGBPoint, GetColor) at
#: a few x: name -> (ColorSpace, RGBPoints as (x, r, g, b), [[x, r, g, b], ...]).
VTK_COLOURS = {
    "Cool to Warm": (
        "Diverging",
        [
            (0, 0.23137254902, 0.298039215686, 0.752941176471),
            (0.5, 0.865, 0.865, 0.865),
            (1, 0.705882352941, 0.0156862745098, 0.149019607843),
        ],
        [
            [0.05, 0.290072, 0.384649, 0.82742],
            [0.15, 0.417015, 0.547998, 0.939854],
            [0.3, 0.622446, 0.746198, 0.999142],
            [0.45, 0.812704, 0.854156, 0.919695],
            [0.55, 0.914136, 0.836315, 0.793055],
            [0.7, 0.969594, 0.677194, 0.559698],
            [0.85, 0.893788, 0.427776, 0.3341],
            [0.95, 0.779139, 0.210043, 0.204745],
        ],
    ),
    "blue-red": (
        "Diverging",
        [(0, 0.1, 0.2, 0.9), (1, 0.9, 0.1, 0.1)],
        [
            [0.05, 0.369014, 0.324632, 1.0],
            [0.15, 0.579803, 0.48713, 1.0],
            [0.3, 0.7713, 0.692447, 1.0],
            [0.45, 0.938345, 0.911334, 1.0],
            [0.55, 1.0, 0.922956, 0.867071],
            [0.7, 1.0, 0.720228, 0.560771],
            [0.85, 1.0, 0.508734, 0.326693],
            [0.95, 0.99616, 0.308448, 0.18375],
        ],
    ),
    "lab": (
        "Lab",
        [(0, 0.05, 0.1, 0.4), (1, 0.95, 0.85, 0.2)],
        [
            [0.05, 0.153179, 0.129119, 0.398872],
            [0.15, 0.271685, 0.192449, 0.395426],
            [0.3, 0.407664, 0.295587, 0.386507],
            [0.45, 0.529127, 0.405573, 0.371593],
            [0.55, 0.606999, 0.481962, 0.357228],
            [0.7, 0.721852, 0.600522, 0.326537],
            [0.85, 0.835879, 0.723351, 0.279366],
            [0.95, 0.911911, 0.807395, 0.23213],
        ],
    ),
    "lab red-blue-green": (
        "Lab",
        [(0, 1, 0, 0), (0.3, 0, 0, 1), (1, 0, 1, 0)],
        [
            [0.05, 0.94199, 0.0, 0.233802],
            [0.15, 0.790313, 0.0, 0.535188],
            [0.3, 0.000299, 0.0, 1.0],
            [0.45, 0.402226, 0.322275, 0.853604],
            [0.55, 0.469107, 0.454188, 0.754167],
            [0.7, 0.489193, 0.638874, 0.596858],
            [0.85, 0.415425, 0.819422, 0.41202],
            [0.95, 0.266281, 0.939692, 0.232469],
        ],
    ),
    "step": (
        "Step",
        [(0, 1, 0, 0), (5, 0, 1, 0), (10, 0, 0, 1)],
        [
            [0.5, 0.0, 1.0, 0.0],
            [1.5, 0.0, 1.0, 0.0],
            [3.0, 0.0, 1.0, 0.0],
            [4.5, 0.0, 1.0, 0.0],
            [5.5, 0.0, 0.0, 1.0],
            [7.0, 0.0, 0.0, 1.0],
            [8.5, 0.0, 0.0, 1.0],
            [9.5, 0.0, 0.0, 1.0],
        ],
    ),
    "hsv rainbow": (
        "HSV",
        [(0, 0, 0, 1), (1, 1, 0, 0)],
        [
            [0.05, 0.0, 0.2, 1.0],
            [0.15, 0.0, 0.6, 1.0],
            [0.3, 0.0, 1.0, 0.8],
            [0.45, 0.0, 1.0, 0.2],
            [0.55, 0.2, 1.0, 0.0],
            [0.7, 0.8, 1.0, 0.0],
            [0.85, 1.0, 0.6, 0.0],
            [0.95, 1.0, 0.2, 0.0],
        ],
    ),
    "hsv wrapped": (  # HSVWrap on: the short way round the hue circle
        "HSV",
        [(0, 1, 0, 0.2), (1, 0.9, 0.2, 0)],
        [
            [0.05, 0.995, 0.0, 0.177994],
            [0.15, 0.985, 0.0, 0.134617],
            [0.3, 0.97, 0.0, 0.071133],
            [0.45, 0.955, 0.0, 0.00955],
            [0.55, 0.945, 0.03045, 0.0],
            [0.7, 0.93, 0.088867, 0.0],
            [0.85, 0.915, 0.145383, 0.0],
            [0.95, 0.905, 0.182006, 0.0],
        ],
    ),
}


@pytest.mark.parametrize("name", sorted(VTK_COLOURS))
def test_paraview_colour_spaces_match_vtk(tmp_path: Path, name: str) -> None:
    space, pts, expected = VTK_COLOURS[name]
    m = {"Name": name, "ColorSpace": space, "RGBPoints": [v for p in pts for v in p]}
    m["HSVWrap"] = "wrapped" in name
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # reproduced spaces: no "interpolated in RGB" note
        tf = TransferFunction.load(write(tmp_path, "m.json", paraview_json([m])))
    for x, *rgb in expected:
        np.testing.assert_allclose(tf(x)[:3], rgb, atol=1 / 255, err_msg=f"{name} at {x}")


def test_vtk_itself_agrees_when_installed() -> None:
    """With vtk installed (the bench extra), the same comparison on a fine grid."""
    vtk = pytest.importorskip("vtk")
    for name, (space, pts, _) in VTK_COLOURS.items():
        ctf = vtk.vtkColorTransferFunction()
        getattr(ctf, f"SetColorSpaceTo{space}")()
        ctf.SetHSVWrap("wrapped" in name)
        for p in pts:
            ctf.AddRGBPoint(*p)
        col = np.asarray(pts, dtype=float)
        wrap = "wrapped" in name
        col = (
            tf_curves.step(col)
            if space == "Step"
            else tf_curves.subdivided(col, space, hsv_wrap=wrap)
        )
        tf = TransferFunction([(r[0], *r[1:], 0.5) for r in col])
        xs = np.linspace(pts[0][0], pts[-1][0], 200)[1:-1]  # not on the nodes (steps)
        want = np.array([ctf.GetColor(float(x)) for x in xs])
        np.testing.assert_allclose(tf(xs)[:, :3], want, atol=1 / 255, err_msg=name)


def test_single_paraview_object_and_voxwarp_json_still_load(tmp_path: Path) -> None:
    one = write(tmp_path, "one.json", json.dumps(PARAVIEW_PRESETS[2]))
    assert TransferFunction.load(one).name == "X Ray"
    own = write(tmp_path, "own.json", json.dumps({"preset": "viridis"}))
    assert TransferFunction.load(own, hu_volume()).name == "viridis"
    assert TransferFunction.map_names(own) == []


# ---------------------------------------------------------------------------- matplotlib
def test_colormap_name_gives_its_colours_and_a_rising_opacity() -> None:
    import matplotlib

    vol = hu_volume()
    lo, hi = window(vol)
    for name in ("viridis", "magma_r", "gray", "jet", "twilight"):
        tf = TransferFunction.preset(name, vol)
        cmap = matplotlib.colormaps[name]
        pts = np.asarray(tf.points)
        assert len(pts) <= 40  # editable in the GUI: far fewer than the map's N colours
        t = np.linspace(0.0, 1.0, cmap.N)  # every colour of the map, within 1/255
        np.testing.assert_allclose(tf(lo + t * (hi - lo))[:, :3], cmap(t)[:, :3], atol=1 / 255)
        assert np.all(np.diff(pts[:, 4]) >= 0)
        assert pts[0, 4] == 0.0
        assert pts[-1, 4] == pytest.approx(tf_formats.RAMP_OPACITY)
    assert len(TransferFunction.preset("gray", vol).points) == 2  # a straight map: 2 points
    # reversed maps as matplotlib has them
    fwd, rev = TransferFunction.preset("viridis", vol), TransferFunction.preset("viridis_r", vol)
    np.testing.assert_allclose(rev(lo)[:3], fwd(hi)[:3], atol=1e-9)
    np.testing.assert_allclose(rev(hi)[:3], fwd(lo)[:3], atol=1e-9)


def test_small_listed_colormap_keeps_all_its_colours() -> None:
    import matplotlib

    tf = TransferFunction.preset("tab10", hu_volume())
    colours = np.asarray(matplotlib.colormaps["tab10"].colors)
    np.testing.assert_allclose(np.asarray(tf.points)[:, 1:4], colours, atol=1e-9)


def test_presets_win_and_scene_json_accepts_colormap_names() -> None:
    vol = hu_volume()
    assert TransferFunction.coerce("hot", vol).points == TransferFunction.preset("hot", vol).points
    assert len(TransferFunction.coerce("hot", vol).points) == 4  # voxwarp's hot, not matplotlib's
    tf = TransferFunction.from_dict({"preset": "cividis"}, vol)
    assert tf.name == "cividis"
    assert TransferFunction.coerce("cividis", vol).points == tf.points


def test_colormap_without_matplotlib_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tfmod, "colormaps_available", lambda: False)
    with pytest.raises(SceneError) as info:
        TransferFunction.preset("viridis")
    msg = str(info.value)
    assert "pip install 'voxwarp[teach]'" in msg
    assert "\n" not in msg
    for name in PRESETS:
        assert name in msg


def test_unknown_name_lists_presets_and_suggests() -> None:
    with pytest.raises(SceneError) as info:
        TransferFunction.preset("virdis")
    msg = str(info.value)
    assert "\n" not in msg
    assert "did you mean viridis" in msg
    assert "ct-bone" in msg
    assert "matplotlib colour-map name" in msg


# ---------------------------------------------------------------------------- specs
def test_file_spec_rules(tmp_path: Path) -> None:
    path = write(tmp_path, "presets.xml", PRESETS_XML)
    assert file_spec("viridis") is None
    assert file_spec("ct-bone") is None
    assert file_spec(path) == (path, None)
    assert file_spec(f"{path}:CT-Bone") == (path, "CT-Bone")
    assert file_spec("missing.json") == ("missing.json", None)
    assert file_spec("missing.xml:CT-Bone") == ("missing.xml", "CT-Bone")
    assert file_spec("dir/tf") == ("dir/tf", None)


# ---------------------------------------------------------------------------- hostile input
_OK_COLOUR = "8 0 0 0 0 1 1 1 1"
HOSTILE_XML = {
    "huge N": ('<MRML><VolumeProperty name="x" scalarOpacity="999999999 0 0 1 1"'
               f' colorTransfer="{_OK_COLOUR}"/></MRML>', "499,999,999 points; .* at most 65,536"),
    "N of 40 digits": ('<MRML><VolumeProperty name="x" scalarOpacity="' + "9" * 40
                       + f' 0 0" colorTransfer="{_OK_COLOUR}"/></MRML>', "too large"),
    "N not matching": ('<MRML><VolumeProperty name="x" scalarOpacity="6 0 0 1 1"'
                       f' colorTransfer="{_OK_COLOUR}"/></MRML>', "says 6 numbers but has 4"),
    "NaN": ('<MRML><VolumeProperty name="x" scalarOpacity="4 0 nan 1 1"'
            f' colorTransfer="{_OK_COLOUR}"/></MRML>', "not a number"),
    "inf": ('<MRML><VolumeProperty name="x" scalarOpacity="4 0 0 1e999 1"'
            f' colorTransfer="{_OK_COLOUR}"/></MRML>', "finite"),
    "word": ('<MRML><VolumeProperty name="x" scalarOpacity="4 0 zero 1 1"'
             f' colorTransfer="{_OK_COLOUR}"/></MRML>', "not a number"),
    "opacity 1.5": ('<MRML><VolumeProperty name="x" scalarOpacity="4 0 0 1 1.5"'
                    f' colorTransfer="{_OK_COLOUR}"/></MRML>', r"\[0, 1\]"),
    "negative colour": ('<MRML><VolumeProperty name="x" scalarOpacity="4 0 0 1 1"'
                        ' colorTransfer="8 0 -0.1 0 0 1 1 1 1"/></MRML>', r"\[0, 1\]"),
    "x decreasing": ('<MRML><VolumeProperty name="x" scalarOpacity="4 5 0 1 1"'
                     f' colorTransfer="{_OK_COLOUR}"/></MRML>', "must not decrease"),
    "odd count": ('<MRML><VolumeProperty name="x" scalarOpacity="3 0 0 1"'
                  f' colorTransfer="{_OK_COLOUR}"/></MRML>', "groups of 2"),
    "empty opacity": ('<MRML><VolumeProperty name="x" scalarOpacity=""'
                      f' colorTransfer="{_OK_COLOUR}"/></MRML>', "empty"),
    "no colour": ('<MRML><VolumeProperty name="x" scalarOpacity="4 0 0 1 1"/></MRML>',
                  "no colorTransfer"),
    "no VolumeProperty": ("<MRML><Other/></MRML>", "no <VolumeProperty>"),
    "not XML": ("<MRML><VolumeProperty", "not well-formed"),
    "entities": ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">'
                 '<!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">]>'
                 '<MRML><VolumeProperty name="&lol2;"/></MRML>', "DTD or entities"),
}  # fmt: skip

HOSTILE_JSON = {
    "categorical": ([{"Name": "cat", "IndexedColors": [1, 0, 0, 0, 1, 0]}], "categorical"),
    "RGBPoints 5 numbers": ([{"Name": "a", "RGBPoints": [0, 1, 1, 1, 1]}], "groups of 4"),
    "RGBPoints strings": ([{"Name": "a", "RGBPoints": ["x", 1, 1, 1]}], "not a number"),
    "RGBPoints null": ([{"Name": "a", "RGBPoints": [None, 1, 1, 1]}], "not a number"),
    "RGBPoints not a list": ([{"Name": "a", "RGBPoints": 5}], "no RGBPoints list"),
    "Points not a list": ([{"Name": "a", "RGBPoints": [0, 0, 0, 0], "Points": {}}], "Points"),
    "colour 2": ([{"Name": "a", "RGBPoints": [0, 2, 0, 0]}], r"\[0, 1\]"),
    "x decreasing": ([{"Name": "a", "RGBPoints": [1, 0, 0, 0, 0, 1, 1, 1]}], "must not decrease"),
    "empty list of maps": ([], "control point"),
    "every map broken": (
        [{"Name": "a", "RGBPoints": 5}, {"Name": "b", "IndexedColors": [1, 0, 0]}],
        "no RGBPoints list",
    ),
    "one non-map": ([5, {"Name": "a", "RGBPoints": "x"}], "not a JSON object"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE_XML))
def test_hostile_slicer_xml_is_one_line(tmp_path: Path, case: str) -> None:
    text, pattern = HOSTILE_XML[case]
    path = write(tmp_path, "presets.xml", text)
    with pytest.raises(SceneError, match=pattern) as info:
        TransferFunction.load(path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("case", sorted(HOSTILE_JSON))
def test_hostile_paraview_json_is_one_line(tmp_path: Path, case: str) -> None:
    doc, pattern = HOSTILE_JSON[case]
    path = write(tmp_path, "map.json", json.dumps(doc))
    with pytest.raises(SceneError, match=pattern) as info:
        TransferFunction.load(path)
    assert "\n" not in str(info.value)


def test_hostile_files_are_one_line(tmp_path: Path) -> None:
    junk = tmp_path / "junk.xml"
    junk.write_bytes(bytes(range(256)) * 4)
    latin = tmp_path / "latin.vp"
    latin.write_bytes(b"1\n\xe9\xe9\n")
    short = write(tmp_path, "short.vp", "1\n1\n0.9\n")
    big = tmp_path / "big.json"
    with open(big, "wb") as fh:  # a sparse 1 GB file: refused by its size, not read
        fh.truncate(1 << 30)
    cases = {
        str(junk): "binary",
        str(latin): "not UTF-8",
        short: "9 lines",
        str(big): "at most 32 MB",
        str(tmp_path): "folder",
        str(tmp_path / "none.xml"): "no such transfer function file",
        write(tmp_path, "empty.xml", "  \n"): "empty",
    }
    for path, pattern in cases.items():
        t0 = time.perf_counter()
        with pytest.raises(SceneError, match=pattern) as info:
            TransferFunction.load(path)
        assert time.perf_counter() - t0 < 1.0
        assert "\n" not in str(info.value)


def test_billion_laughs_is_refused_quickly(tmp_path: Path) -> None:
    ents = "".join(f'<!ENTITY l{i} "{("&l" + str(i - 1) + ";") * 10}">' for i in range(1, 10))
    text = f'<?xml version="1.0"?><!DOCTYPE m [<!ENTITY l0 "ha">{ents}]><MRML>&l9;</MRML>'
    path = write(tmp_path, "laughs.xml", text)
    t0 = time.perf_counter()
    with pytest.raises(SceneError, match="DTD"):
        TransferFunction.load(path)
    assert time.perf_counter() - t0 < 1.0


def test_slicer_presets_keep_their_data_units() -> None:
    maps = tf_formats.slicer_presets(PRESETS_XML, "presets.xml")
    assert [m.name for m in maps] == ["CT-AAA", "CT-Bone", "MR-Default"]
    assert all(m.unit_distance == 1.0 for m in maps)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pts, mapped = tf_formats.to_control_points(maps[1], (-1000.0, 2000.0), 1.0)
    assert not mapped  # Slicer presets keep their data units (HU)
    assert pts[0][0] == -3024
    assert pts[-1][0] == 3071


def test_the_docs_snippets_load(tmp_path: Path) -> None:
    """docs/transfer-functions.md's ParaView and Slicer examples are valid files."""
    import re

    page = Path(__file__).resolve().parents[2] / "docs" / "transfer-functions.md"
    blocks = dict(re.findall(r"```(json|xml)\n(.*?)```", page.read_text(encoding="utf-8"), re.S))
    vol = hu_volume()
    pv = TransferFunction.load(write(tmp_path, "bb.json", blocks["json"]), vol)
    assert pv.name == "Black-Body Radiation"
    lo, hi = window(vol)
    np.testing.assert_allclose(pv(lo + 0.4 * (hi - lo))[:3], (0.901960784314, 0, 0), atol=1e-9)
    bone = TransferFunction.load(write(tmp_path, "ct-bone.xml", blocks["xml"]) + ":CT-Bone", vol)
    for x, r, g, b in CT_BONE_COLOUR:
        np.testing.assert_allclose(bone(x)[:3], (r, g, b), atol=1e-9)


def test_a_map_name_may_hold_a_colon(tmp_path: Path) -> None:
    """``FILE:NAME`` splits after the shortest existing file, so ``maps.json:a:b`` picks
    the map called ``a:b`` (and a folder with ':' in its name still works)."""
    folder = tmp_path / "my:maps"
    folder.mkdir()
    maps = [
        {"Name": "a", "ColorSpace": "RGB", "RGBPoints": [0, 1, 0, 0, 1, 1, 0, 0]},
        {"Name": "a:b", "ColorSpace": "RGB", "RGBPoints": [0, 0, 0, 1, 1, 0, 0, 1]},
    ]
    path = write(folder, "maps.json", json.dumps(maps))
    assert file_spec(f"{path}:a:b") == (path, "a:b")
    tf = TransferFunction.load(f"{path}:a:b")
    assert tf(0.5)[:3].tolist() == [0.0, 0.0, 1.0]


@pytest.mark.parametrize("text", ["[]", "{}", '{"points": [[0, 2, 0, 0, 0]]}'])
def test_errors_about_a_voxwarp_json_file_name_it(tmp_path: Path, text: str) -> None:
    path = write(tmp_path, "tf.json", text)
    with pytest.raises(SceneError) as info:
        TransferFunction.load(path)
    assert str(info.value).startswith(f"{path}: ")
    assert "\n" not in str(info.value)
