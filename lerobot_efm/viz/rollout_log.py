"""Log EFM policy rollouts to a rerun recording (an ``.rrd`` file, no viewer needed).

Everything of episode ``i`` lives under ``episode_{i}/`` on two timelines: ``step`` (control step, a
sequence) and ``time`` (``step / fps`` seconds, a duration). Entity paths (``ep`` = ``episode_{i}``):

=================================  ==========================================================================
``ep/camera/render``               ``env.render()`` frame (optional)
``ep/camera/<cam>``                ``observation.images.<cam>`` as seen by the policy (before normalisation)
``ep/goal/<cam>``                  ``observation.goal.images.<cam>`` (goal image)
``ep/world/<name>``                3-D point of the agent (``EnvViz.state_points``; point env: ``agent``; Talos:
                                   ``hand_commanded``, ``hand_measured``) or of an object (``EnvViz.object_points``;
                                   Talos: ``pot``, ``door_handle``, ``tray_handle``)
``ep/world/<name>_path``           the trajectory so far (line strip)
``ep/world/goal_<name>``           the goal point (from ``observation.goal.state`` / ``.goal.environment_state``)
``ep/world/action_chunk``          at each replanning: the predicted action chunk (``EnvViz.action_points``)
``ep/world/obs_plan``              planned observations ``obs_plan`` (FM-PC/PS/AS), when they are low-dimensional
``ep/world/candidates``            FM-PS/FM-AS: every candidate plan/chunk, the chosen one thick and red
``ep/action``                      executed action (unnormalised), one series per dimension
``ep/action_chunk/r<step>``        the chunk predicted at ``<step>``, over the steps it covers
``ep/distance/critic``             critic estimate of the steps to the goal, at each replanning
``ep/distance/true_remaining``     steps actually left, back-filled once the episode succeeded
``ep/distance/candidates``         FM-PS/FM-AS: the critic score of every candidate
``ep/obs/<key>``                   vector observations (``observation.state``, ``observation.environment_state``...),
                                   series named by ``EnvViz.dim_names``
``ep/objects/<name>``              object states (``EnvViz.object_series``; Talos: door, tray, pot_x/y/z), the
                                   goal's as ``ep/objects/goal_<name>``; a policy trained with an auxiliary
                                   state head: its reading of the camera at each replan, ``read_<name>``
                                   and ``read_goal_<name>`` (points)
``ep/goal_obs/<key>``              vector goal observations (``observation.goal.state``...)
``ep/reward``, ``ep/success``      per step
``ep/info/<key>``                  numeric ``info`` entries of the env (point env: ``distance``)
``ep/events``                      text log: replans, end of episode
``scene/...``                      static env geometry (point env: arena and wall; Talos: table, cabinet, workspace)
=================================  ==========================================================================

Env-specific geometry is a hook: :func:`lerobot_efm.viz.env_viz.register_env_viz` maps an env type
(``--env.type``) to an :class:`~lerobot_efm.viz.env_viz.EnvViz` saying which observation / action dimensions are
positions; each env keeps its own next to it (``envs/<env>/viz.py``).
"""

from __future__ import annotations

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import torch
from lerobot.utils.constants import OBS_IMAGES

from ..configuration_efm import GOAL_PREFIX
from .env_viz import STATE_KEY, EnvViz, get_env_viz
from .unnormalize import latent_to_states, to_hwc_uint8, to_numpy, unnormalize_actions

GOAL_STATE_KEY = GOAL_PREFIX + "state"
IMAGE_PREFIX = OBS_IMAGES + "."
GOAL_IMAGE_PREFIX = GOAL_PREFIX + "images."

CHOSEN_COLOR = (230, 40, 40)
CANDIDATE_COLOR = (150, 150, 150)
CHUNK_COLOR = (40, 90, 230)
PLAN_COLOR = (240, 150, 20)
GOAL_COLOR = (40, 170, 60)
AGENT_COLOR = (210, 40, 40)
# the state_points / object_points of an env, in order (first: the agent, as AGENT_COLOR)
POINT_COLORS = ((210, 40, 40), (150, 60, 200), (230, 140, 20), (20, 160, 170), (140, 90, 40), (200, 60, 140))
OBJECT_COLOR_OFFSET = 2  # objects take the palette after the (usually two) agent points


