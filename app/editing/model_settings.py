"""What a deformation model is built from, one typed settings object per family, and
the one rule of when a running model is *settled*.

The family adapters (:mod:`voxwarp.editing.families`) build models from these settings
(``Family.build(settings, volume, ctx)``); the editor, the CLI (``voxwarp render
--massspring/--chainmail/--wires/--lattice``), the napari widget and the notebook viewer
all go through them, so a model built from the same settings is the same everywhere.

Settled (Knoche 2008, 3.2: the explicit and semi-implicit integrators only approach
rest): a mass-spring model is settled when every element is slower than
:data:`SETTLE_SPEED` mm/s (:func:`is_settled`; ``MassSpring.settle`` checks it every 50
steps); a ChainMail model when a relaxation step moves no element by more than
:data:`CHAINMAIL_REST_MM` (:func:`chainmail_at_rest`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, NamedTuple

import numpy as np

from voxwarp.deform.elements.anchors import ANCHOR_CHOICES, AUTO, MODEL_DEFAULT
from voxwarp.deform.elements.anchors import DEFAULT as DEFAULT_REGION
from voxwarp.deform.elements.margin import AUTO_MARGIN
from voxwarp.editing.common import CHAINMAIL_VARIANTS, INTEGRATORS, EditorError, choice

#: a mass-spring model whose elements are all slower than this (mm/s) is settled
SETTLE_SPEED = 1e-3
#: most steps a settling run takes when no limit is given
SETTLE_MAX_STEPS = 20000
#: steps a mass-spring run takes without settling and without a step count: with the
#: CLI's defaults (semi-implicit, shear springs, dt ~ 24 ms) an 8³ grid is settled after
#: about 600 steps and a 16³ grid within ~5 % of the dragged distance after 1000
FIXED_STEPS = 1000
#: a ChainMail relaxation step that moves no element more than this (mm) means rest
CHAINMAIL_REST_MM = 1e-4


def max_speed(model: Any) -> float:
    """The fastest element's speed (mm/s) of a mass-spring model."""
    return float(np.sqrt(np.max(np.sum(model.velocities() ** 2, axis=-1))))


def is_settled(model: Any) -> bool:
    """Whether every element of a mass-spring model is slower than :data:`SETTLE_SPEED`."""
    return bool(max_speed(model) < SETTLE_SPEED)


def chainmail_at_rest(before: np.ndarray, after: np.ndarray) -> bool:
    """Whether a ChainMail relaxation from positions ``before`` to ``after`` moved no
    element more than :data:`CHAINMAIL_REST_MM`."""
    return bool(np.max(np.abs(after - before)) < CHAINMAIL_REST_MM)


class SettingError(EditorError):
    """A setting the builder cannot use; :attr:`setting` names it (``"model"``: the
    model refused its settings), so that a caller can name its own option."""

    def __init__(self, setting: str, message: str) -> None:
        super().__init__(message)
        self.setting = setting


# ---------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class Drag:
    """Elements held at an offset (mm, world) from rest: ``selection`` is an index
    ``(i, j, k)``, (m, 3) indices or a bool mask of the grid shape."""

    selection: Any
    offset: Any


@dataclass(frozen=True)
class Cut:
    """A cutting plane of ChainMail: a point on it and its normal (world mm), optionally
    the radius (mm) of the disk on it that cuts."""

    point: tuple[float, float, float]
    normal: tuple[float, float, float]
    radius: float | None = None


@dataclass(frozen=True)
class SettleRule:
    """How long a mass-spring model runs after its drags.

    ``settle=False``: ``steps`` steps (None: :data:`FIXED_STEPS`); ``settle=True``: until
    :func:`is_settled`, at most ``steps`` (None: :data:`SETTLE_MAX_STEPS`).
    """

    settle: bool = False
    steps: int | None = 0

    @property
    def limit(self) -> int:
        """The steps to run (fixed) or the most steps (settling)."""
        if self.steps is not None:
            return int(self.steps)
        return SETTLE_MAX_STEPS if self.settle else FIXED_STEPS


