"""What the 3D scene is made of: the figure-8, the car, its trail and the trigger markers.

Every function takes a viser ``SceneApi`` (a server's shared scene, one client's scene, or a recording
server's), so the live view and the ``.viser`` recordings draw the same things. World frame: x, y on the
ground as in :mod:`driftlab.core.track`, z up, metres.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import viser

from driftlab.core.track import LEFT, RIGHT, Circle, FigureEight
from driftlab.web.frames import EpisodeFrames, sideslip_colors

TRACK_Z_M = 0.02  # lines just above the ground plane, so they never z-fight with it
ROAD_HALF_WIDTH_M = 3.0
TRAIL_Z_M = 0.25  # lines are camera-facing ribbons: the trail sits higher so the highlight never covers it
_CIRCLE_SEGMENTS = 240  # smooth at any zoom: 1.15 m chords on a 44 m circle


def yaw_wxyz(yaw_rad: float) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of a rotation by ``yaw_rad`` about +z."""
    return (math.cos(0.5 * yaw_rad), 0.0, 0.0, math.sin(0.5 * yaw_rad))


def _polyline_segments(points_xy: np.ndarray, z_m: float) -> np.ndarray:
    """(n, 2) points -> (n - 1, 2, 3) line segments joining consecutive points."""
    xyz = np.column_stack([points_xy, np.full(len(points_xy), z_m)])
    return np.stack([xyz[:-1], xyz[1:]], axis=1)


def circle_points(circle: Circle, radius_offset_m: float = 0.0, n: int = _CIRCLE_SEGMENTS) -> np.ndarray:
    """(n + 1, 2) closed polyline of a circle, optionally offset outwards."""
    phi = np.linspace(0.0, 2.0 * math.pi, n + 1)
    radius = circle.radius_m + radius_offset_m
    return np.column_stack([circle.center_x_m + radius * np.cos(phi), circle.center_y_m + radius * np.sin(phi)])


def set_world(scene: viser.SceneApi) -> None:
    """z up, as the track's frame, and lit by viser's default lights alone, without its environment map: where
    WebGL runs without a GPU (a container, a remote desktop) the map's image-based lighting is most of each frame's
    work (docs/benchmarks.md, "The test suite's time"), and a flat track and a box car show nothing more with it."""
    scene.set_up_direction("+z")
    scene.configure_environment_map(hdri=None)


def set_overview_camera(camera) -> None:
    """Point a camera (a client's, or a server's initial camera) at the whole 8 from above one side."""
    # From -x: the left circle (y > 0) is on the left of the screen, as a driver at P0 would name it.
    camera.position = (-105.0, -25.0, 85.0)
    camera.look_at = (0.0, -25.0, 0.0)  # aimed right of the 8's centre so the 8 sits left of the control panel


def set_replay_camera(camera) -> None:
    """The whole 8 in the middle of the view (a recording has no control panel beside it)."""
    camera.position = (-118.0, 0.0, 95.0)
    camera.look_at = (0.0, 0.0, 0.0)


def set_chase_camera(camera, x_m: float, y_m: float, course_rad: float, *, behind_m: float = 16.0,
                     height_m: float = 8.0) -> None:
    """Behind the car along its direction of travel: the body's angle to the path is the sideslip."""
    camera.position = (x_m - behind_m * math.cos(course_rad), y_m - behind_m * math.sin(course_rad), height_m)
    camera.look_at = (x_m, y_m, 0.8)


def draw_track(scene: viser.SceneApi, track: FigureEight) -> dict[int, viser.LineSegmentsHandle]:
    """Ground, both circles with road edges, P0; returns the highlight of each circle (LEFT/RIGHT), hidden."""
    extent_x = 2.0 * max(track.left_radius_m, track.right_radius_m) + 40.0
    extent_y = 2.0 * (track.left_radius_m + track.right_radius_m) + 40.0
    scene.add_grid("/ground", width=extent_x, height=extent_y, plane="xy", cell_size=5.0, section_size=25.0,
                   plane_color=(236, 238, 232), plane_opacity=1.0, position=(0.0, 0.5 * (track.left_radius_m
                   - track.right_radius_m), 0.0), fade_distance=600.0)
    highlights = {}
    for direction, name in ((LEFT, "left"), (RIGHT, "right")):
        circle = track.circle(direction)
        scene.add_line_segments(f"/track/{name}/centre", _polyline_segments(circle_points(circle), TRACK_Z_M),
                                colors=(90, 90, 90), thickness=0.15)
        for side, offset in (("outer", ROAD_HALF_WIDTH_M), ("inner", -ROAD_HALF_WIDTH_M)):
            scene.add_line_segments(f"/track/{name}/{side}",
                                    _polyline_segments(circle_points(circle, offset), TRACK_Z_M),
                                    colors=(160, 160, 150), thickness=0.08)
        highlights[direction] = scene.add_line_segments(
            f"/track/{name}/tracked", _polyline_segments(circle_points(circle), 2.0 * TRACK_Z_M),
            colors=(255, 200, 110), thickness=0.7, visible=False)
    scene.add_cylinder("/track/p0/post", radius=0.25, height=3.0, color=(20, 20, 20), position=(0.0, 0.0, 1.5))
    start = "P0" if track.laps == 1 else f"P0 · {track.laps} laps"
    scene.add_label("/track/p0/label", start, position=(0.0, 0.0, 3.2), font_screen_scale=1.2)
    return highlights


