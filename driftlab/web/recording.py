"""Episodes as viser recordings: a ``.viser`` file for ``/viser/?playbackPath=`` and a standalone HTML replay
(with a panel of the caption and the state plots, driftlab.web.replay_page).

Recorded on a private viser server (port 0, loopback) so that live viewers never see a recording being
made. A 30 s episode at 30 frames per second records in a fraction of a second.
"""

from __future__ import annotations

import threading

import viser

from driftlab.core.track import FigureEight
from driftlab.web.frames import EpisodeFrames
from driftlab.web.player import EpisodePlayer
from driftlab.web.replay_page import with_panel
from driftlab.web.scene import set_replay_camera, set_world
from driftlab.web.viser_server import quiet_viser_server

RECORDING_FPS = 30.0


class EpisodeRecorder:
    def __init__(self, fps: float = RECORDING_FPS) -> None:
        self.fps = fps
        self._server: viser.ViserServer | None = None
        self._lock = threading.Lock()

    def _fresh_scene(self) -> viser.SceneApi:
        if self._server is None:
            self._server = quiet_viser_server(host="127.0.0.1", port=0)
            set_replay_camera(self._server.initial_camera)
        self._server.scene.reset()
        return self._server.scene

    def _record(self, frames: EpisodeFrames, track: FigureEight, *, caption_label: bool = True,
                ghost: EpisodeFrames | None = None) -> viser.infra.StateSerializer:
        scene = self._fresh_scene()
        set_world(scene)
        player = EpisodePlayer(scene, track)
        serializer = self._server.get_scene_serializer()
        player.load(frames, ghost)
        if caption_label:  # the .viser file has no page around it: the caption is a label in the scene
            player.show_caption(frames.caption())
        step_s = 1.0 / self.fps
        n_steps = int(player.duration_s * self.fps) + 1
        for k in range(n_steps + 1):
            player.seek(min(k * step_s, player.duration_s))
            serializer.insert_sleep(step_s)
        return serializer

    def viser_file(self, frames: EpisodeFrames, track: FigureEight) -> bytes:
        with self._lock:
            return self._record(frames, track).serialize()

    def html(self, frames: EpisodeFrames, track: FigureEight, ghost: EpisodeFrames | None = None) -> str:
        """A standalone replay page; ``ghost``: another episode driven beside it (a translucent car)."""
        with self._lock:
            # The HTML replay shows the caption and the state plots in a panel beside the 3D view.
            return with_panel(self._record(frames, track, caption_label=False, ghost=ghost).as_html(), frames,
                              ghost)

    def stop(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None
