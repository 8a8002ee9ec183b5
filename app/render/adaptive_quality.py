"""Adaptive quality of interactive frames (as VTK's interactive sample distance and
3D Slicer's adaptive quality).

While the user drags or orbits, the GUI draws at a coarser *level*: a lower resolution
(:meth:`voxwarp.render.raycaster.Renderer.draw_scaled`) and a longer sample distance
along the rays (the scene's ``step`` times a factor; the renderer corrects the
transfer function's opacities for the distance it samples at, so the picture keeps its
brightness). :class:`AdaptiveQuality` picks the level from the time the last
interactive frame took: one level coarser when it missed the frame-time target, one
finer when the finer level's predicted time (the cost scales with pixels times samples
per ray) still fits the target with room to spare. When the view rests, the GUI draws
the full-quality frame (:data:`FULL`), whatever the level.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from voxwarp.errors import VoxwarpError

if TYPE_CHECKING:
    from voxwarp.scene import Scene


@dataclass(frozen=True)
class Quality:
    """One level: ``scale`` of the resolution (0 < scale <= 1) and ``step_factor``, the
    multiple (>= 1) of the scene's sample distance."""

    scale: float
    step_factor: float

    @property
    def cost(self) -> float:
        """The relative cost of a frame: pixels times samples per ray (1 at full quality)."""
        return self.scale * self.scale / self.step_factor


#: the full-quality frame (the view at rest)
FULL = Quality(1.0, 1.0)
#: the interactive levels, finest first: each costs about half the one before it
LEVELS: tuple[Quality, ...] = (
    Quality(1.0, 1.0),
    Quality(0.75, 1.0),
    Quality(0.5, 1.0),
    Quality(0.5, 2.0),
    Quality(0.35, 2.0),
    Quality(0.25, 2.0),
    Quality(0.25, 3.0),
)
#: the level of the first interactive frame: half resolution, twice the sample distance
START_LEVEL = 3
#: interactive frames aim for at least this many frames per second
TARGET_FPS = 15.0
#: the longest sample distance a scene takes (voxels; the bound of ``Scene.step``)
MAX_STEP_VOXELS = 100.0
#: a finer level is taken only when its predicted time is under this fraction of the
#: target (hysteresis: a frame time near the target does not flip between two levels)
FINER_HEADROOM = 0.7


class AdaptiveQualityError(VoxwarpError):
    """Bad settings of :class:`AdaptiveQuality`."""


class AdaptiveQuality:
    """Chooses the :class:`Quality` of interactive frames from the last frame's time.

    Parameters
    ----------
    target_fps
        Interactive frames aim for this rate (the frame-time budget is ``1 / target_fps``).
    levels
        The allowed levels, finest first (the bounds: the choice never leaves them).
    start
        Index into ``levels`` of the first interactive frame's level.
    min_level
        The finest level index interactive frames may use (e.g. to keep the half
        resolution of old: the index of ``Quality(0.5, 1.0)``).
    """

    def __init__(
        self,
        target_fps: float = TARGET_FPS,
        levels: tuple[Quality, ...] = LEVELS,
        start: int = START_LEVEL,
        min_level: int = 0,
    ) -> None:
        if not levels or any(not (0 < q.scale <= 1 and q.step_factor >= 1) for q in levels):
            raise AdaptiveQualityError(
                "levels must be a non-empty list of Quality(scale in (0, 1], step_factor >= 1)"
            )
        if not 0 < target_fps <= 1000:
            raise AdaptiveQualityError(f"target_fps must be in (0, 1000]; got {target_fps}")
        if not 0 <= min_level <= start < len(levels):
            raise AdaptiveQualityError(
                f"need 0 <= min_level <= start < {len(levels)}; got min_level={min_level},"
                f" start={start}"
            )
        self.levels = tuple(levels)
        self.target_s = 1.0 / float(target_fps)
        self.min_level = int(min_level)
        self.start = int(start)
        self.level = self.start

    @property
    def quality(self) -> Quality:
        """The level the next interactive frame draws at."""
        return self.levels[self.level]

    def frame_drawn(self, seconds: float) -> Quality:
        """Note that an interactive frame at :attr:`quality` took ``seconds``; returns
        the level of the next one (one step coarser, one finer, or the same)."""
        if not seconds >= 0:  # also NaN
            raise AdaptiveQualityError(f"a frame time must be >= 0 seconds; got {seconds}")
        here = self.quality
        if seconds > self.target_s and self.level < len(self.levels) - 1:
            self.level += 1
        elif self.level > self.min_level:
            finer = self.levels[self.level - 1]
            if seconds * finer.cost / here.cost < FINER_HEADROOM * self.target_s:
                self.level -= 1
        return self.quality

    def reset(self) -> None:
        """Back to the starting level (e.g. another volume was opened)."""
        self.level = self.start


def scene_at(scene: Scene, quality: Quality) -> Scene:
    """``scene`` with its sample distance times ``quality.step_factor`` (a copy; the
    scene itself when the factor is 1); the renderer corrects the transfer function's
    opacities for the distance. The resolution is the caller's (``draw_scaled``)."""
    if quality.step_factor == 1.0:
        return scene
    return scene.copy(step=min(scene.step * quality.step_factor, MAX_STEP_VOXELS))
