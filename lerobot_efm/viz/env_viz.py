"""How rerun draws an env: :class:`EnvViz` says which observation / action dimensions are positions, which are
objects, and what static scene to log. Each env keeps its own next to it (``envs/<env>/viz.py``); this module holds
the class, the generic fallbacks and the registry from ``--env.type`` names to them (imported on first use)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import rerun as rr
from lerobot.utils.constants import OBS_ENV_STATE, OBS_STATE

STATE_KEY, ENV_STATE_KEY = OBS_STATE, OBS_ENV_STATE


def pad3(x: np.ndarray) -> np.ndarray:
    """(..., k) -> (..., 3): the first 3 dims, zero-padded (2-D positions get z = 0)."""
    x = np.asarray(x, dtype=np.float32)
    out = np.zeros((*x.shape[:-1], 3), dtype=np.float32)
    k = min(3, x.shape[-1])
    out[..., :k] = x[..., :k]
    return out


@dataclass
class EnvViz:
    """How to draw an env in 3-D (and name its vectors in the plots).

    state_points: (..., S) unnormalised ``observation.state`` -> {name: (..., 3)} positions to draw
        (also applied to ``observation.goal.state`` and to planned states).
    action_points: (..., A) unnormalised actions -> (..., 3), or None when actions are not positions.
    scene: optional callback ``scene(rec)`` logging static geometry under ``scene/``.
    object_points: other vector observation key (e.g. ``observation.environment_state``) -> callback
        (D,) -> {name: (3,)}: objects drawn at ``ep/world/<name>`` with their path (goal: ``goal_<name>``).
    object_series: observation key -> callback (D,) -> {name: float}: object states plotted under
        ``ep/objects/<name>``, the goal's under ``ep/objects/goal_<name>`` (names are entity path parts).
    dim_names: observation key -> one name per dimension, the legend of ``ep/obs/<key>`` series (and, prefixed
        with ``goal``, of its goal mirror).
    eye: ``(position, look_target)`` of the 3-D view's camera (z up), None for rerun's default.
    object_series_title: the name of the plot of ``object_series``.
    """

    state_points: Callable[[np.ndarray], dict[str, np.ndarray]]
    action_points: Callable[[np.ndarray], np.ndarray | None] | None = None
    scene: Callable[[rr.RecordingStream], None] | None = None
    object_points: dict[str, Callable[[np.ndarray], dict[str, np.ndarray]]] = field(default_factory=dict)
    object_series: dict[str, Callable[[np.ndarray], dict[str, float]]] = field(default_factory=dict)
    dim_names: dict[str, Sequence[str]] = field(default_factory=dict)
    eye: tuple[Sequence[float], Sequence[float]] | None = None
    object_series_title: str = "objects (thin: goal)"


def _default_state_points(state: np.ndarray) -> dict[str, np.ndarray]:
    return {"agent": pad3(state)}


DEFAULT_ENV_VIZ = EnvViz(state_points=_default_state_points, action_points=pad3)


def hand_points(
    commanded: slice = slice(0, 3), measured: slice | None = None, action: slice | None = None
) -> EnvViz:
    """An EnvViz for arms whose state holds the commanded and (optionally) measured hand positions and whose
    actions hold the hand position command at ``action`` (default: the ``commanded`` slice of the state).
    Talos: ``envs/talos_kitchen/viz.py`` (``observation.state[0:3]`` commanded, ``[10:13]`` measured)."""
    action = commanded if action is None else action

    def state_points(s: np.ndarray) -> dict[str, np.ndarray]:
        s = np.asarray(s)
        points = {"hand_commanded": pad3(s[..., commanded])}
        if measured is not None:
            points["hand_measured"] = pad3(s[..., measured])
        return points

    return EnvViz(state_points=state_points, action_points=lambda a: pad3(np.asarray(a)[..., action]))


_ENV_VIZ: dict[str, EnvViz] = {}

# Geometry kept next to its env, imported on first use (module:attribute): the env modules import MuJoCo.
_LAZY_ENV_VIZ = {
    "efm_point_reach": "lerobot_efm.envs.point_reach_viz:POINT_REACH_VIZ",
    "talos_kitchen": "lerobot_efm.envs.talos_kitchen.viz:TALOS_KITCHEN_VIZ",
    "planar_push": "lerobot_efm.envs.planar_push.viz:PLANAR_PUSH_VIZ",
    "ogbench": "lerobot_efm.ogbench.viz:OGBENCH_VIZ",
}


def register_env_viz(env_type: str, viz: EnvViz) -> None:
    """Declare how to draw the env ``env_type`` (the ``--env.type`` name)."""
    _ENV_VIZ[env_type] = viz


def get_env_viz(env_type: str | None) -> EnvViz:
    """The env's :class:`EnvViz`; :data:`DEFAULT_ENV_VIZ` (state dims as one xyz point) for unknown envs."""
    if env_type in _LAZY_ENV_VIZ and env_type not in _ENV_VIZ:
        module, attr = _LAZY_ENV_VIZ[env_type].split(":")
        _ENV_VIZ[env_type] = getattr(importlib.import_module(module), attr)
    return _ENV_VIZ.get(env_type or "", DEFAULT_ENV_VIZ)
