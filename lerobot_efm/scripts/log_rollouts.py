"""``lerobot-efm-log-rollouts``: roll a trained policy out in a simulated env and write everything to a rerun
``.rrd`` file (no viewer). Not a deployment: that is LeRobot's own ``lerobot-rollout`` (a real or simulated
robot); this is ``lerobot-eval`` with a rerun log, one episode after another.

    lerobot-efm-log-rollouts --policy.path=outputs/train/.../pretrained_model \\
        --env.type=efm_point_reach --env.task=around_wall --eval.n_episodes=2 --output=rollout.rrd
    rerun rollout.rrd        # view it later, anywhere

Flags are lerobot-eval's (``--env.*``, ``--policy.*``, ``--eval.n_episodes``, ``--seed``); episodes run one at
a time (``--eval.batch_size`` does not apply: each step is logged as it happens).

The loop is lerobot-eval's (``preprocess_observation`` -> env preprocessor -> policy preprocessor ->
``select_action`` -> postprocessor -> env postprocessor -> ``env.step``) with one env, synchronously. What
is logged is described in :mod:`lerobot_efm.viz.rollout_log`.

Why not ``lerobot_eval.rollout`` with its callbacks: in lerobot 0.6.1 they see neither the observation nor the
action of a step (``render_callback(env)`` gets the vector env, ``predicted_latents_callback(policy)`` the policy),
and rewards and successes come back only when the whole batch has finished. Streaming a step as it happens would
mean reading the observation back out of the policy's normalised input queue; this loop keeps the same order of
processors instead, and ``lerobot-eval`` itself stays the tool for success rates.
"""

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from lerobot import envs as lerobot_envs
from lerobot.configs import parser
from lerobot.configs.default import EvalConfig
from lerobot.configs.policies import PreTrainedConfig
from lerobot.utils.constants import ACTION

import lerobot_efm  # noqa: F401  (registers the efm_* policies and envs)
from lerobot_efm.configuration_efm import GOAL_PREFIX, mirror_key
from lerobot_efm.scripts import run_cli

from ..viz.rollout_log import RolloutLogger

logger = logging.getLogger(__name__)


@dataclass
class RolloutConfig:
    env: lerobot_envs.EnvConfig
    policy: PreTrainedConfig | None = None
    # The .rrd file written.
    output: Path = Path("outputs/rollout.rrd")
    eval: EvalConfig = field(default_factory=lambda: EvalConfig(n_episodes=1, batch_size=1))
    seed: int = 1000
    # Stop an episode after this many steps (default: the env's own limit).
    max_steps: int | None = None
    # Log env.render() frames too (an extra camera).
    render: bool = True
    application_id: str = "lerobot_efm_rollout"

    def __post_init__(self) -> None:
        # As lerobot's EvalPipelineConfig: --policy.path is removed by parser.wrap and read here.
        policy_path = parser.get_path_arg("policy")
        if policy_path:
            overrides = parser.get_yaml_overrides("policy") + (parser.get_cli_overrides("policy") or [])
            self.policy = PreTrainedConfig.from_pretrained(policy_path, cli_overrides=overrides)
            self.policy.pretrained_path = Path(policy_path)
        if self.policy is None or getattr(self.policy, "pretrained_path", None) is None:
            raise ValueError("Give the trained policy with --policy.path=<checkpoint>/pretrained_model.")
        if self.eval.n_episodes < 1:
            raise ValueError(f"--eval.n_episodes must be >= 1, got {self.eval.n_episodes}.")

    @classmethod
    def __get_path_fields__(cls) -> list[str]:
        return ["policy"]


def _success(info: dict) -> bool:
    """``is_success`` of env 0 of a vector env, from ``final_info`` when the env auto-reset (as lerobot_eval)."""
    source = info.get("final_info", info) if "final_info" in info else info
    if isinstance(source, dict):
        value = source.get("is_success", False)
    else:  # gymnasium < 1.0: a sequence of per-env dicts
        item = source[0] if len(source) else None
        value = item.get("is_success", False) if isinstance(item, dict) else False
    return bool(np.asarray(value).reshape(-1)[0]) if np.asarray(value).size else False


