"""Log sampled hindsight-goal tuples (o, g, d, tau^a, tau^o) of a LeRobot dataset to a rerun recording,
to check goals and strides (L_o / S_o, L_a / S_a, L_g) by eye.

Sample ``n`` is logged at time ``sample = n`` under ``sample_{n}/`` (``env_viz`` maps states/actions to 3-D):

=================================  ==========================================================================
``sample_{n}/world/obs``           o_k as point(s) (``EnvViz.state_points`` of ``observation.state``)
``sample_{n}/world/goal``          g = o_{k+d}
``sample_{n}/world/obs_traj``      tau^o (FM-PC/PS/AS): L_o states S_o frames apart, as a strip with points
``sample_{n}/world/action_traj``   tau^a: L_a actions S_a frames apart (``EnvViz.action_points``)
``sample_{n}/world/episode``       the whole state path of the sample's episode, for context
``sample_{n}/d``                   d (frames to the goal), scalar
``sample_{n}/action``              tau^a per dimension, over the sample's own ``offset`` timeline (frames)
``sample_{n}/images/<cam>``        o_k camera frames; ``goal_images/<cam>`` g; ``traj_images/<cam>/<j>`` tau^o
``sample_{n}/info``                text: frame index, episode, d
``summary/d``                      d of every sample on the ``sample`` timeline
=================================  ==========================================================================
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import torch

from ..configuration_efm import GOAL_DISTANCE_KEY, GOAL_PREFIX, OBS_PREFIX, TRAJ_PREFIX
from .env_viz import STATE_KEY, EnvViz, get_env_viz
from .rollout_log import CHUNK_COLOR, GOAL_COLOR, PLAN_COLOR
from .unnormalize import to_hwc_uint8, to_numpy

OBS_COLOR = (210, 40, 40)
EPISODE_COLOR = (170, 170, 170)


def _points(viz: EnvViz, state: np.ndarray) -> np.ndarray:
    """(..., S) -> (P, ..., 3): every named point of ``viz.state_points`` stacked."""
    return np.stack(list(viz.state_points(np.asarray(state, np.float32)).values()))


def log_hindsight_samples(
    rec: rr.RecordingStream, dataset, indices, env_viz: EnvViz | None = None
) -> list[dict]:
    """Log ``dataset[i]`` for every ``i`` of ``indices`` (a :class:`HindsightGoalDataset`); returns, per
    sample, its frame index, episode and d (the values logged)."""
    viz = env_viz or get_env_viz(None)
    spec = dataset.spec
    state_all = dataset.vectors.get(STATE_KEY)
    logged = []
    for n, idx in enumerate(indices):
        item = dataset[int(idx)]
        root = f"sample_{n}"
        d = float(item[GOAL_DISTANCE_KEY])
        k, ep = int(idx), int(item["episode_index"])
        rec.set_time("sample", sequence=n)
        rec.log("summary/d", rr.Scalars([d]))
        rec.log(f"{root}/d", rr.Scalars([d]))
        rec.log(
            f"{root}/info",
            rr.TextDocument(
                f"sample {n}: dataset row {k} (frame index {int(item['index'])}, episode {ep}), d = {int(d)} frames, "
                f"goal row {k + int(d)}; L_o={spec.obs_traj_len} S_o={spec.obs_traj_stride} "
                f"L_a={spec.action_traj_len} S_a={spec.action_traj_stride} L_g={spec.max_goal_distance}"
            ),
        )
        if STATE_KEY in item:
            obs = _points(viz, to_numpy(item[STATE_KEY]))  # (P, 3)
            goal = _points(viz, to_numpy(item[GOAL_PREFIX + STATE_KEY[len(OBS_PREFIX) :]]))
            rec.log(
                f"{root}/world/obs", rr.Points3D(obs, colors=[OBS_COLOR], radii=0.03, labels=["o"] * len(obs))
            )
            rec.log(
                f"{root}/world/goal",
                rr.Points3D(goal, colors=[GOAL_COLOR], radii=0.04, labels=[f"g (d={int(d)})"] * len(goal)),
            )
            traj_key = TRAJ_PREFIX + STATE_KEY[len(OBS_PREFIX) :]
            if traj_key in item:
                traj = _points(viz, to_numpy(item[traj_key]))  # (P, L_o, 3)
                rec.log(
                    f"{root}/world/obs_traj",
                    rr.LineStrips3D(list(traj), colors=[PLAN_COLOR] * len(traj), radii=0.008),
                )
                rec.log(
                    f"{root}/world/obs_traj_points",
                    rr.Points3D(traj.reshape(-1, 3), colors=[PLAN_COLOR], radii=0.018),
                )
            if state_all is not None:
                lo, hi = int(dataset.episode_start[k]), int(dataset.episode_end[k])
                path = _points(viz, to_numpy(state_all[lo:hi]))
                rec.log(
                    f"{root}/world/episode",
                    rr.LineStrips3D(list(path), colors=[EPISODE_COLOR] * len(path), radii=0.003),
                )
        actions = to_numpy(item["action"])  # (L_a, A), raw units
        pts = viz.action_points(actions) if viz.action_points else None
        if pts is not None:
            rec.log(f"{root}/world/action_traj", rr.LineStrips3D([pts], colors=[CHUNK_COLOR], radii=0.006))
        rec.log(
            f"{root}/action", rr.SeriesLines(names=[f"a{i}" for i in range(actions.shape[-1])]), static=True
        )
        for j, a in enumerate(actions):
            rec.set_time("offset", sequence=j * spec.action_traj_stride)
            rec.log(f"{root}/action", rr.Scalars(a.astype(np.float64)))
        rec.disable_timeline("offset")
        for key, value in item.items():
            if not isinstance(value, torch.Tensor) or value.ndim < 3:
                continue
            for prefix, sub in (
                (GOAL_PREFIX, "goal_images"),
                (TRAJ_PREFIX, "traj_images"),
                (OBS_PREFIX, "images"),
            ):
                if key.startswith(prefix + "images."):
                    cam = key[len(prefix + "images.") :]
                    if sub == "traj_images":
                        for j, frame in enumerate(value):
                            rec.log(f"{root}/{sub}/{cam}/{j}", rr.Image(to_hwc_uint8(frame)))
                    else:
                        rec.log(f"{root}/{sub}/{cam}", rr.Image(to_hwc_uint8(value)))
                    break
        logged.append({"sample": n, "row": k, "episode": ep, "d": d})
    return logged


def samples_blueprint(n: int, cameras: list[str]) -> rrb.Blueprint:
    tabs = []
    for i in range(n):
        root = f"/sample_{i}"
        views = [rrb.Spatial3DView(origin=f"{root}/world", name="o, g, tau")]
        images = [rrb.Spatial2DView(origin=f"{root}/images/{c}", name=f"o {c}") for c in cameras]
        images += [rrb.Spatial2DView(origin=f"{root}/goal_images/{c}", name=f"g {c}") for c in cameras]
        side = [
            *images,
            rrb.TimeSeriesView(origin=f"{root}/action", name="tau^a"),
            rrb.TextDocumentView(origin=f"{root}/info"),
        ]
        views.append(rrb.Vertical(*side))
        tabs.append(rrb.Horizontal(*views, name=f"sample {i}"))
    tabs.append(rrb.TimeSeriesView(origin="/summary", name="d over samples"))
    return rrb.Blueprint(rrb.Tabs(*tabs), collapse_panels=False)
