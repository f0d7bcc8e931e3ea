"""What the critic believes: Critic(eps=0 | start, goal) in steps on the evaluation pairs (the 10 planar pairs, or
OGBench's 5 pointmaze tasks with ``--suite ogbench``), next to the number of steps the scripted expert (given the
goal) or the noise-free BFS oracle needs to solve each.

Why: FM-AC acts conditioned on this distance. A critic trained on play data only knows the play's own paths, so
its minimum estimates how long the *observed* routes take (slow, with detours), and on partitioned play it has never
seen a route between regions; the RL bootstrap (eq. 5) should shorten both by stitching. Hindsight distances stop at
``max_goal_distance`` (200 steps for pointmaze): only the bootstrap can teach longer ones. Comparing the estimates
with a direct route shows which of these a checkpoint has learnt.

    python benchmarks/critic_distances.py RUN_A/train/checkpoints/012000/pretrained_model [RUN_B/...] \
        --out benchmarks/results/critic_distances_planar_push.md
    python benchmarks/critic_distances.py --suite ogbench RUN/train/checkpoints/012000/pretrained_model
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch


def expert_steps(max_steps: int = 600) -> list[int]:
    """Steps the scripted expert (told the goal) takes to succeed on each evaluation pair (max_steps if never)."""
    from lerobot_efm.envs.planar_push.demonstrators import ExpertReachGoal
    from lerobot_efm.envs.planar_push.env import EVAL_PAIRS, PlanarPushEnv

    env, steps = PlanarPushEnv(task="all"), []
    for k in range(len(EVAL_PAIRS)):
        env.reset(options={"pair": k})
        expert = ExpertReachGoal(env, np.random.default_rng(k), goal=env.goal)
        obs, n = expert.reset(), max_steps
        for t in range(max_steps):
            obs, _, _, _, info = env.step(expert.act(obs))
            if info["is_success"]:
                n = t + 1
                break
        steps.append(n)
    env.close()
    return steps


def planar_pairs() -> tuple[np.ndarray, np.ndarray]:
    from lerobot_efm.envs.planar_push.env import EVAL_PAIRS

    return np.stack([p[1] for p in EVAL_PAIRS]), np.stack([p[2] for p in EVAL_PAIRS])


def ogbench_pairs(dataset: str, max_steps: int = 1000) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Start and goal observations of OGBench's five tasks, and the steps the noise-free BFS oracle takes."""
    from lerobot_efm.ogbench.env import GOAL_STATE_KEY, TASK_NAMES, OGBenchEnv
    from lerobot_efm.ogbench.generate import oracle_direction

    env, starts, goals, steps = OGBenchEnv(dataset, task="all"), [], [], []
    for k in range(1, len(TASK_NAMES) + 1):
        obs, _ = env.reset(seed=0, options={"task_id": k})
        starts.append(obs["agent_pos"])
        goals.append(obs[GOAL_STATE_KEY])
        n = max_steps
        for t in range(max_steps):
            *_, info = env.step(oracle_direction(env.maze, exact_goal=True))
            if info["is_success"]:
                n = t + 1
                break
        steps.append(n)
    env.close()
    return np.stack(starts), np.stack(goals), steps


def critic_steps(checkpoint: Path, starts: np.ndarray, goals: np.ndarray) -> list[float]:
    """Critic(0 | start, goal) in steps for each pair, through the checkpoint's own pre-processor."""
    from checkpoint_loading import load_policy

    policy, pre, _ = load_policy(checkpoint)
    start = torch.tensor(starts, dtype=torch.float32)
    goal = torch.tensor(goals, dtype=torch.float32)
    batch = pre({"observation.state": start, "observation.goal.state": goal, "task": [""] * len(starts)})
    torch.manual_seed(0)
    policy.predict_action_chunk(batch)
    return policy.last_prediction["distance"].reshape(-1).tolist()


def label(checkpoint: Path) -> str:
    """``<dataset>/<variant> @ <step>`` from a paper_experiments run path, else the path."""
    parts = checkpoint.resolve().parts
    if "checkpoints" in parts:
        i = parts.index("checkpoints")
        return f"{parts[i - 3]}/{parts[i - 2]} @ {parts[i + 1].lstrip('0') or '0'}"
    return str(checkpoint)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoints", type=Path, nargs="+")
    ap.add_argument("--suite", choices=("planar_push", "ogbench"), default="planar_push")
    ap.add_argument("--ogbench-dataset", default="pointmaze-large-navigate-v0")
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.suite == "planar_push":
        (starts, goals), expert = planar_pairs(), expert_steps()
        names, reference = [f"pair{k}" for k in range(len(expert))], "scripted expert (steps to success)"
    else:
        starts, goals, expert = ogbench_pairs(args.ogbench_dataset)
        names, reference = (
            [f"task{k + 1}" for k in range(len(expert))],
            "BFS oracle, no noise (steps to success)",
        )
    lines = [
        "| checkpoint | " + " | ".join(names) + " | mean ratio |",
        "|---" * (len(expert) + 2) + "|",
        f"| {reference} | " + " | ".join(map(str, expert)) + " | 1.00 |",
    ]
    for ck in args.checkpoints:
        d = critic_steps(ck, starts, goals)
        ratio = float(np.mean(np.array(d) / np.array(expert)))
        lines.append(f"| {label(ck)} | " + " | ".join(f"{x:.0f}" for x in d) + f" | {ratio:.2f} |")
    table = "\n".join(lines)
    print(table)
    if args.out:
        args.out.write_text(
            f"# Critic(0 | start, goal) in steps on the {args.suite} evaluation pairs\n\n"
            f"Generated by `python benchmarks/critic_distances.py --suite {args.suite} "
            f"{' '.join(map(str, args.checkpoints))}`"
            "\n\n" + table + "\n"
        )


if __name__ == "__main__":
    main()
