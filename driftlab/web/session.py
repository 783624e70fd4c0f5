"""One browser tab: its own job selection and convergence plot, and its parts on its own scene and GUI:
playback (driftlab.web.playback), what-if (driftlab.web.what_if) and compare (driftlab.web.compare).

The tab reads through the view app (a :class:`TabData`) and never the other way round, except for the
results the view app hands back: new evaluations (:meth:`ClientSession.on_history`), a what-if episode
(:meth:`ClientSession.on_what_if_result`) and the study list (:meth:`ClientSession.set_study_options`).
"""

from __future__ import annotations

import threading
import time
from typing import Any, Protocol

import numpy as np
import viser
import viser.uplot

from driftlab.markup import plain
from driftlab.services.read_model import compiling, drift_window_text
from driftlab.web.compare import ComparePanel
from driftlab.web.frames import EpisodeFrames
from driftlab.web.playback import Playback
from driftlab.web.plots import padded_range, series
from driftlab.web.scene import set_overview_camera, set_world
from driftlab.web.sources import JobHistory, car_geometry_of_spec, track_of_spec
from driftlab.web.what_if import WhatIfPanel

FRAME_RATE_HZ = 30.0
TEXT_EVERY_FRAMES = 6  # HUD text and time slider at 5 Hz: enough to read, a fraction of the traffic
NO_JOB = "(no jobs yet: start one with POST /api/jobs)"


class TabData(Protocol):
    """What a tab reads and asks of the view app."""

    def history(self, job_id: int) -> JobHistory: ...

    def frames(self, evaluation_id: int) -> EpisodeFrames: ...

    def studies(self) -> list[tuple[int, str, str, str]]: ...

    def study(self, study_id: int) -> dict[str, Any]: ...

    def compare(self, job_ids: list[int]) -> list[dict[str, Any]]: ...

    def config_diff(self, job_ids: list[int]) -> dict[str, Any]: ...

    def request_what_if(self, session: ClientSession, theta: dict[str, float], config_doc: dict[str, Any],
                        plant_overrides: dict[str, float], seed: int) -> None: ...

    def enqueue(self, job_id: int, theta: dict[str, float]) -> str: ...


def job_label(job_id: int, name: str, status: str) -> str:
    return f"{job_id} · {name} · {status}"