class RolloutLogger:
    """Logs rollouts of one policy in one env type to a ``rr.RecordingStream``.

    Usage per episode: ``begin_episode(i)``; per step ``log_observation(t, obs)`` (the observation after
    LeRobot's ``preprocess_observation`` and the env preprocessor, batch of 1), ``log_prediction(t, pred)``
    when the policy replanned, ``log_action(t, action)``, ``log_outcome(t, reward, success, info)``;
    finally ``end_episode(length, success)``. ``blueprint()`` gives the default layout.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        env_type: str | None,
        fps: float,
        policy=None,
        preprocessor=None,
        postprocessor=None,
        env_viz: EnvViz | None = None,
    ):
        self.rec, self.fps = rec, float(fps)
        self.policy, self.preprocessor, self.postprocessor = policy, preprocessor, postprocessor
        self.viz = env_viz or get_env_viz(env_type)
        self.episodes: list[dict] = []
        self.cameras: set[str] = set()
        self.goal_cameras: set[str] = set()
        self._goal_images: dict[str, np.ndarray] = {}  # the goal image last logged per camera, this episode
        self._static_done: set[str] = set()
        if self.viz.scene is not None:
            self.viz.scene(rec)

    # --- helpers -----------------------------------------------------------------------------------
    @property
    def ep(self) -> str:
        return f"episode_{self.episodes[-1]['index']}"

    def set_step(self, step: int) -> None:
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("time", duration=float(step) / self.fps)

    def _series_names(self, path: str, names: list[str], color=None) -> None:
        if path in self._static_done:
            return
        self._static_done.add(path)
        kwargs = {} if color is None else {"colors": [color] * len(names)}
        self.rec.log(path, rr.SeriesLines(names=names, **kwargs), static=True)

    def _scalars(self, path: str, values, names: list[str] | None = None, color=None) -> None:
        values = np.atleast_1d(np.asarray(values, dtype=np.float64)).reshape(-1)
        self._series_names(
            path,
            names
            or ([path.rsplit("/", 1)[-1]] if len(values) == 1 else [f"{i}" for i in range(len(values))]),
            color,
        )
        self.rec.log(path, rr.Scalars(values))

    # --- episode -----------------------------------------------------------------------------------
    def begin_episode(self, index: int, task: str | None = None, seed: int | None = None) -> None:
        self.episodes.append(
            {"index": int(index), "path": {}, "length": None, "success": None, "task": task, "seed": seed}
        )
        self.set_step(0)
        self._goal_images = {}
        self.rec.log(f"{self.ep}/events", rr.TextLog(f"episode {index} starts (task={task!r}, seed={seed})"))

    def log_render(self, step: int, frame) -> None:
        img = to_hwc_uint8(frame) if frame is not None else None
        if img is not None:
            self.set_step(step)
            self.cameras.add("render")
            self.rec.log(f"{self.ep}/camera/render", rr.Image(img))

    def _dim_names(self, key: str, size: int) -> list[str]:
        """Legend of the series of observation ``key`` (its goal mirror: the observation's names, 'goal ' first)."""
        base, prefix = key, ""
        if key.startswith(GOAL_PREFIX):
            base, prefix = "observation." + key[len(GOAL_PREFIX) :], "goal "
        names = self.viz.dim_names.get(base)
        if names is None or len(names) != size:
            return [f"{prefix}{i}" for i in range(size)]
        return [f"{prefix}{n}" for n in names]

    def _log_points(self, points: dict[str, np.ndarray], color_offset: int = 0) -> None:
        """Each named 3-D point at ``ep/world/<name>`` and its path so far at ``ep/world/<name>_path``."""
        paths = self.episodes[-1]["path"]
        for j, (name, p) in enumerate(points.items()):
            color = POINT_COLORS[(color_offset + j) % len(POINT_COLORS)]
            paths.setdefault(name, []).append(np.asarray(p, np.float32).reshape(3))
            self.rec.log(
                f"{self.ep}/world/{name}", rr.Points3D([paths[name][-1]], colors=[color], radii=0.03)
            )
            self.rec.log(
                f"{self.ep}/world/{name}_path",
                rr.LineStrips3D([np.stack(paths[name])], colors=[color], radii=0.006),
            )

    def _log_goal_points(self, points: dict[str, np.ndarray]) -> None:
        for name, p in points.items():
            self.rec.log(
                f"{self.ep}/world/goal_{name}",
                rr.Points3D([np.asarray(p).reshape(3)], colors=[GOAL_COLOR], radii=0.04),
            )

    def _log_object_series(self, values: dict[str, float], goal: bool, readout: bool = False) -> None:
        """Object states (door angle...) under ``ep/objects/<name>``; the goal's, thin, under ``goal_<name>``;
        what the policy's auxiliary head reads from the camera, as points, under ``read_<name>`` /
        ``read_goal_<name>``."""
        for j, (name, v) in enumerate(values.items()):
            part = ("read_" if readout else "") + ("goal_" if goal else "")
            path = f"{self.ep}/objects/{part}{name}"
            if path not in self._static_done:
                self._static_done.add(path)
                color = POINT_COLORS[(OBJECT_COLOR_OFFSET + j) % len(POINT_COLORS)]
                label = ("read " if readout else "") + ("goal " if goal else "") + name
                style = (
                    rr.SeriesPoints(names=[label], colors=[color], marker_sizes=[2.0 if goal else 3.0])
                    if readout
                    else rr.SeriesLines(names=[label], colors=[color], widths=[1.0 if goal else 2.5])
                )
                self.rec.log(path, style, static=True)
            self.rec.log(path, rr.Scalars([float(v)]))

    def log_observation(self, step: int, observation: dict) -> None:
        self.set_step(step)
        ep = self.ep
        vectors: dict[str, np.ndarray] = {}
        for key, value in observation.items():
            if not isinstance(value, (torch.Tensor, np.ndarray)):
                continue
            if key.startswith(GOAL_IMAGE_PREFIX):
                cam = key[len(GOAL_IMAGE_PREFIX) :]
                img = to_hwc_uint8(value)
                if img is not None and not np.array_equal(img, self._goal_images.get(cam)):
                    self.goal_cameras.add(cam)  # logged when it changes (a goal sequence), not every step
                    self._goal_images[cam] = img
                    self.rec.log(f"{ep}/goal/{cam}", rr.Image(img))
            elif key.startswith(IMAGE_PREFIX):
                cam = key[len(IMAGE_PREFIX) :]
                img = to_hwc_uint8(value)
                if img is not None:
                    self.cameras.add(cam)
                    self.rec.log(f"{ep}/camera/{cam}", rr.Image(img))
            elif key.startswith("observation.") and to_numpy(value).ndim <= 2:
                vec = vectors[key] = to_numpy(value).reshape(-1)
                if key.startswith(GOAL_PREFIX):
                    self._scalars(
                        f"{ep}/goal_obs/{key[len(GOAL_PREFIX) :]}", vec, self._dim_names(key, len(vec))
                    )
                else:
                    self._scalars(
                        f"{ep}/obs/{key[len('observation.') :]}", vec, self._dim_names(key, len(vec))
                    )
        if STATE_KEY in vectors:
            self._log_points(self.viz.state_points(vectors[STATE_KEY]))
        if GOAL_STATE_KEY in vectors:
            self._log_goal_points(self.viz.state_points(vectors[GOAL_STATE_KEY]))
        for key, points in self.viz.object_points.items():
            goal_key = GOAL_PREFIX + key[len("observation.") :]
            if key in vectors:
                self._log_points(points(vectors[key]), OBJECT_COLOR_OFFSET)
            if goal_key in vectors:
                self._log_goal_points(points(vectors[goal_key]))
        for key, series in self.viz.object_series.items():
            goal_key = GOAL_PREFIX + key[len("observation.") :]
            if key in vectors:
                self._log_object_series(series(vectors[key]), goal=False)
            if goal_key in vectors:
                self._log_object_series(series(vectors[goal_key]), goal=True)

    def log_action(self, step: int, action) -> None:
        self.set_step(step)
        a = to_numpy(action).reshape(-1)
        self._scalars(f"{self.ep}/action", a, [f"a{i}" for i in range(len(a))])

    def _log_readout(self, prediction: dict) -> None:
        """The auxiliary head's reading of the observation and goal (``auxiliary_state``, in the recording's
        units), plotted as points next to the true object states, at every replan."""
        key = getattr(getattr(self.policy, "config", None), "auxiliary_state_key", None)
        series = self.viz.object_series.get(key)
        for name, goal in (("auxiliary_state", False), ("auxiliary_goal_state", True)):
            if name not in prediction:
                continue
            value = to_numpy(prediction[name])[0]
            if series is not None:
                self._log_object_series(series(value), goal=goal, readout=True)
            else:
                prefix = f"{self.ep}/readout/{'goal_' if goal else ''}{key.removeprefix('observation.')}"
                self._scalars(prefix, value, self._dim_names(key, len(value)))

    def log_prediction(self, step: int, prediction: dict) -> None:
        """What the policy believed when it replanned at ``step`` (``policy.last_prediction``, batch row 0)."""
        self.set_step(step)
        ep, cfg = self.ep, getattr(self.policy, "config", None)
        stride = int(getattr(cfg, "action_traj_stride", 1) or 1)
        self.rec.log(f"{ep}/events", rr.TextLog(f"replan at step {step}"))
        if "action" in prediction:
            chunk = unnormalize_actions(self.postprocessor, prediction["action"][:1])[0]  # (L_a, A)
            pts = self.viz.action_points(chunk) if self.viz.action_points else None
            if pts is not None:
                self.rec.log(
                    f"{ep}/world/action_chunk", rr.LineStrips3D([pts], colors=[CHUNK_COLOR], radii=0.008)
                )
            names = [f"a{i}" for i in range(chunk.shape[-1])]
            path = f"{ep}/action_chunk/r{step:04d}"
            self._series_names(path, [f"{n} @{step}" for n in names])
            for j, a in enumerate(chunk):  # waypoint j covers control step step + j * S_a
                self.set_step(step + j * stride)
                self.rec.log(path, rr.Scalars(a.astype(np.float64)))
            self.set_step(step)
        self._log_readout(prediction)
        if "distance" in prediction:
            d = float(to_numpy(prediction["distance"]).reshape(-1)[0])
            self._series_names(f"{ep}/distance/critic", ["critic estimate (steps)"], (40, 90, 230))
            self.rec.log(f"{ep}/distance/critic", rr.Scalars([d]))
        scores = prediction.get("candidate_distances")
        scores = None if scores is None else to_numpy(scores)[0]
        chosen = prediction.get("chosen_candidate")
        chosen = None if chosen is None else int(to_numpy(chosen).reshape(-1)[0])
        if scores is not None:
            self._scalars(f"{ep}/distance/candidates", scores, [f"c{i}" for i in range(len(scores))])
        if "obs_plan" in prediction:
            states = latent_to_states(self.policy, self.preprocessor, prediction["obs_plan"][:1])
            if states is not None and STATE_KEY in states:
                strips = list(self.viz.state_points(states[STATE_KEY][0]).values())
                self.rec.log(
                    f"{ep}/world/obs_plan",
                    rr.LineStrips3D(strips, colors=[PLAN_COLOR] * len(strips), radii=0.01),
                )
        candidates = None
        if "candidate_obs_plans" in prediction:
            states = latent_to_states(self.policy, self.preprocessor, prediction["candidate_obs_plans"][:1])
            if states is not None and STATE_KEY in states:
                candidates = list(self.viz.state_points(states[STATE_KEY][0]).values())[0]  # (N, L_o, 3)
        elif "candidate_actions" in prediction and self.viz.action_points:
            raw = unnormalize_actions(self.postprocessor, prediction["candidate_actions"][:1])[
                0
            ]  # (N, L_a, A)
            candidates = self.viz.action_points(raw)
        if candidates is not None:
            n = len(candidates)
            colors = [CHOSEN_COLOR if i == chosen else CANDIDATE_COLOR for i in range(n)]
            radii = [0.012 if i == chosen else 0.003 for i in range(n)]
            labels = [f"{i}: {scores[i]:.1f}" if scores is not None else str(i) for i in range(n)]
            self.rec.log(
                f"{ep}/world/candidates",
                rr.LineStrips3D(
                    list(candidates), colors=colors, radii=radii, labels=labels, show_labels=False
                ),
            )

    def log_outcome(self, step: int, reward: float, success: bool, info: dict | None = None) -> None:
        """Reward and success of the transition taken at ``step``."""
        self.set_step(step)
        ep = self.ep
        self._scalars(f"{ep}/reward", [float(reward)], ["reward"])
        self._scalars(f"{ep}/success", [float(bool(success))], ["success"])
        for key, value in (info or {}).items():
            if key.startswith("_") or key in ("is_success", "final_info", "final_obs"):
                continue
            v = np.asarray(value)
            if v.dtype.kind in "fiub" and v.size == 1:
                self._scalars(f"{ep}/info/{key}", [float(v.reshape(-1)[0])], [key])

    def log_event(self, step: int, text: str) -> None:
        """A text line in the episode's event log at ``step`` (e.g. how a grasp ended)."""
        self.set_step(step)
        self.rec.log(f"{self.ep}/events", rr.TextLog(text, level=rr.TextLogLevel.INFO))

    def end_episode(self, length: int, success: bool) -> None:
        """``length`` env steps were taken; on success, back-fill the true number of steps left."""
        ep = self.ep
        self.episodes[-1].update(length=int(length), success=bool(success))
        if success:
            self._series_names(f"{ep}/distance/true_remaining", ["true steps left"], (40, 170, 60))
            for t in range(length + 1):
                self.set_step(t)
                self.rec.log(f"{ep}/distance/true_remaining", rr.Scalars([float(length - t)]))
        self.set_step(length)
        self.rec.log(
            f"{ep}/events",
            rr.TextLog(
                f"episode {self.episodes[-1]['index']} ends after {length} steps, success={bool(success)}",
                level=rr.TextLogLevel.INFO,
            ),
        )

    # --- layout ------------------------------------------------------------------------------------
    def blueprint(self, episodes: list[int] | None = None) -> rrb.Blueprint:
        """One tab per episode (``episodes``: indices; default the logged ones): cameras and goal images | the 3-D
        world | plots, events below. The side panels start collapsed and the time cursor at the end of the
        recording (the whole trajectory shows)."""
        eye = (
            None
            if self.viz.eye is None
            else rrb.EyeControls3D(
                position=self.viz.eye[0], look_target=self.viz.eye[1], eye_up=(0.0, 0.0, 1.0)
            )
        )
        tabs = []
        for index in [e["index"] for e in self.episodes] if episodes is None else episodes:
            ep = f"episode_{index}"
            images = [rrb.Spatial2DView(origin=f"/{ep}/camera/{c}", name=c) for c in sorted(self.cameras)]
            images += [
                rrb.Spatial2DView(origin=f"/{ep}/goal/{c}", name=f"goal {c}")
                for c in sorted(self.goal_cameras)
            ]
            world = rrb.Spatial3DView(
                origin="/", contents=["/scene/**", f"/{ep}/world/**"], name="world", eye_controls=eye
            )
            plots = [
                rrb.TimeSeriesView(origin=f"/{ep}/distance", name="distance to goal (steps)"),
                rrb.TimeSeriesView(
                    origin=f"/{ep}",
                    contents=[f"/{ep}/action", f"/{ep}/action_chunk/**"],
                    name="actions & chunks",
                    plot_legend=rrb.PlotLegend(visible=False),
                ),  # one series per dim and chunk: too long
            ]
            if self.viz.object_series:
                plots.append(rrb.TimeSeriesView(origin=f"/{ep}/objects", name=self.viz.object_series_title))
            plots.append(
                rrb.TimeSeriesView(
                    origin=f"/{ep}",
                    contents=[
                        f"/{ep}/obs/**",
                        f"/{ep}/goal_obs/**",
                        f"/{ep}/reward",
                        f"/{ep}/success",
                        f"/{ep}/info/**",
                    ],
                    name="state, reward, success",
                    plot_legend=rrb.PlotLegend(visible=False),
                )
            )
            left = [rrb.Vertical(*images)] if images else []
            columns = [*left, world, rrb.Vertical(*plots)]
            shares = ([1] if left else []) + [2, 1.4]
            tabs.append(
                rrb.Vertical(
                    rrb.Horizontal(*columns, column_shares=shares),
                    rrb.TextLogView(origin=f"/{ep}/events", name="events"),
                    row_shares=[6, 1],
                    name=ep,
                )
            )
        root = rrb.Tabs(*tabs) if len(tabs) > 1 else (tabs[0] if tabs else rrb.Spatial3DView(origin="/"))
        return rrb.Blueprint(
            root,
            rrb.BlueprintPanel(state="collapsed"),
            rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(timeline="step", state="collapsed", play_state="following"),
        )
