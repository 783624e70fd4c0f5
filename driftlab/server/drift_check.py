"""The drift check a posted job gets (driftlab.core.drivability) without holding the request while the server
compiles it: on a fresh install the check's kernels (the drift equilibria's residuals) compile the first time they
run, ~20 s of a core, and a client that times out and retries makes a duplicate job. The server compiles them in the
background at start; a job posted before they are ready is stored at once and checked when its runner claims it
(driftlab.worker.job_loop: a job whose car cannot drift there fails saying why)."""

from __future__ import annotations

import threading

from driftlab.core.config import EpisodeConfig
from driftlab.core.configure import preset_config
from driftlab.core.drivability import check_drivable
from driftlab.core.errors import ConfigError

# The presets whose checks compile every kernel a check runs: DriftLab's plant and a CommonRoad car's fit.
WARMED_PRESETS = ("default", "commonroad_std")
DEFERRED = ("the server is still compiling its drift check (a fresh install): this job's drift is checked when it "
            "starts, and a job whose car cannot drift there fails saying why")


class DriftCheck:
    """Checks a posted config now once the check is compiled (:meth:`warm_in_background`); until then says it is
    deferred. Ready from the start where nothing warms it (an in-process app checks every config at once)."""

    def __init__(self) -> None:
        self.ready = threading.Event()
        self.ready.set()

    def warm_in_background(self) -> None:
        self.ready.clear()
        threading.Thread(target=self._warm, name="drift-check-warm-up", daemon=True).start()

    def _warm(self) -> None:
        try:
            for plant in WARMED_PRESETS:
                try:
                    check_drivable(preset_config(plant))
                except ConfigError:
                    pass  # compiled all the same
        finally:
            self.ready.set()

    def check(self, config: EpisodeConfig) -> str | None:
        """Raises NotDrivableError (a ConfigError: 422) where the config cannot drift; returns :data:`DEFERRED`
        while the check is still compiling, else None."""
        if not self.ready.is_set():
            return DEFERRED
        check_drivable(config)
        return None
