"""Optional dependency groups (pip *extras*) and the one-line error when one is missing.

Core voxwarp renders headless and runs every deformation family; the rest is optional:
``gui`` (PySide6), ``movie`` (imageio-ffmpeg, tqdm), ``distributed`` (dask, distributed),
``teach`` (matplotlib, Pillow), ``dicom`` (pylibjpeg and its JPEG, JPEG 2000 and RLE
decoders, for compressed DICOM), ``registration`` (SimpleITK: ITK transform files,
MetaImage fields, the registration demo), ``segmentation`` (scikit-image: meshes from
label volumes), ``notebook`` (jupyter_rfb, ipywidgets: the Jupyter Viewer), ``napari``
(napari, npe2: the napari plugin), ``docs`` (mkdocs and its plugins: ``make docs``) and
``all``. Call :func:`require` where a feature starts,
so a user learns which extra to install before any work is done.
"""

from __future__ import annotations

import importlib.util

from voxwarp.errors import MissingExtraError

#: extra -> the modules it provides
EXTRAS: dict[str, tuple[str, ...]] = {
    "gui": ("PySide6",),
    "movie": ("imageio_ffmpeg", "tqdm"),
    "distributed": ("dask", "distributed"),
    "teach": ("matplotlib", "PIL"),
    "dicom": ("pylibjpeg", "libjpeg", "openjpeg", "rle"),
    "registration": ("SimpleITK",),
    "segmentation": ("skimage",),
    "notebook": ("jupyter_rfb", "ipywidgets"),
    "napari": ("napari", "npe2"),
    "docs": ("mkdocs", "material", "mkdocstrings"),
}


def missing(extra: str) -> list[str]:
    """The modules of ``extra`` that cannot be imported here."""
    return [m for m in EXTRAS[extra] if importlib.util.find_spec(m) is None]


def require(extra: str, what: str) -> None:
    """Raise :class:`~voxwarp.errors.MissingExtraError` unless ``extra`` is installed.

    ``what`` names the feature, e.g. ``require("gui", "voxwarp gui")`` gives
    ``voxwarp gui needs the gui extra: pip install 'voxwarp[gui]'``.
    """
    absent = missing(extra)
    if absent:
        raise MissingExtraError(
            f"{what} needs the {extra} extra (missing: {', '.join(absent)}):"
            f" pip install 'voxwarp[{extra}]'"
        )
