"""How rerun draws OGBench pointmaze (``--env.type=ogbench``): the point's (x, y) on the floor. Its actions are
velocities in [-1, 1], not positions, so they are plotted, not drawn in the maze."""

from __future__ import annotations

import numpy as np

from ..viz.env_viz import STATE_KEY, EnvViz, pad3

OGBENCH_VIZ = EnvViz(
    state_points=lambda s: {"agent": pad3(np.asarray(s)[..., :2])},
    action_points=None,
    dim_names={STATE_KEY: ("x", "y")},
)