@dataclass(frozen=True)
class ElementSettings:
    """An element grid over the volume's box and what is done to it before the first
    frame (shared by mass-spring and ChainMail)."""

    #: elements per axis
    shape: tuple[int, int, int] = (8, 8, 8)
    backend: str = "cpu"
    #: one stiffness (0..1] for every element (None: the grid's default)
    stiffness: float | None = None
    #: (value, stiffness) points mapping the volume's values to element stiffness, or a
    #: tissue preset: "ct", "mr" or "auto" (from the volume's modality)
    stiffness_from_volume: Sequence[tuple[float, float]] | str | None = None
    #: index ranges ``((i0, i1), (j0, j1), (k0, k1))`` (inclusive) of fixed elements
    fixed: tuple[tuple[tuple[int, int], ...], ...] = ()
    drags: tuple[Drag, ...] = ()
    #: the warp's inverse mode (None: the model's default, ``"baked"``)
    inverse: str | None = None
    # -- the grid margin (mm): the grid's box reaches this far beyond the volume's on
    # -- every side (0: the volume's box; "auto": 10 % of its largest side, resolved
    # -- when the grid is built, margin.auto_margin; the CLI's default is the largest
    # -- drag, grid.default_margin)
    margin: float | str = 0.0
    #: boundary conditions (:mod:`voxwarp.deform.elements.anchors`): the grid's fixed
    #: elements ("shell", "corners": the thesis's, "none", "default": the model's own,
    #: :attr:`default_anchor`) and the region of influence (mm, "auto", None: off;
    #: "default": "auto" with the shell, else off)
    anchor: str = MODEL_DEFAULT
    fix_outside: float | str | None = "default"
    #: the model's own anchor mode: springs spread a drag over the whole grid, so
    #: mass-spring fixes the shell (ChainMail overrides it)
    default_anchor: ClassVar[str] = "shell"

    def grid_anchor(self) -> str:
        """The anchor mode of the grid: :attr:`anchor`, or the model's default."""
        return self.default_anchor if self.anchor == MODEL_DEFAULT else self.anchor


@dataclass(frozen=True)
class MassSpringSettings(ElementSettings):
    """A mass-spring model (Knoche 2008, chapter 3)."""

    integrator: str = "semi-implicit"
    shear: bool = False
    bend: bool = False
    #: how long it runs after the drags (default: not at all, a model at rest)
    run: SettleRule = field(default_factory=SettleRule)


@dataclass(frozen=True)
class ChainMailSettings(ElementSettings):
    """A 3D ChainMail model (Knoche 2008, chapter 4; Gibson 1997)."""

    #: ChainMail moves an element only once a link to it runs out of slack, so a drag is
    #: local with the thesis's corners; a fixed shell next to a drag would stop it (the
    #: links to the shell run out of slack within one spacing)
    default_anchor: ClassVar[str] = "corners"

    variant: str = "enhanced"
    cuts: tuple[Cut, ...] = ()
    #: after the cuts: cut links crossing these planes or disks are linked again
    joins: tuple[Cut, ...] = ()
    #: relaxation steps run once after the drags
    relax: int = 0
    #: relaxation steps after every later move, saved with the model (None: ``relax``)
    relax_steps: int | None = None
    #: CPU: compile the kernels before the drags, so their time is the move's alone
    warm_up: bool = False


@dataclass(frozen=True)
class WireSettings:
    """A wire field: the ``"wires"`` warp entry of scene JSON (``wires`` plus the field
    options ``field_scale``, ``layout``, ``masks``, ...), as a wire file holds it."""

    entry: dict[str, Any]

    @classmethod
    def of(cls, wires: Sequence[Any], **options: Any) -> WireSettings:
        """Settings of :class:`~voxwarp.deform.wires.field.Wire` objects and options."""
        return cls({"type": "wires", "wires": [w.to_dict() for w in wires], **options})