def _env0_info(info: dict) -> dict:
    """Per-env info of env 0 (final_info when the episode just ended), as scalars."""
    source = info.get("final_info", info)
    if not isinstance(source, dict):
        return {}
    out = {}
    for key, value in source.items():
        if key.startswith("_") or isinstance(value, dict):
            continue
        v = np.asarray(value)
        if v.dtype.kind in "fiub" and v.ndim == 1 and v.size >= 1:
            out[key] = v[0]
    return out


def _task_text(env) -> str:
    """The env's task description (LeRobot envs expose ``task_description`` and ``task``), or ''."""
    for name in ("task_description", "task"):
        try:
            return str(env.call(name)[0])
        except AttributeError:
            continue
    return ""


def run_episode(
    env,
    policy,
    env_preprocessor,
    env_postprocessor,
    preprocessor,
    postprocessor,
    log: RolloutLogger,
    index: int,
    seed: int,
    max_steps: int,
    render: bool,
    on_first_step=None,
) -> dict:
    """One episode in env 0 of a (1-env) vector env, as lerobot_eval's rollout, logging every step;
    ``on_first_step()`` is called once the first observation is logged."""
    from lerobot.envs.utils import NEW_ROLLOUT_OPTION, preprocess_observation

    policy.reset()
    observation, info = env.reset(seed=[seed], options={NEW_ROLLOUT_OPTION: True})
    task = _task_text(env)
    log.begin_episode(index, task=task, seed=seed)
    step, success, done, reward_sum = 0, False, False, 0.0
    infos = []
    readout = ReadoutErrors(getattr(policy.config, "auxiliary_state_key", None))
    while not done and step < max_steps:
        obs = preprocess_observation(observation)
        obs["task"] = [task]
        obs = env_preprocessor(obs)
        log.log_observation(step, obs)
        if render:
            log.log_render(step, env.call("render")[0])
        if step == 0 and on_first_step is not None:
            on_first_step()
        before = getattr(policy, "last_prediction", None)
        batch = preprocessor(dict(obs))
        with torch.inference_mode():
            action = policy.select_action(batch)
        prediction = getattr(policy, "last_prediction", None)
        if prediction is not None and prediction is not before:  # the action queue was empty: replanned
            log.log_prediction(step, prediction)
            readout.add(prediction, obs)
        action = postprocessor(action)
        action = env_postprocessor({ACTION: action})[ACTION]
        action_np = action.to("cpu").numpy()
        log.log_action(step, action_np[0])
        observation, reward, terminated, truncated, info = env.step(action_np)
        success = _success(info)
        reward_sum += float(reward[0])
        infos.append(_env0_info(info))
        log.log_outcome(step, float(reward[0]), success, infos[-1])
        done = bool(terminated[0] or truncated[0])
        step += 1
        if not done:
            continue
        final = info.get(
            "final_obs"
        )  # autoreset SAME_STEP: `observation` already belongs to the next episode
        if final is not None:
            try:
                final_obs = final[0] if not isinstance(final, dict) else {k: v[0] for k, v in final.items()}
                batched = {
                    k: (v[None] if isinstance(v, np.ndarray) else {c: im[None] for c, im in v.items()})
                    for k, v in final_obs.items()
                }
                log.log_observation(step, env_preprocessor(preprocess_observation(batched)))
            except Exception as e:  # noqa: BLE001  (env-specific final observations: only a nicety)
                logger.debug("final observation not logged: %s", e)
    if not done:  # stopped by max_steps: log where it ended
        obs = env_preprocessor(preprocess_observation(observation))
        log.log_observation(step, obs)
    result = {
        "episode": index,
        "seed": seed,
        "length": step,
        "success": success,
        "sum_reward": reward_sum,
        "task": task,
    }
    if infos and "grip_command" in infos[0]:  # an env that reports its grasps (the Talos kitchen)
        result["grasps"] = _log_grasps(log, infos)
    result.update(readout.summary())
    log.end_episode(step, success)
    return result


