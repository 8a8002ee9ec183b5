"""The panel of the lattice family: only the Model group's resolution (nodes per axis);
the nodes are dragged in the viewport."""

from __future__ import annotations

from typing import ClassVar

from voxwarp.editing.families.lattice import LatticeFamily
from voxwarp.editing.session import EditSession
from voxwarp.ui.family_panels.base import FamilyPanel

__all__ = ["LatticePanel"]


class LatticePanel(FamilyPanel):
    """A lattice of trilinear cells: no widgets of its own."""

    labels: ClassVar[dict[str, str]] = {"lattice": "lattice"}
    options: ClassVar[dict[str, tuple[str, ...]]] = {"lattice": ("resolution",)}
    editable = True

    @classmethod
    def summary(cls, s: EditSession) -> str:
        """The family and its cells per axis."""
        nodes = s.adapter(LatticeFamily).lattice_nodes
        return cls.sized(s, None if nodes is None else [n - 1 for n in nodes.shape[:3]], "cells")