class ClientSession:
    def __init__(self, client: viser.ClientHandle, data: TabData) -> None:
        self.client = client
        self.data = data
        self.lock = threading.RLock()
        self.history: JobHistory | None = None
        self.best_frames: EpisodeFrames | None = None
        self._closed = threading.Event()
        set_world(client.scene)
        set_overview_camera(client.camera)
        gui = client.gui
        gui.configure_theme(control_width="large", dark_mode=False)
        self._build_job_gui(gui)
        self.playback = Playback(client, history=lambda: self.history, frames_of=data.frames, best=self._best,
                                 lock=self.lock)
        self.what_if = WhatIfPanel(gui, client, lambda *args: data.request_what_if(self, *args), self._best,
                                   enqueue=data.enqueue)
        self.what_if.gui_reset.on_click(lambda _: self.what_if.reset_sliders(self._best()))
        self.playback.build_downloads(gui)
        self.compare = ComparePanel(gui, read_studies=data.studies, read_study=data.study,
                                    read_compare=data.compare, read_config_diff=data.config_diff,
                                    play_together=self._play_together, lock=self.lock)
        self._thread = threading.Thread(target=self._run, name=f"driftlab-view-{client.client_id}", daemon=True)
        self._thread.start()

    # ----- the job and its convergence ---------------------------------------------------------------------
    def _build_job_gui(self, gui: viser.GuiApi) -> None:
        gui.add_markdown("**DriftLab**: inertia drift around the 8, tuned by Bayesian optimization.")
        self.job_dropdown = gui.add_dropdown("Job", (NO_JOB,))
        self.job_dropdown.on_update(self._on_job_selected)
        self.job_text = gui.add_markdown("")
        self.window_text = gui.add_markdown("")
        self.convergence = gui.add_uplot(
            (np.zeros(1), np.full(1, np.nan), np.full(1, np.nan), np.full(1, np.nan)),
            (series("evaluation", "#888"), series("J", "#2a6fdb", points=True),
             series("best so far", "#e8590c", width=2.5), series("failed (at top)", "#c92a2a", points=True)),
            title="Convergence: J per evaluation", aspect=1.6, scales={"x": {"time": False}},
            axes=({"label": "evaluation"}, {"label": "J"}))

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

    def set_study_options(self, studies: list[tuple[int, str, str, str]]) -> None:
        with self.lock:
            self.compare.set_study_options(studies)

    def _on_job_selected(self, _event: viser.GuiEvent) -> None:
        label = self.job_dropdown.value
        if label == NO_JOB:
            return
        job_id = int(label.split(" ·")[0])
        if self.history is not None and self.history.job_id == job_id:
            return
        history = self.data.history(job_id)
        with self.lock:
            self.history = history
            self.best_frames = None
            self.playback.player.set_track(track_of_spec(history.spec))
            self.playback.player.set_car(*car_geometry_of_spec(history.spec))
            self.what_if.select_job(history)
            self.on_history(history)
            self.what_if.reset_sliders(self._best(), run=False)
            self.playback.follow_live()
            self.window_text.content = "**Drift window**: computing..."
        threading.Thread(target=self._show_drift_window, args=(history,), daemon=True,
                         name=f"driftlab-window-{self.client.client_id}").start()

    def _show_drift_window(self, history: JobHistory) -> None:
        text = drift_window_text(history.spec)  # seconds for a CommonRoad car: not under the tab's lock
        with self.lock:
            if self.history is history:
                self.window_text.content = text

    def on_history(self, history: JobHistory) -> None:
        """New evaluations or a new status of a job (from the view app's poller)."""
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
            f"**{history.values[best_pos]:.4g}** (lower is better), evaluation id {history.ids[best_pos]} "
            f"(index {best_pos})")
        waits = " (**compiling the simulation**: numba, once after an install)" if compiling(history.status) else ""
        self.job_text.content = (f"**{plain(history.name)}**: {history.status}{waits}, {history.n_done} / "
                                 f"{history.iterations} evaluations, {sum(history.completed)} completed; "
                                 f"best J {best_text}")

    def _best(self) -> EpisodeFrames | None:
        if self.history is None:
            return None
        pos = self.history.best_position()
        if pos is None:
            return None
        if self.best_frames is None or self.best_frames.index != pos:
            self.best_frames = self.data.frames(self.history.ids[pos])
        return self.best_frames

    # ----- results handed back -----------------------------------------------------------------------------
    def on_what_if_result(self, frames: EpisodeFrames | None, error: str | None, worker_ms: float) -> None:
        """Called by the what-if runner with the latest request's episode."""
        with self.lock:
            if error is not None:
                self.what_if.show_error(error)
                self.playback.show_what_if_error(error)
                self.client.add_notification("What-if not run", error, color="red", auto_close_seconds=12.0)
                return
            self.playback.play_what_if(frames, ghost=self.what_if.ghost)
            self.what_if.show_result(frames, worker_ms)

    @property
    def last_what_if_latency_s(self) -> float | None:
        return self.what_if.last_latency_s

    def _play_together(self, evaluation_ids: list[int], captions: list[str]) -> None:
        episodes = [self.data.frames(i) for i in evaluation_ids]
        with self.lock:
            self.playback.play_together(episodes, captions)

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
                with self.client.atomic(), self.lock:  # one frame's messages reach the browser together
                    self.playback.tick(period, tick % TEXT_EVERY_FRAMES == 0)
            except Exception:  # a closed connection mid-frame ends the loop, never the server
                if self._closed.is_set():
                    return
                raise
