"""Where a deployed policy's goal comes from when the robot's observations carry none.

LeRobot's deployment CLI (``lerobot-rollout``) hands the policy the robot's observation only; it knows nothing of
goals. An ``efm_*`` policy is therefore told its goal at deploy time with ``--policy.goal_path=goal.safetensors``
(a file written by ``lerobot-efm-goal``) or ``--policy.goal_dataset_root=DIR --policy.goal_episode=E
--policy.goal_frame=F`` (a frame of a LeRobot dataset, video frames decoded by LeRobot's decoder). The goal is a
plain observation (``observation.state``, ``observation.images.<cam>``); :func:`load_goals` turns it into the
policy's goal keys (``observation.goal.*``), checked against the checkpoint's features, and the pre-processor's
:class:`~lerobot_efm.processor_efm.AddBatchDimensionToGoalsStep` inserts it into every observation that lacks it,
before normalisation (the policy itself sees only normalised inputs).
"""

from __future__ import annotations

import logging
from pathlib import Path

import torch
from lerobot.utils.keyboard_input import create_key_listener

from .configuration_efm import GOAL_PREFIX, OBS_PREFIX, is_mirror_key
from .frames import Crop, crop_frames, fit_frames, resize_frame

log = logging.getLogger(__name__)

# The goals the pre-processor inserts into observations without one (goal key -> unbatched tensor), in order,
# and which one is current. Deployment CLIs rebuild the pre-processor from the checkpoint's JSON, so the saved
# step cannot receive the CLI's --policy.goal_* values; the policy, built from the CLI-overridden config, sets
# the goals here instead, and advances them when its critic says the current one is reached.
_deploy = {
    "goals": [],
    "index": 0,
    "image_shapes": {},
    "image_crop": None,
    "warned": set(),
    "key": None,
    "key_pressed": False,
    "listener": None,
}


def set_deploy_goal(
    goal: dict[str, torch.Tensor] | list[dict[str, torch.Tensor]] | None, advance_key: str | None = None
) -> None:
    """Replace the goal (or the sequence of goals) inserted into goal-less observations (None removes it).
    ``advance_key``: a key whose press moves a sequence on to its next goal (LeRobot's keyboard listener)."""
    goals = [] if not goal else [goal] if isinstance(goal, dict) else list(goal)
    _deploy["goals"], _deploy["index"], _deploy["key_pressed"] = goals, 0, False
    if _deploy["listener"] is not None:
        _deploy["listener"].stop()
    _deploy["key"], _deploy["listener"] = None, None
    if advance_key and len(goals) > 1:
        _deploy["key"] = advance_key
        _deploy["listener"] = create_key_listener(_on_key, controls_help=f"'{advance_key}' = next goal")


def _on_key(name: str) -> None:
    """Keyboard listener thread: remember the press; the control loop advances at its next action."""
    if name == _deploy["key"]:
        _deploy["key_pressed"] = True


def advance_deploy_goal_on_key() -> bool:
    """Move on to the next goal if the advance key was pressed since the last call; True when it advanced."""
    pressed, _deploy["key_pressed"] = _deploy["key_pressed"], False
    if not pressed or _deploy["index"] + 1 >= len(_deploy["goals"]):
        return False
    _deploy["index"] += 1
    log.info("key '%s': now goal %d of %d", _deploy["key"], _deploy["index"], len(_deploy["goals"]))
    return True


def set_image_shapes(shapes: dict[str, tuple[int, ...]], crop: Crop | None = None) -> None:
    """The (C, H, W) the policy's cameras were trained at, and the region of the frame they were taken from
    (``crop``, None = whole frame): live frames are cropped and resized to them, and so are goal images of those
    cameras that come with the observation (``observation.goal.images.*``)."""
    goals = {GOAL_PREFIX + k.removeprefix(OBS_PREFIX): s for k, s in shapes.items()}
    _deploy["image_shapes"], _deploy["image_crop"], _deploy["warned"] = {**shapes, **goals}, crop, set()


