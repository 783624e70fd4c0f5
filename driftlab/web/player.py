"""Plays stored episodes onto a scene: the car (and a ghost car), trail, trigger markers, tracked circle.

The player owns no clock: callers move it with :meth:`EpisodePlayer.seek` (a live view's 30 Hz loop, or a
recording's fixed steps), so live viewing and recording draw identically.
"""

from __future__ import annotations

import viser

from driftlab.core.track import FigureEight
from driftlab.web.frames import EpisodeFrames
from driftlab.web.scene import CarModel, Trail, TriggerMarkers, draw_track

GHOST_COLOR = (60, 150, 255)


class EpisodePlayer:
    def __init__(self, scene: viser.SceneApi, track: FigureEight | None = None) -> None:
        self.scene = scene
        self.track = track or FigureEight()
        self._highlights = draw_track(scene, self.track)
        self._tracked: int | None = None
        self.car = CarModel(scene, "car")
        self.ghost = CarModel(scene, "ghost", color=GHOST_COLOR, opacity=0.45)
        self.ghost.visible = False
        self.trail = Trail(scene, "trail")
        self.ghost_trail = Trail(scene, "ghost_trail", thickness_m=0.25)
        self.markers = TriggerMarkers(scene)
        self.frames: EpisodeFrames | None = None
        self.ghost_frames: EpisodeFrames | None = None
        self.t_s = 0.0

    def set_track(self, track: FigureEight) -> None:
        if track != self.track:
            self.track = track
            self._highlights = draw_track(self.scene, track)  # same node names: replaces the old track
            self._tracked = None

    @property
    def duration_s(self) -> float:
        spans = [f.duration_s for f in (self.frames, self.ghost_frames) if f is not None]
        return max(spans, default=0.0)

    @property
    def finished(self) -> bool:
        return self.frames is not None and self.t_s >= self.duration_s

    def load(self, frames: EpisodeFrames, ghost: EpisodeFrames | None = None) -> None:
        """Start ``frames`` (and a ghost episode beside it, or none) from t = 0."""
        self.frames, self.ghost_frames = frames, ghost
        self.trail.clear()
        self.ghost_trail.clear()
        self.markers.clear()
        self.ghost.visible = ghost is not None and ghost.n_frames > 0
        self.car.visible = True
        self.seek(0.0)

    def unload(self) -> None:
        """Show no episode: trail and markers cleared, the car parked out of sight."""
        self.frames, self.ghost_frames = None, None
        self.trail.clear()
        self.ghost_trail.clear()
        self.markers.clear()
        self.ghost.visible = False
        self.car.visible = False
        self.t_s = 0.0

    def show_caption(self, text: str) -> None:
        """A label over the track (recordings have no GUI panel: this is where their J and theta show)."""
        self.scene.add_label("/caption", text, position=(0.0, 0.0, 14.0), font_screen_scale=0.9)

    def seek(self, t_s: float) -> None:
        self.t_s = min(max(t_s, 0.0), self.duration_s)
        if self.frames is None or self.frames.n_frames == 0:
            return
        i = self.frames.index_at(self.t_s)
        self.car.set_pose(*self.frames.pose_at(i))
        self.trail.advance(self.frames, i, force=self.t_s >= self.frames.duration_s)
        self.markers.show(self.frames.triggers_before(self.t_s))
        self._highlight(self.frames.tracked_circle_at(i))
        if self.ghost_frames is not None and self.ghost_frames.n_frames > 0:
            g = self.ghost_frames.index_at(self.t_s)
            self.ghost.set_pose(*self.ghost_frames.pose_at(g))
            self.ghost_trail.advance(self.ghost_frames, g, force=self.t_s >= self.ghost_frames.duration_s)

    def _highlight(self, direction: int) -> None:
        if direction != self._tracked:  # send only on change: one message per phase switch
            for d, handle in self._highlights.items():
                handle.visible = d == direction
            self._tracked = direction
