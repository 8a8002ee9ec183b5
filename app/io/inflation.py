"""Compressed field files that inflate like a decompression bomb: refused before inflating.

A 1.2 MB ``.nii.gz`` whose header claims 1.2 GB of vectors (all zeros) kept a reader
busy for minutes. Deflate (gzip, zip, MetaImage's zlib) cannot shrink anything more than
about 1032-fold, and only runs of one byte get near that; a genuine field does not: noisy
vectors shrink 3-15-fold, a field with compact support (zero outside a ball, as a local
deformation exported to a large grid) measured 433-fold. bzip2 goes much further on
zeros (600,000-fold) while a compact-support field measured 4,200-fold. Readers of
compressed fields (``.nii.gz``, gzip/bzip2 NRRD, deflated ``.npz`` members, compressed
MetaImage) call :func:`check_inflation` with the header's size before inflating.
"""

from __future__ import annotations

from voxwarp.core.limits import format_bytes
from voxwarp.errors import FieldError

#: Most a compressed field may inflate (bytes of data / bytes stored), by codec: below
#: what only near-constant data reaches (deflate's ceiling is ~1032), above genuine fields.
MAX_INFLATION = {"deflate": 900, "bzip2": 50_000}
#: Fields whose data is at most this many bytes are always read, whatever their ratio.
INFLATION_FLOOR = 256 << 20


def check_inflation(need: int, stored: int, what: str, codec: str = "deflate") -> None:
    """Refuse ``need`` bytes of data inflated from ``stored`` bytes when that is more than
    :data:`MAX_INFLATION` ``[codec]``-fold and over :data:`INFLATION_FLOOR`; one line
    naming the estimate and the fix (write the field uncompressed)."""
    limit = MAX_INFLATION[codec]
    if need <= INFLATION_FLOOR or need <= limit * max(stored, 1):
        return
    raise FieldError(
        f"{what}: its header claims {format_bytes(need)} of data inflating"
        f" {need / max(stored, 1):,.0f}-fold from {format_bytes(stored)}; {codec} data"
        f" inflating over {limit:,}-fold is near-constant (a genuine field compresses far"
        " less): the file is damaged or a decompression bomb; if it is genuine, write it"
        " uncompressed"
    )
