"""How rerun draws the PointReach env (``--env.type=efm_point_reach``): the point, the arena and the wall."""

from __future__ import annotations

import numpy as np
import rerun as rr

from ..viz.env_viz import STATE_KEY, EnvViz, pad3


def _point_reach_scene(rec: rr.RecordingStream) -> None:
    from lerobot_efm.envs.point_reach import WALL_HALF_WIDTH, WALL_TOP

    square = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [-1, -1, 0]]
    w = WALL_HALF_WIDTH
    wall = [[-w, -1, 0], [w, -1, 0], [w, WALL_TOP, 0], [-w, WALL_TOP, 0], [-w, -1, 0]]
    rec.log("scene/arena", rr.LineStrips3D([square], colors=[(120, 120, 120)], radii=0.004), static=True)
    rec.log("scene/wall", rr.LineStrips3D([wall], colors=[(60, 60, 60)], radii=0.008), static=True)


POINT_REACH_VIZ = EnvViz(
    state_points=lambda s: {"agent": pad3(np.asarray(s)[..., :2])},
    action_points=lambda a: pad3(np.asarray(a)[..., :2]),  # absolute position commands
    scene=_point_reach_scene,
    dim_names={STATE_KEY: ("x", "y")},
    eye=((0.0, -1.5, 2.3), (0.0, -0.1, 0.0)),  # from above, slightly tilted: the 2-D arena stays readable
)
