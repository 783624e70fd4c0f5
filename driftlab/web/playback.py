"""A tab's playback: what plays (live, rewatch, what-if, compare), the controls, the HUD, the episode's state
plots and its downloads. It moves the player one frame per :meth:`Playback.tick` of the tab's 30 Hz loop.

Modes: "live" follows the selected job (when an episode ends, the newest evaluation plays next); "rewatch"
plays a chosen stored evaluation; "what-if" an episode the worker just ran, with the job's best as a ghost;
"compare" the best episodes of several jobs together, as ghost cars beside the first.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import viser
import viser.uplot

from driftlab.markup import plain
from driftlab.services.read_model import NotFound
from driftlab.web.frames import EpisodeFrames
from driftlab.web.player import EpisodePlayer
from driftlab.web.plots import padded_range, series
from driftlab.web.scene import set_chase_camera, set_overview_camera
from driftlab.web.sources import JobHistory

STATE_PLOTS = (("V_mps", "V_ref_mps", "V [m/s]"), ("beta_rad", "beta_ref_rad", "beta [rad]"),
               ("r_radps", "r_ref_radps", "r [rad/s]"), ("delta_rad", "delta_ref_rad", "delta [rad]"))
MODE_TITLES = {"live": "Live (follows the job)", "rewatch": "Rewatch", "what-if": "What-if",
               "compare": "Compare (best episodes together)"}


class Playback:
    """Playback controls and state plots of one tab.

    Args:
        client: the tab.
        history: the selected job's history, or None (read when needed: the selection changes).
        frames_of: a stored evaluation's episode by its id.
        best: the selected job's best episode, or None.
        lock: the tab's lock, held by every callback (the 30 Hz loop holds it too).
    """

    def __init__(self, client: viser.ClientHandle, *, history: Callable[[], JobHistory | None],
                 frames_of: Callable[[int], EpisodeFrames], best: Callable[[], EpisodeFrames | None],
                 lock: threading.RLock) -> None:
        self.client = client
        self.lock = lock
        self.history = history
        self.frames_of = frames_of
        self.best = best
        self.mode = "live"
        self.playing = True
        self.speed = 1.0
        self.compare_captions: list[str] = []
        self.stale: str | None = None  # why the episode shown is not the one last asked for (a what-if refused)
        self.empty: EpisodeFrames | None = None  # the evaluation chosen last, if it has no step to play
        self.player = EpisodePlayer(client.scene)
        self._build_gui(client.gui)

    # ----- GUI -------------------------------------------------------------------------------------------
    def _build_gui(self, gui: viser.GuiApi) -> None:
        with gui.add_folder("Playback"):
            self.hud = gui.add_markdown("")
            with gui.add_folder("Choose", expand_by_default=True):
                self.gui_live = gui.add_button("Follow live", icon=viser.Icon.ACTIVITY)
                self.gui_best = gui.add_button("Play best", icon=viser.Icon.TROPHY)
                self.gui_index = gui.add_number("Evaluation index", 0, min=0, step=1,
                                                hint="0-based index within the job (the API's 'index')")
                self.gui_play_index = gui.add_button("Play evaluation at index")
            self.gui_play = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
            self.gui_chase = gui.add_checkbox("Chase camera", False,
                                              hint="Follow the car from behind, along its direction of travel")
            self.gui_speed = gui.add_slider("Speed (x real time)", 0.25, 8.0, 0.25, 1.0)
            self.gui_time = gui.add_slider("Time [s]", 0.0, 30.0, 0.1, 0.0)
        self.gui_live.on_click(lambda _: self._locked(self.follow_live))
        self.gui_best.on_click(lambda _: self._locked(self.play_best))
        self.gui_play_index.on_click(lambda _: self._locked(self.play_index, int(self.gui_index.value)))
        self.gui_play.on_click(lambda _: self._locked(self.toggle_play))
        self.gui_speed.on_update(self._on_speed)
        self.gui_time.on_update(self._on_scrub)
        self.gui_chase.on_update(self._on_chase)
        with gui.add_folder("Episode states"):
            self.state_plots = [gui.add_uplot((np.zeros(1), np.zeros(1), np.zeros(1)),
                                              (series("t [s]", "#888"), series(label, "#2a6fdb"),
                                               series("reference", "#e8590c")), title=label, aspect=2.5,
                                              scales={"x": {"time": False}})
                                for _, _, label in STATE_PLOTS]

    def _locked(self, action: Callable[..., Any], *args: Any) -> None:
        with self.lock:
            action(*args)

    def build_downloads(self, gui: viser.GuiApi) -> None:
        """The downloads folder (built last, below the other panels)."""
        with gui.add_folder("Downloads", expand_by_default=False):
            self.downloads = gui.add_markdown("")

    # ----- choosing what plays -----------------------------------------------------------------------------
    def follow_live(self) -> None:
        self.mode = "live"
        self.playing = True
        self.load_latest()

    def load_latest(self) -> None:
        history = self.history()
        if history is None:
            return
        if history.n_done == 0:  # nothing of this job to show: not the previous job's episode under its name
            self.player.unload()
            self.empty = None
            self.show_hud()
            return
        if self.empty is not None and self.empty.evaluation_id == history.ids[-1]:
            return  # the newest stopped before its first step; it is shown as such until a newer one lands
        self._load_stored(history.ids[-1])

    def _load_stored(self, evaluation_id: int) -> None:
        """A stored episode; one whose trajectory a long job did not keep leaves the view as it is and says why."""
        try:
            frames = self.frames_of(evaluation_id)
        except NotFound:
            self.hud.content = (f"Evaluation id {evaluation_id}: its trajectory was not kept (past the job's "
                                f"trajectory limit; every best's is).")
            return
        self.load(frames)

    def play_best(self) -> None:
        best = self.best()
        if best is None:
            self.hud.content = "No completed evaluation yet."
            return
        self.mode = "rewatch"
        self.playing = True
        self.load(best)

    def play_index(self, index: int) -> None:
        history = self.history()
        if history is None or not 0 <= index < history.n_done:
            n = 0 if history is None else history.n_done
            self.hud.content = f"Evaluation # must be in [0, {n - 1}]; this job has {n} evaluations."
            return
        self.mode = "rewatch"
        self.playing = True
        self._load_stored(history.ids[index])

    def play_what_if(self, frames: EpisodeFrames, ghost: EpisodeFrames | None) -> None:
        """A what-if episode beside the ghost it was asked against (the best evaluation's episode on the same seed
        when it was asked; the best may have moved on since)."""
        self.mode = "what-if"
        self.playing = True
        self.load(frames, ghost=ghost)

    def play_together(self, episodes: list[EpisodeFrames], captions: list[str]) -> None:
        """Several episodes at once: the first as the car, the others as ghost cars (compare mode)."""
        if not episodes:
            return
        self.mode = "compare"
        self.playing = True
        self.compare_captions = captions
        self.load(episodes[0], ghost=episodes[1] if len(episodes) > 1 else None, more_ghosts=tuple(episodes[2:]))

    def show_what_if_error(self, error: str) -> None:
        """A what-if that could not run (an undrivable plant, a dead worker): the previous episode stops where it
        is and is marked stale, with the reason on top of the HUD."""
        self.stale = error
        self.playing = False
        self._show_play_button()
        self.show_hud()

    def load(self, frames: EpisodeFrames, ghost: EpisodeFrames | None = None,
             more_ghosts: tuple[EpisodeFrames, ...] = ()) -> None:
        self.stale = None
        if frames.n_frames == 0:  # stopped at t = 0 (a model without a drift there): nothing to draw or play
            self.player.unload()
            self.empty = frames
            self._show_downloads(frames)
            self.show_hud()
            return
        self.empty = None
        self.player.load(frames, ghost, more_ghosts)
        self.gui_time.max = max(self.player.duration_s, 0.1)
        self._show_states(frames)
        self._show_downloads(frames)
        self.show_hud()

    def _show_states(self, frames: EpisodeFrames) -> None:
        t = frames.column("t_s")
        for plot, (actual, reference, _) in zip(self.state_plots, STATE_PLOTS, strict=True):
            plot.data = (t, frames.column(actual), frames.column(reference))
            both = np.concatenate([frames.column(actual), frames.column(reference)])
            plot.scales = {"x": {"time": False, "range": (0.0, max(float(t[-1]), 0.1))},
                           "y": {"range": padded_range(both, min_span=0.4)}}

    def _show_downloads(self, frames: EpisodeFrames) -> None:
        if not hasattr(self, "downloads"):
            return
        if frames.evaluation_id is None:
            self.downloads.content = "This what-if episode is not stored; the downloads are for stored evaluations."
            return
        base = f"/api/evaluations/{frames.evaluation_id}"
        name = plain(frames.name())  # it holds the job's name: text, never markup
        self.downloads.content = (
            f"{name[:1].upper() + name[1:]}:\n\n"
            f"- [trajectory CSV]({base}/trajectory?format=csv)\n"
            f"- [trajectory JSON]({base}/trajectory?format=json)\n"
            f"- [recording (.viser)]({base}/recording.viser)\n"
            f"- [standalone HTML replay]({base}/replay.html)\n"
            f"- [open the recording in the viewer](/viser/?playbackPath={base}/recording.viser)")

    # ----- controls ----------------------------------------------------------------------------------------
    def toggle_play(self) -> None:
        if not self.playing and self.player.finished:
            self.player.seek(0.0)
        self.playing = not self.playing
        self._show_play_button()
        self._follow_with_camera()  # paused: the camera stays behind the car where it stopped

    def _show_play_button(self) -> None:
        self.gui_play.label = "Pause" if self.playing else "Play"
        self.gui_play.icon = viser.Icon.PLAYER_PAUSE if self.playing else viser.Icon.PLAYER_PLAY

    def _on_speed(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.speed = float(self.gui_speed.value)

    def _on_chase(self, event: viser.GuiEvent) -> None:
        if event.client is None:
            return
        with self.lock:
            if self.gui_chase.value:
                self._follow_with_camera()  # at once, playing or paused
            else:
                set_overview_camera(self.client.camera)

    def _on_scrub(self, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own 5 Hz update of the slider
            return
        with self.lock:
            self.player.seek(float(self.gui_time.value))
            self._follow_with_camera()  # scrubbing moves the car: the chase camera goes with it
            self.show_hud()

    def _follow_with_camera(self) -> None:
        frames = self.player.frames
        if self.gui_chase.value and frames is not None and frames.n_frames:
            i = frames.index_at(self.player.t_s)
            x_m, y_m, _, _ = frames.pose_at(i)
            set_chase_camera(self.client.camera, x_m, y_m, frames.course_at(i))

    def show_hud(self) -> None:
        frames = self.player.frames
        history = self.history()
        if frames is None:
            if self.empty is not None:
                why = f": {plain(self.empty.failure_reason)}" if self.empty.failure_reason else ""
                self.hud.content = (f"**{MODE_TITLES[self.mode]}**: {plain(self.empty.name())} stopped before its "
                                    f"first step ({plain(self.empty.status)}{why}): nothing to play.")
                return
            name = f" of job **{plain(history.name)}**" if history is not None else ""
            self.hud.content = f"Waiting for the first evaluation{name}..."
            return
        # The player runs to the longest episode shown (a ghost may outlast the car's): the car's clock stops at
        # its own end, and the HUD says so rather than print a time past it.
        t_s = min(self.player.t_s, frames.duration_s)
        lines = [f"**{MODE_TITLES[self.mode]}** · t {t_s:5.1f} / {frames.duration_s:.1f} s"]
        if self.player.t_s > frames.duration_s + 1e-9:
            lines[0] += f" (ended; the others play on to {self.player.duration_s:.1f} s)"
        lap = self.player.lap_text()
        if lap is not None:
            lines.append(lap)
        if self.stale is not None:
            lines.insert(0, f"**What-if not run**: {plain(self.stale)}. The episode below is the previous one (stale), "
                            "paused.")
        if self.mode == "compare":
            lines += self.compare_captions
        else:
            lines.append(plain(frames.caption()))
            if self.player.ghost_frames is not None:
                lines.append(f"ghost (blue): {plain(self.player.ghost_frames.caption())}")
        if self.mode == "live" and history is not None and history.n_done:
            lines.append(f"newest: evaluation id {history.ids[-1]} (index {history.n_done - 1})")
        self.hud.content = "\n\n".join(lines)

    # ----- one frame ---------------------------------------------------------------------------------------
    def tick(self, period_s: float, show_text: bool) -> None:
        if self.player.frames is None:
            history = self.history()
            if self.mode == "live" and history is not None and history.n_done:
                self.load_latest()
            return
        if not self.playing:
            return
        if self.player.finished:
            self._at_end()
            return
        self.player.seek(self.player.t_s + period_s * self.speed)
        self._follow_with_camera()
        if show_text:
            self.gui_time.value = round(self.player.t_s, 1)
            self.show_hud()

    def _at_end(self) -> None:
        if self.mode == "live":
            self.load_latest()  # the newest evaluation, or the same one again
        elif self.mode == "compare":
            self.player.seek(0.0)  # the compared episodes loop, side by side
        else:
            self.playing = False
            self._show_play_button()
            self.show_hud()