@dataclass(frozen=True)
class LatticeSettings:
    """A trilinear lattice: its ``nodes`` (nx, ny, nz, 3) over ``box`` (None: the
    volume's), or a lattice file (the ``"lattice"`` warp entry of scene JSON)."""

    nodes: np.ndarray | None = None
    box: Any = None
    file: str | None = None


# ---------------------------------------------------------------------------- the editor's
@dataclass
class FamilyOptions:
    """The family settings an edit session keeps whichever family is chosen (they survive
    a switch of family), saves in its scene's editor entry and undoes: the next element
    model's ``integrator``, ``variant`` and ``stiffness``, the running model's
    ``steps_per_frame`` and ``relax_steps``, and how the wire field is built
    (``wire_settings``). The family adapters read them; the session never names them.
    """

    integrator: str = "semi-implicit"
    variant: str = "enhanced"
    #: element stiffness of new mass-spring/ChainMail models (0..1]
    stiffness: float = 0.5
    #: boundary conditions of new element models (see :class:`ElementSettings`)
    anchor: str = MODEL_DEFAULT
    fix_outside: float | str | None = "default"
    #: mass-spring steps and ChainMail relaxation steps per frame while running
    steps_per_frame: int = 10
    relax_steps: int = 1
    wire_settings: dict[str, Any] = field(default_factory=lambda: {"field_scale": 2})
    # -- the grid margin of new mass-spring/ChainMail models: mm their grid's box reaches
    # -- beyond the volume's (0: the volume's box), or "auto" (the default: 10 % of the
    # -- volume box's largest side, resolved when a model is built, margin.auto_margin),
    # -- as no drag is known then; an editor entry without the key means 0
    margin: float | str = AUTO_MARGIN

    def copy(self) -> FamilyOptions:
        """An independent copy."""
        return replace(self, wire_settings=dict(self.wire_settings))

    def with_model_settings(self, settings: dict[str, Any]) -> FamilyOptions:
        """A copy with the model settings of ``EditSession.set_deformation``
        (``integrator``, ``variant``, ``stiffness``, ``margin``, ``anchor``,
        ``fix_outside``; nothing else may be left in ``settings``), checked; an
        :class:`EditorError` names a bad one."""
        settings = dict(settings)
        bounds = _boundary_settings(settings, self.anchor, self.fix_outside)
        integrator = choice(settings.pop("integrator", self.integrator), INTEGRATORS, "integrator")
        variant = choice(settings.pop("variant", self.variant), CHAINMAIL_VARIANTS, "variant")
        stiffness_value = settings.pop("stiffness", self.stiffness)
        try:
            stiffness = float(stiffness_value)
        except (TypeError, ValueError) as exc:
            raise EditorError(
                f"stiffness must be a number in (0, 1]; got {stiffness_value!r}"
            ) from exc
        margin = _margin(settings.pop("margin", self.margin))
        if settings:
            raise EditorError(f"unknown deformation settings: {', '.join(sorted(settings))}")
        if not 0.0 < stiffness <= 1.0:
            raise EditorError(f"stiffness must be in (0, 1]; got {stiffness}")
        return replace(
            self.copy(),
            integrator=integrator,
            variant=variant,
            stiffness=stiffness,
            margin=margin,
            **bounds,
        )

    def set_run_option(self, name: str, value: Any) -> int:
        """Set ``steps_per_frame`` or ``relax_steps`` (0..10000); returns the value."""
        if name not in ("steps_per_frame", "relax_steps"):
            raise EditorError(f"unknown option {name!r}")
        v = int(value)
        if not 0 <= v <= 10000:
            raise EditorError(f"{name} must be 0..10000; got {value!r}")
        setattr(self, name, v)
        return v

    @contextlib.contextmanager
    def one_step(self) -> Iterator[None]:
        """One model step per frame (mass-spring and ChainMail) inside the block."""
        steps, relax = self.steps_per_frame, self.relax_steps
        self.steps_per_frame = self.relax_steps = 1
        try:
            yield
        finally:
            self.steps_per_frame, self.relax_steps = steps, relax

    def to_entry(self) -> dict[str, Any]:
        """The keys of the scene's editor entry (as saved before the options had a type)."""
        return {
            "integrator": self.integrator,
            "variant": self.variant,
            "steps_per_frame": self.steps_per_frame,
            "relax_steps": self.relax_steps,
            "stiffness": self.stiffness,
            "anchor": self.anchor,
            "fix_outside": self.fix_outside,
            "wire_settings": dict(self.wire_settings),
            "margin": self.margin,
        }

    def read_entry(self, entry: dict[str, Any]) -> None:
        """Take the options an editor entry holds (missing ones stay, but a missing
        ``margin`` is 0: the entry was saved before the margin, and its scene's new
        models are built as they were then)."""
        for key in ("integrator", "variant"):
            if key in entry:
                setattr(self, key, str(entry[key]))
        for key in ("steps_per_frame", "relax_steps"):
            if key in entry:
                setattr(self, key, int(entry[key]))
        if "stiffness" in entry:
            self.stiffness = float(entry["stiffness"])
        if "anchor" in entry:
            self.anchor = str(entry["anchor"])
        if "fix_outside" in entry:
            self.fix_outside = entry["fix_outside"]
        if isinstance(entry.get("wire_settings"), dict):
            self.wire_settings = dict(entry["wire_settings"])
        self.margin = _margin(entry.get("margin", 0.0))