def fit_live_images(observation: dict) -> dict:
    """Resize camera frames (``observation.images.*``, (C, H, W) or (B, C, H, W) floats) whose size differs from
    the checkpoint's (a robot camera set to another resolution than the recording's), warning once per camera.
    A goal image that comes with the observation (``observation.goal.images.*``, e.g. from an env that renders
    its goal at the camera's size) is resized the same way, so goal and camera match what training saw. A policy
    trained on a crop of the camera (``image_crop``) gets the same crop of every frame first, which therefore
    must come at another size than the policy's input (a larger one: the crop keeps the detail)."""
    crop = _deploy["image_crop"]
    for key, shape in _deploy["image_shapes"].items():
        value = observation.get(key)
        if not isinstance(value, torch.Tensor):
            continue
        # Frames at the policy's size are taken as fitted already: training batches (cropped and resized by the
        # hindsight dataset) pass through this step too, and must not be cropped twice.
        if tuple(value.shape[-2:]) == tuple(shape[-2:]):
            continue
        if key not in _deploy["warned"] and crop is None:
            log.warning(
                "camera %s sends %s frames, the checkpoint was trained on %s: resized with OpenCV",
                key,
                tuple(value.shape[-3:]),
                tuple(shape),
            )
            _deploy["warned"].add(key)
        elif key not in _deploy["warned"] and _smaller(
            region := tuple(crop_frames(value, crop).shape[-2:]), shape
        ):
            log.warning(
                "camera %s: the crop %s of its %s frames is %s, smaller than the checkpoint's %s: upsampled; "
                "raise the camera's resolution to give the policy the detail it was trained on",
                key,
                crop,
                tuple(value.shape[-3:]),
                region,
                tuple(shape),
            )
            _deploy["warned"].add(key)
        frames = value.reshape(-1, *value.shape[-3:]).cpu()
        resized = fit_frames(frames, shape, crop)
        observation[key] = resized.reshape(*value.shape[:-3], *shape).to(value.device)
    return observation


def _smaller(region: tuple[int, ...], shape: tuple[int, ...]) -> bool:
    """Whether a cropped region is smaller than the policy's (C, H, W) input in height or width (upsampled)."""
    return region[0] < shape[-2] or region[1] < shape[-1]


def deploy_goal() -> dict[str, torch.Tensor]:
    """The current deploy-time goal ({} when none)."""
    goals = _deploy["goals"]
    return goals[_deploy["index"]] if goals else {}


def deploy_goal_index() -> int:
    return int(_deploy["index"])


def advance_deploy_goal(distance_steps: float, threshold: float) -> bool:
    """Move on to the next goal of the sequence once the critic's distance to the current one is under
    ``threshold`` steps; True when it advanced."""
    if _deploy["index"] + 1 >= len(_deploy["goals"]) or distance_steps >= threshold:
        return False
    _deploy["index"] += 1
    log.info(
        "goal %d reached (critic distance %.1f steps < %.1f): now goal %d of %d",
        _deploy["index"] - 1,
        distance_steps,
        threshold,
        _deploy["index"],
        len(_deploy["goals"]),
    )
    return True


def has_goal_source(config) -> bool:
    return bool(getattr(config, "goal_path", None) or getattr(config, "goal_dataset_root", None))


def read_goal_file(path: str | Path) -> dict[str, torch.Tensor]:
    """A goal file: ``observation.*`` tensors of one observation (safetensors)."""
    from safetensors.torch import load_file

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"goal file {path} does not exist (write one with lerobot-efm-goal)")
    goal = load_file(str(path))
    bad = [k for k in goal if not k.startswith(OBS_PREFIX) or is_mirror_key(k)]
    if bad:
        raise ValueError(
            f"goal file {path}: keys {bad} are not plain observation keys (observation.state, "
            f"observation.images.<camera>)"
        )
    return goal


def write_goal_file(goal: dict[str, torch.Tensor], path: str | Path) -> Path:
    """Save one observation (``observation.*`` tensors, unbatched) as a goal file."""
    from safetensors.torch import save_file

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_file(
        {k: v.detach().cpu().contiguous() for k, v in goal.items() if k.startswith(OBS_PREFIX)}, str(path)
    )
    return path


