"""How rerun draws the planar push maze (``lerobot-efm-log-rollouts --env.type=planar_push``,
``lerobot-efm-log-dataset --env_type=planar_push``): the effector and the disc as two points on the maze floor
(not ``[eff_x, eff_y, obj_x]`` as one xyz point), the walls, the absolute effector command."""

from __future__ import annotations

import numpy as np
import rerun as rr

from ...viz.env_viz import STATE_KEY, EnvViz, pad3
from .env import STATE_NAMES
from .maze import ARENA, wall_boxes


def _state_points(state: np.ndarray) -> dict[str, np.ndarray]:
    s = np.asarray(state)
    return {"effector": pad3(s[..., 0:2]), "disc": pad3(s[..., 2:4])}


def _scene(rec: rr.RecordingStream) -> None:
    a = ARENA
    rec.log(
        "scene/arena",
        rr.LineStrips3D(
            [[[-a, -a, 0], [a, -a, 0], [a, a, 0], [-a, a, 0], [-a, -a, 0]]], colors=[(120, 120, 120)]
        ),
        static=True,
    )
    boxes = wall_boxes()
    rec.log(
        "scene/walls",
        rr.Boxes3D(
            centers=[[cx, cy, 0.02] for cx, cy, _, _ in boxes],
            half_sizes=[[hx, hy, 0.02] for _, _, hx, hy in boxes],
            colors=[(70, 70, 70)],
            fill_mode="solid",
        ),
        static=True,
    )


PLANAR_PUSH_VIZ = EnvViz(
    state_points=_state_points,
    action_points=lambda a: pad3(np.asarray(a)[..., :2]),  # absolute effector commands
    scene=_scene,
    dim_names={STATE_KEY: STATE_NAMES},
    eye=((0.0, -1.6, 2.6), (0.0, -0.1, 0.0)),
)