class ReadoutErrors:
    """|auxiliary head's reading - true value| per dimension at every replan, for the observation and the goal,
    when the policy has an auxiliary state head and the env hands out that state (a simulator's object state):
    does the camera read as well on the policy's own states as on the recorded play?"""

    def __init__(self, key: str | None):
        self.key = key
        self.errors: dict[str, list[np.ndarray]] = {"observation": [], "goal": []}

    def add(self, prediction: dict, obs: dict) -> None:
        if not self.key:
            return
        for name, read, true in (
            ("observation", "auxiliary_state", self.key),
            ("goal", "auxiliary_goal_state", mirror_key(self.key, GOAL_PREFIX)),
        ):
            if read in prediction and true in obs:
                value = np.asarray(obs[true], dtype=np.float64).reshape(-1)
                reading = prediction[read][0].detach().cpu().numpy().astype(np.float64)
                self.errors[name].append(np.abs(reading - value))

    def summary(self) -> dict:
        """``auxiliary_readout_error``: {observation / goal: mean absolute error per dimension}, if measured."""
        measured = {name: np.mean(e, axis=0).tolist() for name, e in self.errors.items() if e}
        return {"auxiliary_readout_error": measured} if measured else {}


def _log_grasps(log: RolloutLogger, infos: list[dict]) -> dict:
    """Classify the episode's gripper closures, log one event per closure, return their summary."""
    from lerobot_efm.envs.talos_kitchen import grasps

    runs = grasps.closures([grasps.from_info(i) for i in infos])
    for r in runs:
        weld = f", held after {r.frames_to_weld} frames" if r.frames_to_weld is not None else ""
        log.log_event(r.start, f"closure {r.start}-{r.end}: {r.outcome} {r.obj or ''}{weld}")
    summary = grasps.summarize(runs)
    summary.pop("per_object")
    return summary


def rollout(cfg: RolloutConfig) -> list[dict]:
    """Build env, policy and processors like lerobot-eval, run ``cfg.eval.n_episodes`` and save ``cfg.output``."""
    import rerun as rr
    from lerobot.envs.factory import make_env, make_env_pre_post_processors
    from lerobot.policies import make_policy, make_pre_post_processors
    from lerobot.utils.random_utils import set_seed

    set_seed(cfg.seed)
    env_dict = make_env(cfg.env, n_envs=1, use_async_envs=False)
    env = next(iter(next(iter(env_dict.values())).values()))
    policy = make_policy(cfg=cfg.policy, env_cfg=cfg.env)
    policy.eval()
    preprocessor, postprocessor = make_pre_post_processors(
        policy_cfg=cfg.policy,
        pretrained_path=cfg.policy.pretrained_path,
        preprocessor_overrides={"device_processor": {"device": str(policy.config.device)}},
    )
    env_preprocessor, env_postprocessor = make_env_pre_post_processors(env_cfg=cfg.env, policy_cfg=cfg.policy)

    env_limit = int(env.call("_max_episode_steps")[0] or 10**9)
    max_steps = min(env_limit, cfg.max_steps) if cfg.max_steps else env_limit
    fps = cfg.env.fps or env.unwrapped.metadata.get("render_fps", 30)

    output = Path(cfg.output)
    output.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(cfg.application_id)
    rec.save(output)
    rec.send_recording_name(f"{cfg.policy.type} in {cfg.env.type}")
    log = RolloutLogger(rec, cfg.env.type, fps, policy, preprocessor, postprocessor)
    results = []
    try:
        with torch.no_grad():
            # The layout goes early (cameras are known after the first step), not at the end: a viewer that opens
            # the file while it is written, or a headless screenshot, shows it at once.
            def send_layout():
                rec.send_blueprint(log.blueprint(list(range(cfg.eval.n_episodes))))

            for i in range(cfg.eval.n_episodes):
                results.append(
                    run_episode(
                        env,
                        policy,
                        env_preprocessor,
                        env_postprocessor,
                        preprocessor,
                        postprocessor,
                        log,
                        i,
                        cfg.seed + i,
                        max_steps,
                        cfg.render,
                        send_layout if i == 0 else None,
                    )
                )
                logger.info("episode %d: %s", i, results[-1])
    finally:
        rec.flush()
        rec.disconnect()
        env.close()
    return results


@parser.wrap()
def rollout_main(cfg: RolloutConfig) -> list[dict]:
    results = rollout(cfg)
    n_success = sum(r["success"] for r in results)
    print(
        f"Wrote {cfg.output}: {len(results)} episode(s), {n_success} success(es); "
        f"lengths {[r['length'] for r in results]}. View it with: rerun {cfg.output}"
    )
    return results


def main(argv: list[str] | None = None) -> list[dict] | None:
    """Console entry point; ``main([...])`` runs in-process with those CLI arguments and returns the summaries."""
    return run_cli(rollout_main, argv, "lerobot-efm-log-rollouts")


if __name__ == "__main__":
    main()
