"""numba's parallel kernels launched from several threads at once.

numba runs ``parallel=True`` kernels on a *threading layer*: TBB or OpenMP where their
libraries load, else its own *workqueue* (a machine without ``libgomp``, macOS without
``libomp``, or ``NUMBA_THREADING_LAYER=workqueue``). The workqueue layer is not
thread-safe: when two threads launch parallel kernels at the same time it terminates the
whole process ("Concurrent access has been detected"). voxwarp launches them from the
GUI thread and from its background workers (skip maps, model steps), so its parallel
kernels are wrapped in :func:`threadsafe`: under workqueue their launches take turns
(one lock); under TBB and OpenMP, which are thread-safe, they run as they come.

Use::

    @threadsafe
    @njit(parallel=True, nogil=True)
    def kernel(a): ...

and call ``kernel(a)`` from Python as before (``kernel.kernel`` is the numba dispatcher,
for jitted callers).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import Any

#: held around each parallel launch while the threading layer is workqueue (or not yet
#: chosen: numba picks it at the first parallel launch of the process)
_LOCK = threading.Lock()
_threadsafe_layer: bool | None = None


def layer_is_threadsafe() -> bool | None:
    """Whether numba's threading layer may be entered by several threads at once: True
    for TBB and OpenMP, False for workqueue, None before any parallel kernel has run."""
    global _threadsafe_layer
    if _threadsafe_layer is None:
        import numba

        try:
            _threadsafe_layer = numba.threading_layer() != "workqueue"
        except ValueError:  # no parallel launch yet: the layer is not chosen
            return None
    return _threadsafe_layer


def threadsafe(kernel: Any) -> Callable[..., Any]:
    """``kernel`` (a ``parallel=True`` numba dispatcher) behind a launcher that lets no
    two threads run it, or another wrapped kernel, at once unless the threading layer is
    thread-safe. The launcher keeps the kernel's name and docstring."""

    @functools.wraps(kernel.py_func)
    def launch(*args: Any, **kwargs: Any) -> Any:
        if layer_is_threadsafe():
            return kernel(*args, **kwargs)
        with _LOCK:
            return kernel(*args, **kwargs)

    launch.kernel = kernel  # type: ignore[attr-defined]
    return launch