def _margin(value: Any) -> float | str:
    """A grid margin setting, checked: :data:`AUTO_MARGIN` or a finite number of mm
    >= 0."""
    if isinstance(value, str) and value == AUTO_MARGIN:
        return AUTO_MARGIN
    try:
        margin = float(value)
    except (TypeError, ValueError) as exc:
        raise EditorError(
            f"margin must be 'auto' or a number of mm >= 0; got {value!r:.40}"
        ) from exc
    if not (np.isfinite(margin) and margin >= 0.0):
        raise EditorError(f"margin must be 'auto' or a number of mm >= 0; got {margin}")
    return margin


def _boundary_settings(
    settings: dict[str, Any], anchor: str, fix_outside: float | str | None
) -> dict[str, Any]:
    """``anchor`` and ``fix_outside`` popped from ``settings`` (default: the current),
    checked; an :class:`EditorError` names a bad one."""
    anchor = choice(settings.pop("anchor", anchor), ANCHOR_CHOICES, "anchor")
    fix_outside = settings.pop("fix_outside", fix_outside)
    if fix_outside not in (DEFAULT_REGION, AUTO, None):
        try:
            fix_outside = float(fix_outside)
        except (TypeError, ValueError) as exc:
            raise EditorError(
                f"fix_outside must be a radius in mm, 'auto' or None; got {fix_outside!r}"
            ) from exc
        if not fix_outside >= 0:
            raise EditorError(f"fix_outside must be >= 0 mm (0: off); got {fix_outside}")
    return {"anchor": anchor, "fix_outside": fix_outside}


# ---------------------------------------------------------------------------- results
@dataclass
class BuildReport:
    """What a build did, for summaries and warnings (the CLI prints them)."""

    #: mass-spring: steps run, whether settling stopped at its limit
    steps: int = 0
    settling: bool = False
    hit_limit: bool = False
    #: ChainMail: links cut and joined again, elements touched by the drags, the drags'
    #: time, the fraction of the way a limited drag went (None: all of it), relaxation
    #: time, elements moved
    cut: int = 0
    joined: int = 0
    touched: int = 0
    solve_ms: float = 0.0
    limited_fraction: float | None = None
    relax_ms: float = 0.0
    displaced: int = 0


class Built(NamedTuple):
    """A built model (None for the wire and lattice families), its warp and a report."""

    model: Any
    warp: Any
    report: BuildReport
