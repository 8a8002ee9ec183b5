"""Jupyter support: the interactive :class:`Viewer` widget (``pip install voxwarp[notebook]``)."""
