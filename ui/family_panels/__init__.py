"""One panel per deformation family, registered by name (as the adapters of
:mod:`voxwarp.editing.families`): :class:`~voxwarp.ui.panels.DeformationPanel` and the
scene tree look the current family up here and never switch on it.

A new family: a :class:`~voxwarp.ui.family_panels.base.FamilyPanel` subclass in a file
here (its labels, Model-group options, group boxes, refresh, window actions) and its
entry below.
Usage: ``FAMILY_PANELS[session.kind]``; :func:`family_label` names a family.
"""

from __future__ import annotations

from voxwarp.ui.family_panels.base import FamilyPanel, PanelAction
from voxwarp.ui.family_panels.elements import ElementsPanel
from voxwarp.ui.family_panels.lattice import LatticePanel
from voxwarp.ui.family_panels.options import ModelOptions
from voxwarp.ui.family_panels.wires import WiresPanel

__all__ = ["FAMILY_PANELS", "FamilyPanel", "ModelOptions", "PanelAction", "family_label"]

#: family name -> panel class (one class may serve several families: see its ``labels``)
FAMILY_PANELS: dict[str, type[FamilyPanel]] = {
    kind: cls
    for cls in (FamilyPanel, ElementsPanel, WiresPanel, LatticePanel)
    for kind in cls.labels
}


def family_label(kind: str) -> str:
    """Human name of family ``kind`` (the name itself when no panel knows it)."""
    cls = FAMILY_PANELS.get(kind)
    return kind if cls is None else cls.labels[kind]
