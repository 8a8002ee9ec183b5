"""The lattice family (Knuth et al., GRAPP 2010): a grid of trilinear cells over the
volume's box; the handles are its nodes."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from voxwarp.deform.lattice.trilinear import TrilinearGrid
from voxwarp.deform.lattice.warp import LatticeWarp
from voxwarp.deform.warp import Warp
from voxwarp.editing.common import COLORS, DisplayOptions
from voxwarp.editing.families.base import Family, ToWorld
from voxwarp.editing.keyframes import json_values, put_key, track
from voxwarp.editing.model_settings import BuildReport, Built, LatticeSettings
from voxwarp.editing.state import DragState, SessionHost
from voxwarp.inputs import load_lattice_file
from voxwarp.render.overlay import OverlayLayer, grid_edges

if TYPE_CHECKING:
    from voxwarp.animation.tracks import Animation

#: most cells per axis of a new lattice
MAX_CELLS = 8


class LatticeFamily(Family):
    """A trilinear lattice; its warp is rebuilt lazily after the nodes move."""

    kind = "lattice"
    has_grid = True
    handle_name = "lattice nodes"

    def __init__(self, session: SessionHost) -> None:
        super().__init__(session)
        self.nodes: np.ndarray | None = None
        self._warp: LatticeWarp | None = None

    @property
    def lattice_nodes(self) -> np.ndarray | None:
        """The lattice's nodes (nx, ny, nz, 3), grid frame; None before :meth:`start`."""
        return self.nodes

    def set_lattice_nodes(self, nodes: np.ndarray) -> None:
        """Move every node of the lattice (shape of :attr:`lattice_nodes`); the scene's
        warps follow."""
        self.set_nodes(nodes)
        self.session.sync_warps()

    def start(self) -> None:
        """An undeformed lattice of ``resolution - 1`` cells per axis (at most 8)."""
        cells = tuple(min(r - 1, MAX_CELLS) for r in self.session.resolution)
        lo, hi = self.session.box
        axes = (np.linspace(0.0, 1.0, c + 1) for c in cells)
        u = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
        self.set_nodes(lo + u * (hi - lo))

    def close(self) -> None:
        self.release(self._warp)
        self._warp = None
        self.nodes = None

    @classmethod
    def resume(cls, session: SessionHost, warp: Warp) -> Family | None:
        if not isinstance(warp, LatticeWarp):
            return None
        family = cls(session)
        family.nodes = np.asarray(warp.grid.nodes, dtype=np.float64).copy()
        family._warp = warp
        return family

    @classmethod
    def build(cls, settings: LatticeSettings, volume: Any, ctx: Any = None) -> Built:
        """The lattice warp of ``settings`` (its nodes over its box, default the
        volume's; or its lattice file) for ``volume`` (no model: ``model`` is None)."""
        if settings.file is not None:
            return Built(None, load_lattice_file(settings.file, volume), BuildReport())
        box = volume.bounds if settings.box is None else settings.box
        return Built(None, LatticeWarp(TrilinearGrid(settings.nodes), box), BuildReport())

    def set_nodes(self, nodes: np.ndarray) -> None:
        """Move every node (the warp follows at the next :meth:`warp`)."""
        shape = self.nodes.shape if self.nodes is not None else np.shape(nodes)
        self.nodes = np.asarray(nodes, dtype=np.float64).reshape(shape)
        self.release(self._warp)
        self._warp = None

    def warp(self) -> Warp | None:
        if self.nodes is None:
            return None
        if self._warp is None:
            settings = LatticeSettings(self.nodes, self.session.box)
            self._warp = self.build(settings, self.session.volume).warp
        return self._warp

    def handles(self) -> np.ndarray:
        return self.nodes.reshape(-1, 3) if self.nodes is not None else np.zeros((0, 3))

    def drag(self, drag: DragState, selection: np.ndarray, delta: np.ndarray) -> None:
        nodes = drag.positions.copy()
        nodes[selection] += delta
        self.set_nodes(nodes)

    def reset(self) -> None:
        self.session.set_deformation(self.kind)  # a fresh lattice, as when first chosen

    def overlay(
        self, handles: np.ndarray, display: DisplayOptions, to_world: ToWorld
    ) -> list[OverlayLayer]:
        if self.nodes is None or not display.lattice_cells:
            return []
        edges = grid_edges(handles.reshape(self.nodes.shape))
        return [
            OverlayLayer("lines", edges, COLORS["lattice"], name="cells"),
            OverlayLayer("points", handles, COLORS["lattice"], 7.0, "nodes"),
        ]

    def snapshot(self) -> dict[str, Any]:
        return {"nodes": self.nodes.copy()} if self.nodes is not None else {}

    def restore(self, state: dict[str, Any]) -> None:
        if "nodes" in state:
            self.nodes = state["nodes"].copy()

    def set_keys(self, animation: Animation, frame: int, interpolation: str) -> None:
        if self.nodes is not None:
            put_key(
                track(animation, "lattice.nodes", interpolation), frame, json_values(self.nodes)
            )
