"""Compressed field files that inflate far past their size: refused before inflating.

A displacement field is a smooth but noisy float array; gzip or deflate shrink one a
few-fold. A 1.2 MB ``.nii.gz`` whose header claims 1.2 GB of vectors (all zeros,
1000-fold) would keep a reader busy for minutes inside the memory budget. Readers of
compressed fields (``.nii.gz``, gzip/bzip2 NRRD, deflated ``.npz`` members, compressed
MetaImage) call :func:`check_inflation` with the header's size before inflating.
"""

from __future__ import annotations

from voxwarp.core.limits import format_bytes
from voxwarp.errors import FieldError

#: Most a compressed field may inflate (bytes of data / bytes stored), ...
MAX_INFLATION = 100
#: ... once the inflated data exceeds this many bytes (small files are always read).
INFLATION_FLOOR = 64 << 20


def check_inflation(need: int, stored: int, what: str) -> None:
    """Refuse ``need`` bytes of data inflated from ``stored`` bytes when that is more
    than :data:`MAX_INFLATION`-fold and over :data:`INFLATION_FLOOR`; one line naming
    the estimate and the fix (write the field uncompressed)."""
    if need <= INFLATION_FLOOR or need <= MAX_INFLATION * max(stored, 1):
        return
    raise FieldError(
        f"{what}: its header claims {format_bytes(need)} of data inflating"
        f" {need / max(stored, 1):,.0f}-fold from {format_bytes(stored)} (a real field"
        f" compresses at most a few-fold; the limit is {MAX_INFLATION}-fold): the file is"
        " damaged or a decompression bomb; if it is genuine, write it uncompressed"
    )
