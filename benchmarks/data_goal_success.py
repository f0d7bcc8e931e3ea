"""Success of a planar-push checkpoint on goals taken from its own training data (not the 10 evaluation pairs).

Why: a policy that fails the 10 evaluation pairs may fail because it has not learnt to reach *any* goal (budget,
method) or because the pairs ask for states the play data hardly covers (data). This script separates the two:
it starts episodes at frames of the recording and asks for a later frame of the same episode where disc and hand
rest (as evaluation goals do), with the same success rule, horizon and replanning as ``lerobot-eval``.

    python benchmarks/data_goal_success.py --checkpoint RUN/train/checkpoints/012000/pretrained_model \
        --dataset outputs/paper_experiments/data/planar_push/full --episodes 50
"""

from __future__ import annotations

import argparse
import glob
import json
from pathlib import Path

import numpy as np
import torch

from lerobot_efm.envs.planar_push.env import SUCCESS_TOL, check_state

REST_SPEED = 0.002  # per-frame displacement under which a body counts as at rest
MIN_DISC_MOVE = 0.3  # goals must move the disc at least this far (a push, not a hand move)


def load_states(root: Path) -> tuple[np.ndarray, np.ndarray]:
    import pandas as pd

    files = sorted(glob.glob(str(root / "data" / "*" / "*.parquet")))
    if not files:
        raise FileNotFoundError(f"no parquet data files under {root / 'data'}")
    df = pd.concat([pd.read_parquet(f, columns=["observation.state", "episode_index"]) for f in files])
    return np.stack(df["observation.state"].to_numpy()).astype(np.float64), df["episode_index"].to_numpy()


def sample_pairs(states, episodes, n, rng, min_gap=60, max_gap=400):
    """(start, goal) states: goal = a later resting frame of the same episode that moved the disc."""
    speed = np.zeros(len(states))
    same = episodes[1:] == episodes[:-1]
    step = np.linalg.norm(states[1:] - states[:-1], axis=1)
    speed[1:] = np.where(same, step, np.inf)
    rest = speed < REST_SPEED
    pairs = []
    for _ in range(100 * n):
        g = int(rng.integers(len(states)))
        if not rest[g]:
            continue
        s = g - int(rng.integers(min_gap, max_gap))
        if s < 0 or episodes[s] != episodes[g]:
            continue
        if np.linalg.norm(states[g, 2:] - states[s, 2:]) < MIN_DISC_MOVE:
            continue
        try:  # bodies in contact (slightly overlapping in the recording) cannot be placed by the env
            check_state(states[s]), check_state(states[g])
        except ValueError:
            continue
        pairs.append((states[s], states[g]))
        if len(pairs) == n:
            break
    if len(pairs) < n:
        raise RuntimeError(f"only {len(pairs)} of {n} (start, goal) pairs found in the data")
    return pairs


def evaluate(checkpoint: Path, pairs, max_steps: int, device: str, overrides: dict | None = None) -> dict:
    from checkpoint_loading import load_policy

    from lerobot_efm.envs.planar_push.env import PlanarPushEnv

    policy, pre, post = load_policy(checkpoint, device, overrides)
    envs = [PlanarPushEnv(task="pair0") for _ in pairs]
    for env, (start, goal) in zip(envs, pairs, strict=True):
        env.reset(options={"initial": start, "goal": goal})
    goals = torch.tensor(np.stack([g for _, g in pairs]), dtype=torch.float32)
    done = np.zeros(len(envs), dtype=bool)
    closest = np.full(len(envs), np.inf)
    closest_disc = np.full(len(envs), np.inf)
    policy.reset()
    trajectories = [[env.state] for env in envs]
    for _ in range(max_steps):
        state = torch.tensor(np.stack([e.state for e in envs]), dtype=torch.float32)
        batch = pre({"observation.state": state, "observation.goal.state": goals, "task": [""] * len(envs)})
        with torch.inference_mode():
            action = post(policy.select_action(batch)).cpu().numpy()
        for i, env in enumerate(envs):
            if done[i]:
                continue
            _, _, _, _, info = env.step(action[i])
            closest[i] = min(closest[i], info["effector_distance"] + info["object_distance"])
            closest_disc[i] = min(closest_disc[i], info["object_distance"])
            trajectories[i].append(env.state)
            done[i] = info["is_success"]
        if done.all():
            break
    return {
        "success": float(done.mean()),
        "disc_within_tol": float((closest_disc < SUCCESS_TOL).mean()),
        "n": len(envs),
        "median_closest_sum_distance": float(np.median(closest)),
        "median_closest_disc_distance": float(np.median(closest_disc)),
        "trajectories": [np.stack(t).tolist() for t in trajectories],
        "goals": goals.tolist(),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", type=Path, required=True)
    p.add_argument("--dataset", type=Path, help="the training recording to draw (start, goal) pairs from")
    p.add_argument(
        "--eval-pairs",
        type=int,
        default=0,
        metavar="REPS",
        help="instead of data goals: the 10 evaluation pairs, REPS episodes each (a re-check of lerobot-eval)",
    )
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--max-steps", type=int, default=600)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu")
    p.add_argument("--out", type=Path)
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a config field at inference, e.g. critic_inference_eps=0.5",
    )
    a = p.parse_args()
    if a.eval_pairs > 0:
        from lerobot_efm.envs.planar_push.env import EVAL_PAIRS

        pairs = [(initial, goal) for _, initial, goal in EVAL_PAIRS for _ in range(a.eval_pairs)]
    elif a.dataset is None:
        p.error("give --dataset (goals from the recording) or --eval-pairs REPS")
    else:
        states, episodes = load_states(a.dataset)
        pairs = sample_pairs(states, episodes, a.episodes, np.random.default_rng(a.seed))
    overrides = dict(x.split("=", 1) for x in a.set)
    result = {
        "checkpoint": str(a.checkpoint),
        "dataset": str(a.dataset),
        **evaluate(a.checkpoint, pairs, a.max_steps, a.device, overrides),
    }
    print(json.dumps({k: v for k, v in result.items() if k not in ("trajectories", "goals")}))
    if a.out:
        a.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
