"""numpy's transparent huge pages, off unless asked for.

numpy asks the kernel for transparent huge pages (``madvise``) on every array of
4 MB or more. Where the kernel compacts memory to find them when such an array is
first touched (``/sys/kernel/mm/transparent_hugepage/defrag`` set to ``madvise``, a
common default), a step that allocates a few hundred MB stalls in the kernel for
seconds, and by how long depends on how fragmented memory is, not on the work (the
numbers are in ``docs/benchmarks.md``, "numpy's huge pages"). ``import voxwarp``
turns them off unless ``NUMPY_MADVISE_HUGEPAGE`` is set: numpy's own switch, so
``NUMPY_MADVISE_HUGEPAGE=1`` keeps them.
"""

from __future__ import annotations

import os
import sys

#: numpy's environment switch (read when numpy is imported)
ENV_VAR = "NUMPY_MADVISE_HUGEPAGE"


def small_pages() -> None:
    """Turn numpy's huge pages off, unless :data:`ENV_VAR` says otherwise: before numpy
    is imported through the environment (its subprocesses inherit it), after that
    through numpy's setter."""
    if ENV_VAR in os.environ:
        return
    numpy = sys.modules.get("numpy")
    if numpy is None:
        os.environ[ENV_VAR] = "0"
        return
    core = getattr(numpy, "_core", None) or getattr(numpy, "core", None)
    setter = getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)
    if setter is not None:
        setter(False)
