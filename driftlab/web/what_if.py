"""A tab's what-if panel: sliders for theta (within the job's bounds) and the main plant mismatch settings;
moving one asks for that episode (the view app's what-if runner runs it in a worker) and reports its result.

The episode runs on the seed of the ghost it is compared with (the best evaluation's drawn episode, its worst
seed), so the two J beside each other are one episode each on the same car and noise: with no slider moved the
what-if episode is the ghost's, bit for bit. A slider left where the panel put it contributes the stored value
itself, not the slider's (clipped, stepped) one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import viser

from driftlab.core.config import Theta
from driftlab.core.tuning import DEFAULT_BOUNDS, MODEL_BOUNDS
from driftlab.markup import plain
from driftlab.services.read_model import plant_settings
from driftlab.web.frames import EpisodeFrames
from driftlab.web.sources import JobHistory

# What-if plant sliders: (config key, label, min, max, step).
PLANT_SLIDERS = (("plant.friction_scale", "mu scale", 0.8, 1.3, 0.01),
                 ("plant.tyre_c_scale", "tyre C scale", 0.8, 1.4, 0.01),
                 ("plant.steer_lag_s", "steer lag [s]", 0.0, 0.1, 0.005),
                 ("plant.cg_height_m", "CG height [m]", 0.0, 0.8, 0.05))

# Every theta key has a slider, the model corrections too (a job that did not learn them shows them at 1).
SLIDER_BOUNDS = {**DEFAULT_BOUNDS, **MODEL_BOUNDS}

# request(theta, config_doc, plant overrides, seed): run that episode, answer through WhatIfPanel.show_result.
WhatIfRequest = Callable[[dict[str, float], dict[str, Any], dict[str, float], int], None]


# enqueue(job_id, theta): add the theta to the job (evaluated next); returns what to say.
WhatIfEnqueue = Callable[[int, dict[str, float]], str]


class WhatIfPanel:
    def __init__(self, gui: viser.GuiApi, client: viser.ClientHandle, request: WhatIfRequest,
                 best: Callable[[], EpisodeFrames | None], enqueue: WhatIfEnqueue | None = None) -> None:
        self.client = client
        self.request = request
        self.best = best
        self.enqueue = enqueue
        self.ghost: EpisodeFrames | None = None  # the episode the last request is compared with
        self._placed: dict[str, tuple[float, float]] = {}  # slider key -> (value the panel set, the exact value)
        self.history: JobHistory | None = None
        self.theta_bounds: dict[str, tuple[float, float]] = dict(SLIDER_BOUNDS)
        self._requested_at: float | None = None
        self.last_latency_s: float | None = None
        with gui.add_folder("What-if", expand_by_default=False):
            gui.add_markdown("Move a slider: that one episode runs in a worker and plays at once, with the "
                             "job's best episode as the blue ghost car, on the ghost's seed (the same car and "
                             "noise: the two J compare one episode with one episode).")
            self.theta_sliders = {k: gui.add_slider(k, lo, hi, (hi - lo) / 200.0, 0.5 * (lo + hi))
                                  for k, (lo, hi) in SLIDER_BOUNDS.items()}
            self.plant_sliders = {key: gui.add_slider(label, lo, hi, step, lo)
                                  for key, label, lo, hi, step in PLANT_SLIDERS}
            self.text = gui.add_markdown("")
            self.gui_reset = gui.add_button("Reset to the best theta and the job's plant")
            self.gui_add = gui.add_button("Add this theta to the job (evaluated next)")
            self.add_text = gui.add_markdown("")
        self.gui_add.on_click(lambda _: self.add_to_job())
        for slider in (*self.theta_sliders.values(), *self.plant_sliders.values()):
            slider.on_update(self._on_slider)

    def select_job(self, history: JobHistory) -> None:
        self.history = history
        self.theta_bounds = {**SLIDER_BOUNDS,
                             **{k: tuple(v) for k, v in history.spec.get("bounds", DEFAULT_BOUNDS).items()}}

    def reset_sliders(self, best: EpisodeFrames | None, run: bool = True) -> None:
        """Theta at the job's best (or the bounds' middle), the plant at the job's own."""
        if self.history is None:
            return
        learned = self.history.spec.get("bounds", DEFAULT_BOUNDS)
        middle = {k: 0.5 * (lo + hi) for k, (lo, hi) in learned.items()}
        theta = Theta.filled(best.theta if best is not None else middle)
        plant = plant_settings(self.history.spec)
        placed: dict[str, tuple[float, float]] = {}
        with self.client.atomic():
            for key, slider in self.theta_sliders.items():
                lo, hi = self.theta_bounds[key]
                slider.min, slider.max, slider.step = lo, hi, (hi - lo) / 200.0
                slider.value = float(np.clip(theta[key], lo, hi))
                placed[key] = (float(slider.value), float(theta[key]))
            for key, slider in self.plant_sliders.items():
                name = key.split(".", 1)[1]
                slider.value = float(np.clip(plant[name], slider.min, slider.max))
                placed[key] = (float(slider.value), float(plant[name]))
        self._placed = placed
        if run:
            self.ask()

    def _on_slider(self, event: viser.GuiEvent) -> None:
        if event.client is not None:
            self.ask()

    def _moved(self, key: str, slider: Any) -> bool:
        placed = self._placed.get(key)
        return placed is None or float(slider.value) != placed[0]

    def ask(self) -> None:
        if self.history is None:
            return
        theta = self.theta()
        # Only the plant settings a user moved: the job's own config holds the rest exactly.
        overrides = {k: float(s.value) for k, s in self.plant_sliders.items() if self._moved(k, s)}
        self.ghost = self.best()
        seed = self.ghost.seed if self.ghost is not None and self.ghost.seed is not None else 0
        self._requested_at = time.perf_counter()
        self.text.content = "running..."
        self.request(theta, self.history.spec.get("config", {}), overrides, seed)

    def theta(self) -> dict[str, float]:
        """The sliders' theta (a slider left where the panel put it: the stored value itself)."""
        return {k: float(s.value) if self._moved(k, s) else self._placed[k][1] for k, s in self.theta_sliders.items()}

    def add_to_job(self) -> None:
        """Enqueue the sliders' theta (the keys the job learns) for the job (driftlab.services.enqueue)."""
        if self.history is None or self.enqueue is None:
            return
        learned = self.history.spec.get("bounds", DEFAULT_BOUNDS)
        theta = {k: v for k, v in self.theta().items() if k in learned}
        self.add_text.content = plain(self.enqueue(self.history.job_id, theta))

    def show_error(self, error: str) -> None:
        self.text.content = f"**error**: {plain(error)}"

    def show_result(self, frames: EpisodeFrames, worker_ms: float) -> None:
        """Called once the episode plays: its status, J and how long after the slider it started."""
        latency = ""
        if self._requested_at is not None:  # the first frame of the new episode is queued by now
            self.last_latency_s = time.perf_counter() - self._requested_at
            latency = f", first frame **{1000 * self.last_latency_s:.0f} ms** after the slider"
        ghost = "no ghost: the job has no completed evaluation yet"
        if self.ghost is not None:
            ghost = (f"ghost (evaluation id {self.ghost.evaluation_id}, same seed): J **{self.ghost.episode_J:.4g}**"
                     f" (its mean over {self.ghost.n_seeds} seeds: {self.ghost.J:.4g})")
        plant = ", ".join(f"{plain(k.split('.', 1)[1])} {v:.4g}" for k, v in frames.plant.items()) or "the job's"
        self.text.content = (f"what-if: {frames.status}, J **{frames.J:.4g}** (one episode, seed {frames.seed}); "
                             f"{ghost}; plant: {plant}; episode {worker_ms:.0f} ms in the worker{latency}")