def read_dataset_frame(
    root: str | Path, episode: int, frame: int, repo_id: str | None = None
) -> dict[str, torch.Tensor]:
    """The ``observation.*`` keys of frame ``frame`` (negative: from the end) of episode ``episode`` of the
    LeRobot dataset at ``root``; video frames are decoded, only that one."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    root = Path(root)
    if not (root / "meta" / "info.json").is_file():
        raise FileNotFoundError(f"no LeRobot dataset at {root} (meta/info.json missing)")
    repo_id = repo_id or f"local/{root.name}"
    meta = LeRobotDatasetMetadata(repo_id, root=root)
    if not 0 <= episode < meta.total_episodes:
        raise ValueError(f"goal episode {episode} out of range: {root} has {meta.total_episodes} episodes")
    ds = LeRobotDataset(repo_id, root=root, episodes=[episode])
    n = len(ds)
    if not -n <= frame < n:
        raise ValueError(f"goal frame {frame} out of range: episode {episode} of {root} has {n} frames")
    item = ds[frame % n]
    return {
        k: v
        for k, v in item.items()
        if isinstance(v, torch.Tensor) and k.startswith(OBS_PREFIX) and not is_mirror_key(k)
    }


def to_goal_keys(
    observation: dict[str, torch.Tensor], input_features: dict, crop: Crop | None = None
) -> dict[str, torch.Tensor]:
    """Observation tensors -> the policy's goal keys, in the layout of LeRobot's inference input (float32,
    images CHW in [0, 1], cropped to ``crop`` as in training), checked against the features of the checkpoint
    (goal keys are in ``input_features``).

    Raises with the key, the expected and the found shape when the goal does not fit the checkpoint."""
    wanted = {k: tuple(f.shape) for k, f in input_features.items() if k.startswith(GOAL_PREFIX)}
    if not wanted:
        raise ValueError("this policy has no goal features (observation.goal.*) to fill")
    goal = {}
    for key, shape in wanted.items():
        src = OBS_PREFIX + key[len(GOAL_PREFIX) :]
        if src not in observation:
            raise KeyError(
                f"the goal lacks {src!r} (for {key!r}, shape {shape}); it has {sorted(observation)}"
            )
        value = torch.as_tensor(observation[src])
        if ".images." in key:
            if value.dim() == 3 and value.shape[-1] in (1, 3) and value.shape[0] not in (1, 3):  # HWC
                value = value.permute(2, 0, 1)
            value = value.float() / 255.0 if value.dtype == torch.uint8 else value.float()
            if value.dim() != 3 or value.shape[0] != shape[0]:
                raise ValueError(
                    f"goal image {src!r} has shape {tuple(value.shape)}; the checkpoint expects "
                    f"{shape} (channels, height, width)"
                )
            if tuple(value.shape) != shape:  # at the policy's size: fitted already, as in fit_live_images
                if crop is None:
                    log.warning(
                        "goal image %s is %s, the checkpoint expects %s: resized with OpenCV",
                        src,
                        tuple(value.shape),
                        shape,
                    )
                value = resize_frame(value, shape, crop)
        else:
            value = value.float().reshape(-1) if value.dim() <= 1 else value.float()
            if tuple(value.shape) != shape:
                raise ValueError(
                    f"goal {src!r} has shape {tuple(value.shape)}; the checkpoint expects {shape}"
                )
        goal[key] = value
    return goal


def load_goals(config) -> list[dict[str, torch.Tensor]] | None:
    """The goals named by the config's ``goal_*`` fields as goal-key tensors, or None when it names none.

    ``goal_path`` may list several files separated by commas (a multi-step task), ``goal_frame`` one frame."""
    if getattr(config, "goal_path", None) and getattr(config, "goal_dataset_root", None):
        raise ValueError("set either goal_path or goal_dataset_root, not both")
    if getattr(config, "goal_path", None):
        sources = [p.strip() for p in config.goal_path.split(",") if p.strip()]
        observations = [read_goal_file(p) for p in sources]
    elif getattr(config, "goal_dataset_root", None):
        sources = [f"{config.goal_dataset_root} episode {config.goal_episode} frame {config.goal_frame}"]
        observations = [
            read_dataset_frame(
                config.goal_dataset_root, config.goal_episode, config.goal_frame, config.goal_repo_id
            )
        ]
    else:
        return None
    goals = [
        to_goal_keys(o, config.input_features, getattr(config, "image_crop", None)) for o in observations
    ]
    for source, goal in zip(sources, goals, strict=True):
        states = {k: [round(float(x), 4) for x in v.reshape(-1)] for k, v in goal.items() if v.dim() == 1}
        log.info(
            "deploy goal from %s: %s%s",
            source,
            states,
            " + images " + str(sorted(set(goal) - set(states))) if len(states) < len(goal) else "",
        )
    return goals
