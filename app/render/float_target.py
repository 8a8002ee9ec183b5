"""A float offscreen target that grows to the largest size asked of it: the render
target of the slice sampler and of the field sampler, which read back float values."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


class FloatTarget:
    """Float32 colour attachments with ``components`` channels each (e.g. ``(4, 1)``)
    in one framebuffer, grown (never shrunk) by :meth:`framebuffer`; :meth:`release`
    frees them (idempotent)."""

    def __init__(self, ctx: Any, components: Sequence[int]) -> None:
        self.ctx = ctx
        self.components = tuple(int(c) for c in components)
        self.size = (0, 0)
        self._textures: list[Any] = []
        self._fbo: Any = None

    def framebuffer(self, w: int, h: int) -> Any:
        """The framebuffer, at least ``w`` x ``h`` pixels (its ``size`` may be larger)."""
        tw, th = self.size
        if self._fbo is not None and tw >= w and th >= h:
            return self._fbo
        w, h = max(w, tw), max(h, th)
        self.release()
        self._textures = [self.ctx.texture((w, h), c, dtype="f4") for c in self.components]
        self._fbo = self.ctx.framebuffer(color_attachments=self._textures)
        self.size = (w, h)
        return self._fbo

    @property
    def textures(self) -> list[Any]:
        """The colour attachments (empty before the first :meth:`framebuffer`)."""
        return list(self._textures)

    def release(self) -> None:
        """Free the framebuffer and its textures."""
        if self._fbo is None:
            return
        try:  # never delete the bound framebuffer (moderngl would re-bind its name)
            self.ctx.detect_framebuffer(0).use()
        except Exception:
            pass
        self._fbo.release()
        for tex in self._textures:
            tex.release()
        self._fbo, self._textures, self.size = None, [], (0, 0)
