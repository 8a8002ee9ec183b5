"""A bool array kept at one bit per element (``np.packbits``): how a volume keeps its cell
visibility between octant-map builds, an eighth of the bool array's bytes (a 512³ volume's
cells: 16 MiB instead of 128 MiB).

``BitMask(mask).unpack()`` gives back an equal array in the same memory order
(Fortran-ordered masks, the texture-order views the skip maps use, stay so).
"""

from __future__ import annotations

import numpy as np


class BitMask:
    """``mask`` (any shape, cast to bool) at one bit per element."""

    def __init__(self, mask: np.ndarray) -> None:
        mask = np.asarray(mask, dtype=bool)
        self.shape = mask.shape
        self.fortran = bool(mask.flags.f_contiguous and not mask.flags.c_contiguous)
        order = "F" if self.fortran else "C"
        self.bits = np.packbits(mask.ravel(order=order).view(np.uint8))
        #: how many elements are set
        self.count = int(np.count_nonzero(mask))

    @property
    def fraction(self) -> float:
        """The share of the elements that are set (0..1; 0 for an empty mask)."""
        return self.count / max(int(np.prod(self.shape)), 1)

    @property
    def nbytes(self) -> int:
        """Bytes held."""
        return int(self.bits.nbytes)

    def unpack(self) -> np.ndarray:
        """The bool array, of the mask's shape and memory order (a new array)."""
        size = int(np.prod(self.shape))
        flat = np.unpackbits(self.bits, count=size).view(bool)
        return flat.reshape(self.shape, order="F" if self.fortran else "C")
