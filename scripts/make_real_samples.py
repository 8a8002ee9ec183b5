"""Convert the real scans bundled in ``sample_volumes/`` from their upstream files.

Not used at runtime: ``sample_volumes`` only reads the files this script writes.
Re-runnable; each output is rewritten from scratch.

stent
    The CT of a stented aorta shipped in the visvis wheel (``pip install visvis``), file
    ``visvis/visvisResources/stent_vol.ssdf`` (BSD-3-Clause, Copyright (c) 2012-2025,
    Visvis development team). It is read with the pure-Python ``ssdf`` module that
    visvis vendors (``visvis/utils/ssdf``), put on ``sys.path`` by this script only. The
    file holds ``vol``, a ``uint8`` array ``(256, 128, 128)`` in ``(z, y, x)`` order with
    values 0..32, plus ``colorscale`` (62.5) and ``ncolors`` (32); it has no voxel
    spacing or origin. Written as ``sample_volumes/stent.npz`` with keys ``data``
    (``uint8``, transposed to ``(x, y, z)`` = ``(128, 128, 256)``), ``spacing``
    ``(1, 1, 1)`` (unknown; a placeholder), ``origin`` ``(0, 0, 0)`` and ``units`` ``""``.

colin27
    The Colin27 average T1 MRI ``ch2.nii.gz`` from Debian's ``mricron-data`` package
    (``usr/share/mricron/templates/ch2.nii.gz``; BSD-3-Clause per the package's
    copyright file). It is 3.5 MB, over the 3 MB budget per bundled file, so it is
    block-averaged by 2 (edges replicated to even sizes): ``uint8`` ``(181, 217, 181)``
    at 1 mm becomes ``(91, 109, 91)`` at 2 mm, written as
    ``sample_volumes/colin27_mri.npz`` with keys ``data``, ``spacing`` ``(2, 2, 2)``,
    ``origin`` (world position of voxel 0 in MNI mm, from the NIfTI affine, which is
    diagonal RAS) and ``units`` ``""``. Get the package with::

        cd /tmp && apt-get download mricron-data && dpkg -x mricron-data_*.deb mricron

Usage::

    python scripts/make_real_samples.py [--visvis DIR] [--mricron DIR]

``--visvis`` is the installed ``visvis`` package directory (found by importlib when
omitted; visvis itself is not imported); ``--mricron`` is the directory the Debian
package was extracted into (``/tmp/mricron`` by default). A missing source is skipped
with a message.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

import numpy as np

OUT_DIR = Path(__file__).resolve().parent.parent / "sample_volumes"
MAX_BYTES = 3 * 1024 * 1024


def find_visvis() -> Path | None:
    """The installed visvis package directory, located without importing visvis."""
    spec = importlib.util.find_spec("visvis")
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def make_stent(visvis_dir: Path, out_dir: Path = OUT_DIR) -> Path:
    """Write ``stent.npz`` from visvis' ``stent_vol.ssdf``; returns the written path."""
    sys.path.insert(0, str(visvis_dir / "utils"))
    try:
        import ssdf  # type: ignore[import-not-found]
    finally:
        sys.path.pop(0)
    s = ssdf.load(str(visvis_dir / "visvisResources" / "stent_vol.ssdf"))
    vol = np.asarray(s.vol)
    if vol.shape != (256, 128, 128) or vol.dtype != np.uint8:
        raise ValueError(f"unexpected stent volume {vol.shape} {vol.dtype}")
    data = np.ascontiguousarray(vol.transpose(2, 1, 0))  # (z, y, x) -> (x, y, z)
    out = out_dir / "stent.npz"
    np.savez_compressed(
        out,
        data=data,
        spacing=np.array([1.0, 1.0, 1.0]),
        origin=np.array([0.0, 0.0, 0.0]),
        units=np.array(""),
    )
    return out


def block_mean2(data: np.ndarray) -> np.ndarray:
    """Average 2x2x2 blocks (odd sizes padded by replicating the last slice), rounded."""
    pad = [(0, n % 2) for n in data.shape]
    a = np.pad(data.astype(np.float32), pad, mode="edge")
    nx, ny, nz = (n // 2 for n in a.shape)
    a = a.reshape(nx, 2, ny, 2, nz, 2).mean(axis=(1, 3, 5))
    return np.rint(a).astype(data.dtype)


def make_colin27(mricron_dir: Path, out_dir: Path = OUT_DIR) -> Path:
    """Bundle Colin27 (``ch2.nii.gz``): as is if < 3 MB, else 2x block-averaged npz."""
    import nibabel as nib

    src = mricron_dir / "usr" / "share" / "mricron" / "templates" / "ch2.nii.gz"
    if src.stat().st_size < MAX_BYTES:
        out = out_dir / "colin27_mri.nii.gz"
        out.write_bytes(src.read_bytes())
        return out
    img = nib.load(str(src))
    aff = img.affine
    if not np.allclose(aff[:3, :3], np.diag(np.diag(aff[:3, :3]))) or np.any(np.diag(aff) <= 0):
        raise ValueError(f"expected a diagonal RAS affine, got\n{aff}")
    data = np.asanyarray(img.dataobj)
    if data.dtype != np.uint8:
        raise ValueError(f"expected uint8 data, got {data.dtype}")
    small = block_mean2(data)
    zooms = np.diag(aff)[:3]
    origin = aff[:3, 3] + 0.5 * zooms  # centre of the first 2x2x2 block
    out = out_dir / "colin27_mri.npz"
    np.savez_compressed(
        out,
        data=small,
        spacing=2.0 * zooms,
        origin=origin,
        units=np.array(""),
    )
    return out


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--visvis", type=Path, default=None, help="installed visvis package dir")
    ap.add_argument("--mricron", type=Path, default=Path("/tmp/mricron"), help="extracted deb")
    args = ap.parse_args(argv)
    visvis_dir = args.visvis or find_visvis()
    if visvis_dir is not None and (visvis_dir / "visvisResources" / "stent_vol.ssdf").exists():
        out = make_stent(visvis_dir)
        print(f"wrote {out} ({out.stat().st_size} bytes)")
    else:
        print("visvis not found: stent skipped (pip install visvis, or pass --visvis)")
    if (args.mricron / "usr/share/mricron/templates/ch2.nii.gz").exists():
        out = make_colin27(args.mricron)
        print(f"wrote {out} ({out.stat().st_size} bytes)")
    else:
        print(f"no ch2.nii.gz under {args.mricron}: colin27 skipped (see the docstring)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
