"""One browser tab: its own job selection, playback, state plots and what-if, on its own scene and GUI.

Modes: "live" follows the selected job (when an episode ends, the newest completed evaluation plays next);
"rewatch" plays a chosen stored evaluation; "what-if" plays an episode the worker just ran for the sliders'
values, with the job's best episode beside it as a ghost car.
"""

from __future__ import annotations

import threading
import time
from typing import TYPE_CHECKING, Any

import numpy as np
import viser
import viser.uplot

from driftlab.core.tuning import DEFAULT_BOUNDS
from driftlab.web.frames import EpisodeFrames
from driftlab.web.player import EpisodePlayer
from driftlab.web.scene import set_chase_camera, set_overview_camera
from driftlab.web.sources import JobHistory, track_of_spec

if TYPE_CHECKING:
    from driftlab.web.dashboard import Dashboard

FRAME_RATE_HZ = 30.0
TEXT_EVERY_FRAMES = 6  # HUD text and time slider at 5 Hz: enough to read, a fraction of the traffic
STATE_PLOTS = (("V_mps", "V_ref_mps", "V [m/s]"), ("beta_rad", "beta_ref_rad", "beta [rad]"),
               ("r_radps", "r_ref_radps", "r [rad/s]"), ("delta_rad", "delta_ref_rad", "delta [rad]"))
# What-if plant sliders: (config key, label, min, max, step).
PLANT_SLIDERS = (("plant.friction_scale", "mu scale", 0.8, 1.3, 0.01),
                 ("plant.tyre_c_scale", "tyre C scale", 0.8, 1.4, 0.01),
                 ("plant.steer_lag_s", "steer lag [s]", 0.0, 0.1, 0.005),
                 ("plant.cg_height_m", "CG height [m]", 0.0, 0.8, 0.05))
NO_JOB = "(no jobs yet: start one with POST /api/jobs)"


def _series(label: str, color: str, *, points: bool = False, width: float = 1.5) -> dict[str, Any]:
    if points:
        return {"label": label, "stroke": color, "width": 0, "points": {"show": True, "size": 6, "fill": color}}
    return {"label": label, "stroke": color, "width": width, "points": {"show": False}}


