"""Plays stored episodes onto a scene: the car (and ghost cars), trail, trigger markers, tracked circle.

The player owns no clock: callers move it with :meth:`EpisodePlayer.seek` (a live view's 30 Hz loop, or a
recording's fixed steps), so live viewing and recording draw identically.
"""

from __future__ import annotations

import numpy as np
import viser

from driftlab.core.track import FigureEight
from driftlab.web.frames import EpisodeFrames
from driftlab.web.scene import CarModel, Trail, TriggerMarkers, draw_track

CAR_COLOR = (220, 40, 40)
GHOST_COLOR = (60, 150, 255)
# Further ghost cars (the compare mode plays several jobs' best episodes together), in order.
MORE_GHOST_COLORS = ((40, 170, 90), (150, 80, 200), (230, 150, 30), (20, 160, 160), (200, 60, 120),
                     (120, 120, 120), (110, 70, 30))


class EpisodePlayer:
    def __init__(self, scene: viser.SceneApi, track: FigureEight | None = None) -> None:
        self.scene = scene
        self.track = track or FigureEight()
        self._highlights = draw_track(scene, self.track)
        self._tracked: int | None = None
        self._geometry = (1.39, 1.0)
        self.car = CarModel(scene, "car", color=CAR_COLOR)
        self.ghost = CarModel(scene, "ghost", color=GHOST_COLOR, opacity=0.45)
        self.ghost.visible = False
        self.trail = Trail(scene, "trail")
        self.ghost_trail = Trail(scene, "ghost_trail", thickness_m=0.25)
        self.markers = TriggerMarkers(scene)
        self.frames: EpisodeFrames | None = None
        self.ghost_frames: EpisodeFrames | None = None
        self.more_ghosts: list[tuple[CarModel, Trail]] = []  # created on first use
        self.more_ghost_frames: list[EpisodeFrames] = []
        self.t_s = 0.0
        self._laps = None  # the lap of each of the car's frames, on a track of several laps

    def set_car(self, cg_to_front_m: float, cg_to_rear_m: float) -> None:
        """Draw the car (and its ghost) at a job's vehicle geometry (a CommonRoad car is shorter than Table I's)."""
        if (cg_to_front_m, cg_to_rear_m) == self._geometry:
            return
        self._geometry = (cg_to_front_m, cg_to_rear_m)
        visible, ghost_visible = self.car.visible, self.ghost.visible
        self.car = CarModel(self.scene, "car", cg_to_front_m=cg_to_front_m, cg_to_rear_m=cg_to_rear_m,
                            color=CAR_COLOR)  # same node names: replaces the old car
        self.ghost = CarModel(self.scene, "ghost", cg_to_front_m=cg_to_front_m, cg_to_rear_m=cg_to_rear_m,
                              color=GHOST_COLOR, opacity=0.45)
        self.car.visible, self.ghost.visible = visible, ghost_visible
        if self.frames is not None:
            self.seek(self.t_s)

    def set_track(self, track: FigureEight) -> None:
        if track != self.track:
            self.track = track
            self._highlights = draw_track(self.scene, track)  # same node names: replaces the old track
            self._tracked = None
            self._laps = None if self.frames is None or track.laps == 1 else self.frames.laps_on(track)

    @property
    def duration_s(self) -> float:
        spans = [f.duration_s for f in (self.frames, self.ghost_frames, *self.more_ghost_frames) if f is not None]
        return max(spans, default=0.0)

    @property
    def finished(self) -> bool:
        return self.frames is not None and self.t_s >= self.duration_s

    def load(self, frames: EpisodeFrames, ghost: EpisodeFrames | None = None,
             more_ghosts: tuple[EpisodeFrames, ...] = ()) -> None:
        """Start ``frames`` (and a ghost episode beside it, or none, and up to 7 more ghosts) from t = 0."""
        self.frames, self.ghost_frames = frames, ghost
        self._laps = None if self.track.laps == 1 or frames.n_frames == 0 else frames.laps_on(self.track)
        self.trail.clear()
        self.ghost_trail.clear()
        self.markers.clear()
        self.ghost.visible = ghost is not None and ghost.n_frames > 0
        self.car.visible = True
        self._set_more_ghosts(list(more_ghosts[: len(MORE_GHOST_COLORS)]))
        self.seek(0.0)

    def _set_more_ghosts(self, frames: list[EpisodeFrames]) -> None:
        while len(self.more_ghosts) < len(frames):
            n = len(self.more_ghosts)
            car = CarModel(self.scene, f"ghost{n + 2}", color=MORE_GHOST_COLORS[n], opacity=0.45)
            self.more_ghosts.append((car, Trail(self.scene, f"ghost{n + 2}_trail", thickness_m=0.25)))
        self.more_ghost_frames = frames
        for n, (car, trail) in enumerate(self.more_ghosts):
            trail.clear()
            car.visible = n < len(frames) and frames[n].n_frames > 0

    def unload(self) -> None:
        """Show no episode: trail and markers cleared, the car parked out of sight."""
        self.frames, self.ghost_frames = None, None
        self.trail.clear()
        self.ghost_trail.clear()
        self.markers.clear()
        self.ghost.visible = False
        self.car.visible = False
        self._set_more_ghosts([])
        self.t_s = 0.0

    def lap_text(self) -> str | None:
        """On a track of several laps: the car's lap now and each lap's mean |e| so far (None on one lap)."""
        if self._laps is None or self.frames is None:
            return None
        i = self.frames.index_at(self.t_s)
        lap = int(self._laps[i])
        e_m = np.abs(self.frames.column("e_m")[: i + 1])
        means = [f"{float(np.mean(e_m[self._laps[: i + 1] == k])):.2f}" for k in range(1, lap + 1)]
        return f"lap **{lap} of {self.track.laps}** · mean \\|e\\| by lap: {' · '.join(means)} m"

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
        for (car, trail), frames in zip(self.more_ghosts, self.more_ghost_frames, strict=False):
            if frames.n_frames > 0:
                g = frames.index_at(self.t_s)
                car.set_pose(*frames.pose_at(g))
                trail.advance(frames, g, force=self.t_s >= frames.duration_s)

    def _highlight(self, direction: int) -> None:
        if direction != self._tracked:  # send only on change: one message per phase switch
            for d, handle in self._highlights.items():
                handle.visible = d == direction
            self._tracked = direction
