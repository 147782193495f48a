"""Frame quality for an interactive viewer on a slow adapter.

While something changes from frame to frame (the camera moves, a motion plays, a stroke is painted, a
slider is dragged) the viewer draws a cheaper frame; when the view stops changing it draws one full frame
and then reuses that image until the next change. :class:`QualityGovernor` picks how cheap, from the frame
times it measures, so that a fast GPU never leaves full quality and lavapipe stays above its target rate.

Two knobs make a frame cheaper, in this order (the first costs the least in looks):
- ``stride``: draw every ``stride``-th surfel, enlarged (:mod:`gma.render.subset`). The renderer's cost
  follows the surfel count, far more than the pixel count, because most surfels cover less than a tile.
- ``scale``: render a smaller image and stretch it (bilinear) onto the window.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["FULL", "LADDER", "FrameQuality", "QualityGovernor"]


@dataclass(frozen=True)
class FrameQuality:
    """How a frame is drawn: ``scale`` of the window's size for the surfel image, and ``stride`` (every
    ``stride``-th surfel is drawn)."""

    scale: float = 1.0
    stride: int = 1

    @property
    def is_full(self) -> bool:
        return self.scale == 1.0 and self.stride == 1

    def image_size(self, width: int, height: int) -> tuple[int, int]:
        return max(1, round(width * self.scale)), max(1, round(height * self.scale))

    def label(self) -> str:
        return "full" if self.is_full else f"1/{self.stride} surfels at {self.scale:.0%}"


FULL = FrameQuality()
# From the full frame to the cheapest: roughly halving the cost at each step.
LADDER = (FULL, FrameQuality(1.0, 2), FrameQuality(1.0, 4), FrameQuality(0.75, 4), FrameQuality(0.75, 8),
          FrameQuality(0.5, 8), FrameQuality(0.5, 16))


class QualityGovernor:
    """Chooses the quality of each frame.

    Call :meth:`next_frame` with whether the view changed since the last frame; it answers the quality to
    draw, or None when the last full frame can be shown again. After the frame, call :meth:`frame_done`
    with its wall-clock time. While the view keeps changing, the level moves one step cheaper when the
    recent frames miss the budget (``1 / target_fps``) and one step richer when they would fit it at the
    richer level with room to spare, judged from what that level cost when it was last used.
    ``adaptive=False`` always draws full frames (and still reuses unchanged ones).
    """

    def __init__(self, target_fps: float = 12.0, adaptive: bool = True, ladder=LADDER):
        if target_fps <= 0:
            raise ValueError(f"target_fps must be positive, got {target_fps}")
        self.budget_ms = 1e3 / target_fps
        self.adaptive = adaptive
        self.ladder = tuple(ladder)
        self.level = 0
        self._cost: dict[int, float] = {}   # smoothed ms per frame at each level used so far
        self._drawn: FrameQuality | None = None  # what the image on screen was drawn with
        self._current: int | None = None

    @property
    def quality(self) -> FrameQuality:
        return self.ladder[self.level]

    def next_frame(self, changed: bool) -> FrameQuality | None:
        if not changed and self._drawn is not None and self._drawn.is_full:
            self._current = None
            return None  # nothing moved since the full frame on screen: show it again
        if not changed or not self.adaptive:
            self._current = 0  # the view settled (or adaptation is off): refine to the full frame
            return FULL
        self._current = self.level
        return self.quality

    def frame_done(self, ms: float) -> None:
        """Record the wall-clock time of the frame :meth:`next_frame` last asked for."""
        level, self._current = self._current, None
        if level is None:
            return
        self._drawn = self.ladder[level]
        old = self._cost.get(level)
        self._cost[level] = ms if old is None else 0.6 * old + 0.4 * ms
        if old:
            # The machine got faster or slower (load comes and goes): the other levels' costs, measured
            # earlier, follow by the same factor, so that a stale figure neither blocks nor forces a step.
            drift = self._cost[level] / old
            for other in self._cost:
                if other != level:
                    self._cost[other] *= drift
        if level != self.level or not self.adaptive:
            return  # a full refine frame: it tells what full costs, but does not move the level
        cost = self._cost[level]
        if cost > self.budget_ms and self.level + 1 < len(self.ladder):
            self.level += 1
        elif self.level > 0:
            richer = self._cost.get(self.level - 1)
            # Unknown cost of the richer level: assume each step halves the cost (how LADDER is built).
            expected = richer if richer is not None else 2.0 * cost
            if expected < 0.8 * self.budget_ms:
                self.level -= 1

    def invalidate(self) -> None:
        """Forget the image on screen (resized window, new source): the next frame is drawn."""
        self._drawn = None
