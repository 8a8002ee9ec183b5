"""Bundled sample volumes as :class:`~app.volume.Volume` objects.

Wraps :mod:`sample_volumes` (generators and bundled real scans, numpy only). A sample
volume's ``source`` is ``"sample:NAME"`` so scene JSON can refer to it by name.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from app.errors import VolumeError
from app.volume import Volume

#: The sample `make run` and `voxwarp demo` render by default.
DEFAULT_SAMPLE = "stent"


def sample_names() -> list[str]:
    """Names accepted by :func:`load_sample`."""
    import sample_volumes

    return list(sample_volumes.names())


def load_sample(
    name: str,
    spacing: Sequence[float] | None = None,
    origin: Sequence[float] | None = None,
    **kwargs: Any,
) -> Volume:
    """Generate or load the bundled sample ``name`` (see ``sample_volumes/README.md``).

    ``kwargs`` go to the generator (``shape``, ``seed``) for synthetic phantoms.
    """
    import sample_volumes

    if name not in sample_volumes.names():
        raise VolumeError(
            f"unknown sample {name!r}; bundled samples: {', '.join(sample_volumes.names())}"
        )
    s = sample_volumes.get(name, **kwargs)
    return Volume(
        s.data,
        spacing if spacing is not None else s.spacing,
        origin if origin is not None else (0.0, 0.0, 0.0),
        name=name,
        source=f"sample:{name}",
        units=s.units,
    )