# The car's heading drawn large on the ground: from the overview camera the 4.3 m car is ~15 px, too small to see
# which way it points; an arrow three car lengths long along the body axis, beside the trail (the direction of
# travel), shows the sideslip angle between them.
HEADING_ARROW_M = (-6.0, 2.5, 7.0)  # tail, start of the head, tip along the body axis [m from the CG]
HEADING_ARROW_HALF_WIDTH_M = (0.9, 2.6)  # shaft, head


def heading_arrow_mesh(z_m: float = 0.06) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a flat arrow along +x (the car's forward axis), counter-clockwise seen from above."""
    tail, neck, tip = HEADING_ARROW_M
    shaft, head = HEADING_ARROW_HALF_WIDTH_M
    xy = [(tail, -shaft), (neck, -shaft), (neck, shaft), (tail, shaft), (neck, -head), (tip, 0.0), (neck, head)]
    vertices = np.array([(x, y, z_m) for x, y in xy], dtype=np.float32)
    faces = np.array([(0, 1, 2), (0, 2, 3), (4, 5, 6)], dtype=np.uint32)
    return vertices, faces


class CarModel:
    """A body with a marked front (a light nose stripe and headlights), four wheels (the front ones turn with the
    applied steering angle), and its heading as a large arrow on the ground."""

    WHEEL_RADIUS_M = 0.33
    TRACK_HALF_WIDTH_M = 0.80
    STEER_RESEND_RAD = 0.005  # the steering is nearly constant while a drift is held: resend only on change

    def __init__(self, scene: viser.SceneApi, name: str, *, cg_to_front_m: float = 1.39,
                 cg_to_rear_m: float = 1.0, color=(220, 40, 40), opacity: float | None = None) -> None:
        self.root = scene.add_frame(f"/{name}", show_axes=False)
        length = cg_to_front_m + cg_to_rear_m + 1.9  # overhangs of a saloon
        body_centre_x = 0.5 * (cg_to_front_m - cg_to_rear_m)
        front_x = body_centre_x + 0.5 * length
        scene.add_box(f"/{name}/body", color=color, dimensions=(length, 1.8, 0.6), opacity=opacity,
                      position=(body_centre_x, 0.0, 0.6))
        scene.add_box(f"/{name}/cabin", color=(40, 40, 50), dimensions=(0.5 * length, 1.55, 0.5), opacity=opacity,
                      position=(body_centre_x - 0.2, 0.0, 1.1))
        scene.add_box(f"/{name}/nose", color=(250, 250, 235), dimensions=(0.7, 1.82, 0.08), opacity=opacity,
                      position=(front_x - 0.4, 0.0, 0.93))
        for side in (-1.0, 1.0):
            scene.add_box(f"/{name}/headlight_{'l' if side > 0 else 'r'}", color=(255, 240, 150),
                          dimensions=(0.06, 0.4, 0.18), opacity=opacity, position=(front_x + 0.02, 0.6 * side, 0.62))
        vertices, faces = heading_arrow_mesh()
        scene.add_mesh_simple(f"/{name}/heading", vertices, faces, color=color, side="double", cast_shadow=False,
                              receive_shadow=False, opacity=0.55 if opacity is None else 0.6 * opacity)
        axle_turn = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)  # cylinder axis z -> car's y
        self.front_wheels = []
        for label, x_m, y_m in (("fl", cg_to_front_m, self.TRACK_HALF_WIDTH_M),
                                ("fr", cg_to_front_m, -self.TRACK_HALF_WIDTH_M),
                                ("rl", -cg_to_rear_m, self.TRACK_HALF_WIDTH_M),
                                ("rr", -cg_to_rear_m, -self.TRACK_HALF_WIDTH_M)):
            hub = scene.add_frame(f"/{name}/{label}", show_axes=False, position=(x_m, y_m, self.WHEEL_RADIUS_M))
            scene.add_cylinder(f"/{name}/{label}/tyre", radius=self.WHEEL_RADIUS_M, height=0.25,
                               color=(25, 25, 25), wxyz=axle_turn, opacity=opacity)
            if label.startswith("f"):
                self.front_wheels.append(hub)
        self._pose: tuple[float, float, float] | None = None
        self._steer_rad = 0.0

    def set_pose(self, x_m: float, y_m: float, psi_rad: float, steer_rad: float) -> None:
        if self._pose != (x_m, y_m, psi_rad):
            self.root.position = (x_m, y_m, 0.0)
            self.root.wxyz = yaw_wxyz(psi_rad)
            self._pose = (x_m, y_m, psi_rad)
        if abs(steer_rad - self._steer_rad) >= self.STEER_RESEND_RAD:
            for hub in self.front_wheels:
                hub.wxyz = yaw_wxyz(steer_rad)
            self._steer_rad = steer_rad

    @property
    def visible(self) -> bool:
        return self.root.visible

    @visible.setter
    def visible(self, value: bool) -> None:
        self.root.visible = value