def padded_range(values: np.ndarray, min_span: float = 0.0) -> tuple[float, float]:
    """A y range around the finite values, 8% padded and at least ``min_span`` wide (uPlot puts a single tick
    on a range much narrower than its tick spacing: the steering plot had one)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return (-1.0, 1.0)
    lo, hi = float(finite.min()), float(finite.max())
    pad = max(0.08 * (hi - lo), 0.05, 0.5 * (min_span - (hi - lo)))
    return (lo - pad, hi + pad)


def job_label(job_id: int, name: str, status: str) -> str:
    return f"{job_id} · {name} · {status}"


class ClientSession:
    def __init__(self, client: viser.ClientHandle, dashboard: Dashboard) -> None:
        self.client = client
        self.dashboard = dashboard
        self.lock = threading.RLock()
        self.mode = "live"
        self.playing = True
        self.speed = 1.0
        self.history: JobHistory | None = None
        self.best_frames: EpisodeFrames | None = None
        self.theta_bounds: dict[str, tuple[float, float]] = dict(DEFAULT_BOUNDS)
        self._closed = threading.Event()
        self._what_if_requested_at: float | None = None
        self.last_what_if_latency_s: float | None = None
        client.scene.set_up_direction("+z")
        set_overview_camera(client.camera)
        self.player = EpisodePlayer(client.scene)
        self._build_gui(client.gui)
        self._thread = threading.Thread(target=self._run, name=f"driftlab-view-{client.client_id}", daemon=True)
        self._thread.start()

    # ----- GUI -------------------------------------------------------------------------------------------
    def _build_gui(self, gui: viser.GuiApi) -> None:
        gui.configure_theme(control_width="large", dark_mode=False)
        gui.add_markdown("**DriftLab**: inertia drift around the 8, tuned by Bayesian optimization.")
        self.job_dropdown = gui.add_dropdown("Job", (NO_JOB,))
        self.job_dropdown.on_update(self._on_job_selected)
        self.job_text = gui.add_markdown("")
        self.convergence = gui.add_uplot(
            (np.zeros(1), np.full(1, np.nan), np.full(1, np.nan), np.full(1, np.nan)),
            (_series("evaluation", "#888"), _series("J", "#2a6fdb", points=True),
             _series("best so far", "#e8590c", width=2.5), _series("failed (at top)", "#c92a2a", points=True)),
            title="Convergence: J per evaluation", aspect=1.6, scales={"x": {"time": False}},
            axes=({"label": "evaluation"}, {"label": "J"}))
        with gui.add_folder("Playback"):
            self.hud = gui.add_markdown("")
            with gui.add_folder("Choose", expand_by_default=True):
                self.live_button = gui.add_button("Follow live", icon=viser.Icon.ACTIVITY)
                self.best_button = gui.add_button("Play best", icon=viser.Icon.TROPHY)
                self.index_input = gui.add_number("Evaluation index", 0, min=0, step=1,
                                                  hint="0-based index within the job (the API's 'index')")
                self.index_button = gui.add_button("Play evaluation at index")
            self.play_button = gui.add_button("Pause", icon=viser.Icon.PLAYER_PAUSE)
            self.chase_checkbox = gui.add_checkbox("Chase camera", False,
                                                   hint="Follow the car from behind, along its direction of travel")
            self.speed_slider = gui.add_slider("Speed (x real time)", 0.25, 8.0, 0.25, 1.0)
            self.time_slider = gui.add_slider("Time [s]", 0.0, 30.0, 0.1, 0.0)
        self.live_button.on_click(lambda _: self.follow_live())
        self.best_button.on_click(lambda _: self.play_best())
        self.index_button.on_click(lambda _: self.play_index(int(self.index_input.value)))
        self.play_button.on_click(lambda _: self.toggle_play())
        self.speed_slider.on_update(self._on_speed)
        self.time_slider.on_update(self._on_scrub)
        self.chase_checkbox.on_update(self._on_chase)
        with gui.add_folder("Episode states"):
            self.state_plots = [gui.add_uplot((np.zeros(1), np.zeros(1), np.zeros(1)),
                                              (_series("t [s]", "#888"), _series(label, "#2a6fdb"),
                                               _series("reference", "#e8590c")), title=label, aspect=2.5,
                                              scales={"x": {"time": False}})
                                for _, _, label in STATE_PLOTS]
        with gui.add_folder("What-if", expand_by_default=False):
            gui.add_markdown("Move a slider: that one episode runs in a worker and plays at once, with the "
                             "job's best episode as the blue ghost car.")
            self.theta_sliders = {k: gui.add_slider(k, lo, hi, (hi - lo) / 200.0, 0.5 * (lo + hi))
                                  for k, (lo, hi) in DEFAULT_BOUNDS.items()}
            self.plant_sliders = {key: gui.add_slider(label, lo, hi, step, lo)
                                  for key, label, lo, hi, step in PLANT_SLIDERS}
            self.what_if_text = gui.add_markdown("")
            reset = gui.add_button("Reset to the best theta and the job's plant")
        reset.on_click(lambda _: self.reset_what_if_sliders())
        for slider in (*self.theta_sliders.values(), *self.plant_sliders.values()):
            slider.on_update(self._on_what_if_slider)
        with gui.add_folder("Downloads", expand_by_default=False):
            self.downloads = gui.add_markdown("")

    def set_job_options(self, jobs: list[tuple[int, str, str]]) -> None:
        options = tuple(job_label(*j) for j in jobs) or (NO_JOB,)
        with self.lock:
            current = self.history.job_id if self.history else None
            self.job_dropdown.options = options
            chosen = next((o for o in options if current is not None and o.startswith(f"{current} ·")), None)
            if chosen is None and jobs:
                chosen = options[-1]  # the newest job
            if chosen is not None and self.job_dropdown.value != chosen:
                self.job_dropdown.value = chosen  # fires _on_job_selected

    def _on_job_selected(self, _event: viser.GuiEvent) -> None:
        label = self.job_dropdown.value
        if label == NO_JOB:
            return
        job_id = int(label.split(" ·")[0])
        if self.history is not None and self.history.job_id == job_id:
            return
        history = self.dashboard.history(job_id)
        with self.lock:
            self.history = history
            self.best_frames = None
            self.player.set_track(track_of_spec(history.spec))
            self.theta_bounds = {k: tuple(v) for k, v in history.spec.get("bounds", DEFAULT_BOUNDS).items()}
            self.on_history(history)
            self.reset_what_if_sliders(run=False)
            self.follow_live()

    # ----- job updates (from the dashboard's poller) ------------------------------------------------------
    def on_history(self, history: JobHistory) -> None:
        if self.history is None or history.job_id != self.history.job_id:
            return
        index, j_done, best, failed = history.convergence()
        if len(index) == 0:
            index, j_done, best, failed = (np.zeros(1), np.full(1, np.nan), np.full(1, np.nan), np.full(1, np.nan))
        self.convergence.data = (index, j_done, best, failed)
        # Explicit ranges: uPlot cannot auto-range a series that starts with NaN (a gap), and viser's client
        # keeps the x extent of the first data it saw; x spans the whole job, so the plot shows progress too.
        x_max = float(max(history.iterations - 1, len(index) - 1, 1))
        self.convergence.scales = {"x": {"time": False, "range": (0.0, x_max)},
                                   "y": {"range": padded_range(j_done)}}
        best_pos = history.best_position()
        best_text = "none completed yet" if best_pos is None else (
            f"**{history.values[best_pos]:.3f}** (lower is better), evaluation id {history.ids[best_pos]} "
            f"(index {best_pos})")
        self.job_text.content = (f"**{history.name}**: {history.status}, {history.n_done} / {history.iterations} "
                                 f"evaluations, {sum(history.completed)} completed; best J {best_text}")

    # ----- choosing what plays -----------------------------------------------------------------------------
    def follow_live(self) -> None:
        with self.lock:
            self.mode = "live"
            self.playing = True
            self._load_latest()

    def _load_latest(self) -> None:
        history = self.history
        if history is None:
            return
        if history.n_done == 0:  # nothing of this job to show: not the previous job's episode under its name
            self.player.unload()
            self._show_hud()
            return
        self._load(self.dashboard.frames(history.ids[-1]))

    def play_best(self) -> None:
        with self.lock:
            best = self._best()
            if best is None:
                self.hud.content = "No completed evaluation yet."
                return
            self.mode = "rewatch"
            self.playing = True
            self._load(best)

    def play_index(self, index: int) -> None:
        with self.lock:
            if self.history is None or not 0 <= index < self.history.n_done:
                n = 0 if self.history is None else self.history.n_done
                self.hud.content = f"Evaluation # must be in [0, {n - 1}]; this job has {n} evaluations."
                return
            self.mode = "rewatch"
            self.playing = True
            self._load(self.dashboard.frames(self.history.ids[index]))

    def _best(self) -> EpisodeFrames | None:
        if self.history is None:
            return None
        pos = self.history.best_position()
        if pos is None:
            return None
        if self.best_frames is None or self.best_frames.index != pos:
            self.best_frames = self.dashboard.frames(self.history.ids[pos])
        return self.best_frames

    def _load(self, frames: EpisodeFrames, ghost: EpisodeFrames | None = None) -> None:
        self.player.load(frames, ghost)
        self.time_slider.max = max(self.player.duration_s, 0.1)
        self._show_states(frames)
        self._show_downloads(frames)
        self._show_hud()

    def _show_states(self, frames: EpisodeFrames) -> None:
        t = frames.column("t_s")
        for plot, (actual, reference, _) in zip(self.state_plots, STATE_PLOTS, strict=True):
            plot.data = (t, frames.column(actual), frames.column(reference))
            both = np.concatenate([frames.column(actual), frames.column(reference)])
            plot.scales = {"x": {"time": False, "range": (0.0, max(float(t[-1]), 0.1))},
                           "y": {"range": padded_range(both, min_span=0.4)}}

    def _show_downloads(self, frames: EpisodeFrames) -> None:
        if frames.evaluation_id is None:
            self.downloads.content = "This what-if episode is not stored; the downloads are for stored evaluations."
            return
        base = f"/api/evaluations/{frames.evaluation_id}"
        self.downloads.content = (
            f"{frames.name().capitalize()}:\n\n"
            f"- [trajectory CSV]({base}/trajectory?format=csv)\n"
            f"- [trajectory JSON]({base}/trajectory?format=json)\n"
            f"- [recording (.viser)]({base}/recording.viser)\n"
            f"- [standalone HTML replay]({base}/replay.html)\n"
            f"- [open the recording in the viewer](/viser/?playbackPath={base}/recording.viser)")

    # ----- playback controls ---------------------------------------------------------------------------------
    def toggle_play(self) -> None:
        with self.lock:
            if not self.playing and self.player.finished:
                self.player.seek(0.0)
            self.playing = not self.playing
            self.play_button.label = "Pause" if self.playing else "Play"
            self.play_button.icon = viser.Icon.PLAYER_PAUSE if self.playing else viser.Icon.PLAYER_PLAY

    def _on_speed(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.speed = float(self.speed_slider.value)

    def _on_chase(self, event: viser.GuiEvent) -> None:
        if event.client is not None and not self.chase_checkbox.value:
            set_overview_camera(self.client.camera)

    def _follow_with_camera(self) -> None:
        frames = self.player.frames
        if self.chase_checkbox.value and frames is not None and frames.n_frames:
            i = frames.index_at(self.player.t_s)
            x_m, y_m, _, _ = frames.pose_at(i)
            set_chase_camera(self.client.camera, x_m, y_m, frames.course_at(i))

    def _on_scrub(self, event: viser.GuiEvent) -> None:
        if event.client is None:  # our own 5 Hz update of the slider
            return
        with self.lock:
            self.player.seek(float(self.time_slider.value))
            self._show_hud()

    def _show_hud(self) -> None:
        frames = self.player.frames
        if frames is None:
            name = f" of job **{self.history.name}**" if self.history is not None else ""
            self.hud.content = f"Waiting for the first evaluation{name}..."
            return
        mode = {"live": "Live (follows the job)", "rewatch": "Rewatch", "what-if": "What-if"}[self.mode]
        lines = [f"**{mode}** · t {self.player.t_s:5.1f} / {frames.duration_s:.1f} s", frames.caption()]
        if self.player.ghost_frames is not None:
            lines.append(f"ghost (blue): {self.player.ghost_frames.caption()}")
        if self.mode == "live" and self.history is not None and self.history.n_done:
            lines.append(f"newest: evaluation id {self.history.ids[-1]} (index {self.history.n_done - 1})")
        self.hud.content = "\n\n".join(lines)

    # ----- what-if -----------------------------------------------------------------------------------------
    def reset_what_if_sliders(self, run: bool = True) -> None:
        if self.history is None:
            return
        best = self._best()
        theta = best.theta if best is not None else {k: 0.5 * (lo + hi) for k, (lo, hi) in DEFAULT_BOUNDS.items()}
        plant = self.history.spec.get("config", {}).get("plant", {})
        with self.client.atomic():
            for key, slider in self.theta_sliders.items():
                lo, hi = self.theta_bounds.get(key, DEFAULT_BOUNDS[key])
                slider.min, slider.max, slider.step = lo, hi, (hi - lo) / 200.0
                slider.value = float(np.clip(theta[key], lo, hi))
            for key, slider in self.plant_sliders.items():
                value = plant.get(key.split(".", 1)[1], slider.value)
                slider.value = float(np.clip(value, slider.min, slider.max))
        if run:
            self._request_what_if()

    def _on_what_if_slider(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self._request_what_if()

    def _request_what_if(self) -> None:
        if self.history is None:
            return
        theta = {k: float(s.value) for k, s in self.theta_sliders.items()}
        overrides = {k: float(s.value) for k, s in self.plant_sliders.items()}
        self._what_if_requested_at = time.perf_counter()
        self.what_if_text.content = "running..."
        self.dashboard.what_if.request(self, theta, self.history.spec.get("config", {}), overrides)

    def on_what_if_result(self, frames: EpisodeFrames | None, error: str | None, worker_ms: float) -> None:
        """Called by the what-if runner with the latest request's episode."""
        with self.lock:
            if error is not None:
                self.what_if_text.content = f"**error**: {error}"
                return
            self.mode = "what-if"
            self.playing = True
            self._load(frames, ghost=self._best())
            started = self._what_if_requested_at
            latency = ""
            if started is not None:  # the first frame of the new episode is queued by now
                self.last_what_if_latency_s = time.perf_counter() - started
                latency = f", first frame **{1000 * self.last_what_if_latency_s:.0f} ms** after the slider"
            self.what_if_text.content = (f"{frames.status}, J {frames.J:.3f}; episode {worker_ms:.0f} ms in the "
                                         f"worker{latency}")

    # ----- the 30 Hz loop ------------------------------------------------------------------------------------
    def close(self) -> None:
        self._closed.set()

    def _run(self) -> None:
        period = 1.0 / FRAME_RATE_HZ
        next_tick = time.perf_counter()
        tick = 0
        while not self._closed.is_set():
            next_tick += period
            delay = next_tick - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                next_tick = time.perf_counter()  # fell behind: drop frames rather than burst
            tick += 1
            try:
                with self.client.atomic():  # one frame's messages reach the browser together
                    self._tick(period, tick % TEXT_EVERY_FRAMES == 0)
            except Exception:  # a closed connection mid-frame ends the loop, never the server
                if self._closed.is_set():
                    return
                raise

    def _tick(self, period_s: float, show_text: bool) -> None:
        with self.lock:
            if self.player.frames is None:
                if self.mode == "live" and self.history is not None and self.history.n_done:
                    self._load_latest()
                return
            if not self.playing:
                return
            if self.player.finished:
                self._at_end()
                return
            self.player.seek(self.player.t_s + period_s * self.speed)
            self._follow_with_camera()
            if show_text:
                self.time_slider.value = round(self.player.t_s, 1)
                self._show_hud()

    def _at_end(self) -> None:
        if self.mode == "live":
            self._load_latest()  # the newest evaluation, or the same one again
        else:
            self.playing = False
            self.play_button.label = "Play"
            self.play_button.icon = viser.Icon.PLAYER_PLAY
            self._show_hud()