class Trail:
    """The path driven so far, coloured by sideslip, sent in chunks so a frame never resends the whole path."""

    def __init__(self, scene: viser.SceneApi, name: str, *, chunk_rows: int = 6, thickness_m: float = 0.8) -> None:
        self.scene = scene
        self.name = name
        self.chunk_rows = chunk_rows
        self.thickness_m = thickness_m
        self._chunks: list[viser.LineSegmentsHandle] = []
        self._drawn_until = 0

    def clear(self) -> None:
        for handle in self._chunks:
            handle.remove()
        self._chunks.clear()
        self._drawn_until = 0

    def advance(self, frames: EpisodeFrames, i: int, *, force: bool = False) -> None:
        """Draw rows up to i; a chunk goes out once ``chunk_rows`` rows are waiting (or when forced)."""
        if i < self._drawn_until:
            self.clear()
        if i - self._drawn_until < (1 if force else self.chunk_rows):
            return
        lo = max(self._drawn_until - 1, 0)
        xy = np.column_stack([frames.column("x_m")[lo:i + 1], frames.column("y_m")[lo:i + 1]])
        if len(xy) >= 2:
            segments = _polyline_segments(xy, TRAIL_Z_M)
            colors = sideslip_colors(frames.column("beta_rad")[lo:i])
            self._chunks.append(self.scene.add_line_segments(
                f"/{self.name}/{len(self._chunks)}", segments, colors=np.repeat(colors[:, None, :], 2, axis=1),
                thickness=self.thickness_m))
        self._drawn_until = i


TRIGGER_LABEL_Z_M = 4.6  # just above the 4 m post, so the chase camera sees it by the post, not in the sky
TRIGGER_LABEL_OFFSET_M = 5.0


def trigger_label_position(x_m: float, y_m: float) -> tuple[float, float, float]:
    """Beside the trigger post, pushed away from P0 (triggers fire a few metres before it, where the P0 label
    would cover the text)."""
    distance = math.hypot(x_m, y_m)
    ux, uy = (x_m / distance, y_m / distance) if distance > 1e-6 else (-1.0, 0.0)
    return (x_m + TRIGGER_LABEL_OFFSET_M * ux, y_m + TRIGGER_LABEL_OFFSET_M * uy, TRIGGER_LABEL_Z_M)


LABEL_MERGE_M = 10.0  # triggers closer than this share one label: two labels there would print over each other


def trigger_labels(points: Iterable[dict]) -> list[tuple[tuple[float, float, float], str]]:
    """(position, text) of each label: a trigger within ``LABEL_MERGE_M`` of an earlier label's trigger joins that
    label (the flick and the flick back both fire a few metres before P0), so labels never overlap there."""
    groups: list[tuple[float, float, list[str]]] = []
    for k, p in enumerate(points):
        text = f"trigger {k + 1}  t {p['t_s']:.2f} s"
        near = next((g for g in groups if math.hypot(p["x_m"] - g[0], p["y_m"] - g[1]) < LABEL_MERGE_M), None)
        if near is None:
            groups.append((p["x_m"], p["y_m"], [text]))
        else:
            near[2].append(text)
    return [(trigger_label_position(x, y), " · ".join(texts)) for x, y, texts in groups]


class TriggerMarkers:
    """A post where the planner switched sides and a label beside it, added as playback passes them."""

    def __init__(self, scene: viser.SceneApi, name: str = "triggers") -> None:
        self.scene = scene
        self.name = name
        self._posts: list[viser.SceneNodeHandle] = []
        self._labels: list[viser.LabelHandle] = []

    def clear(self) -> None:
        for handle in (*self._posts, *self._labels):
            handle.remove()
        self._posts.clear()
        self._labels.clear()

    def show(self, points: Iterable[dict]) -> None:
        """Show ``points`` (the trigger events passed so far, in order); only what changed is sent."""
        points = list(points)
        if len(points) < len(self._posts):
            self.clear()
        for k in range(len(self._posts), len(points)):
            p = points[k]
            # Thin and translucent: the chase camera, 16 m behind the car, looks past it in the second after a flick.
            self._posts.append(self.scene.add_cylinder(f"/{self.name}/{k}/post", radius=0.2, height=4.0,
                                                       color=(255, 190, 0), opacity=0.6,
                                                       position=(p["x_m"], p["y_m"], 2.0)))
        for k, (position, text) in enumerate(trigger_labels(points)):
            if k == len(self._labels):
                self._labels.append(self.scene.add_label(f"/{self.name}/label{k}", text, position=position))
            elif self._labels[k].text != text:
                self._labels[k].text = text
