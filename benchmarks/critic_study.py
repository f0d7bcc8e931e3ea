#!/usr/bin/env python
"""Train the critic alone and watch what it believes about OGBench's five pointmaze tasks.

Why: on pointmaze-large-navigate our FM-AC (no-RL and use-RL, 12k steps) solves tasks 1 and 3 and never 2, 4, 5,
the tasks whose goal sits behind a wall: there the critic puts the goal at 0.4-0.5x the oracle's steps (it reads
the maze as open space) and the actor, asked for a short route, pushes into the wall
(``benchmarks/results/critic_distances_pointmaze.md``). Training the critic alone (the actor is 65 % of a step)
separates what the critic can learn (network size, hindsight horizon L_g, the RL bootstrap) from the agent.

It follows lerobot-train (config file + CLI overrides, the hindsight hook, the policy's processors, optimiser and
scheduler presets, EMA) but back-propagates only the critics' loss, weighted as in the agent. Every
``--eval-every`` updates the EMA critic's Critic(0 | start, goal) on the five tasks is printed in steps.

    OMP_NUM_THREADS=1 python benchmarks/critic_study.py --label "256x3, L_g 200, use-RL" --steps 12000 \\
        --out outputs/critic_study/base_rl.json -- --policy.use_rl=true
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

REPO_ROOT = Path(__file__).resolve().parents[1]


def critic_on_pairs(policy, preprocessor, starts: np.ndarray, goals: np.ndarray) -> list[float]:
    """EMA Critic(0 | start, goal) in steps (max over the critic members, as the agent acts)."""
    from lerobot_efm.configuration_efm import GOAL_PREFIX, OBS_PREFIX

    batch = preprocessor(
        {
            "observation.state": torch.tensor(starts, dtype=torch.float32),
            "observation.goal.state": torch.tensor(goals, dtype=torch.float32),
            "task": [""] * len(starts),
        }
    )
    model = policy.ema_model
    with torch.no_grad():
        l_obs, l_goal = model.encode(batch, (OBS_PREFIX, GOAL_PREFIX))
        d = model.critic_distance(l_obs, l_goal)
    return (d * policy.config.max_goal_distance).tolist()


def render(paths: list[Path]) -> str:
    """Critic(0 | start, goal) / oracle steps per task at each evaluated step, one block of rows per run."""
    runs = [json.loads(p.read_text()) for p in paths]
    oracle = runs[0]["oracle"]
    lines = [
        "| run | step | min | " + " | ".join(f"task{k + 1}" for k in range(len(oracle))) + " | mean ratio |",
        "|---|---:|---:|" + "---:|" * (len(oracle) + 1),
        "| BFS oracle, no noise (steps) | | | " + " | ".join(map(str, oracle)) + " | 1.00 |",
    ]
    for run in runs:
        for point in run["curve"]:
            ratios = np.array(point["critic_steps"]) / np.array(oracle)
            lines.append(
                f"| {run['label']} | {point['step']} | {point['minutes']:.1f} | "
                + " | ".join(f"{x:.0f}" for x in point["critic_steps"])
                + f" | {ratios.mean():.2f} |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    from critic_distances import ogbench_pairs
    from lerobot.configs.train import TrainPipelineConfig
    from lerobot.datasets.factory import make_train_eval_datasets
    from lerobot.optim.factory import make_optimizer_and_scheduler
    from lerobot.policies.factory import make_policy, make_pre_post_processors
    from torch.utils.data import DataLoader

    import lerobot_efm  # noqa: F401  (registers the policies)
    from lerobot_efm.train_hook import wrap_datasets

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="train_configs/ogbench_pointmaze_efm_cpu.json")
    ap.add_argument("--label", help="name of the run in the report")
    ap.add_argument("--steps", type=int, default=12000)
    ap.add_argument("--eval-every", type=int, default=2000)
    ap.add_argument("--out", type=Path, required=True, help="JSON of the run (with --report: the markdown)")
    ap.add_argument("--report", type=Path, nargs="+", help="render these run JSONs as one markdown table")
    ap.add_argument("overrides", nargs="*", help="lerobot-train arguments, after --")
    args = ap.parse_args()
    if args.report:
        args.out.write_text(render(args.report))
        return
    if not args.label:
        ap.error("--label is required to train")

    torch.set_num_threads(1)
    cli = [f"--steps={args.steps}", f"--policy.scheduler_decay_steps={args.steps}", *args.overrides]
    cfg = TrainPipelineConfig.from_pretrained(REPO_ROOT / args.config, cli_args=cli)
    cfg.validate()
    torch.manual_seed(cfg.seed)
    dataset, _ = wrap_datasets(cfg, make_train_eval_datasets(cfg))
    policy = make_policy(cfg=cfg.policy, ds_meta=dataset.meta)
    preprocessor, _ = make_pre_post_processors(cfg.policy, dataset_stats=dataset.meta.stats)
    optimizer, scheduler = make_optimizer_and_scheduler(cfg, policy)
    clip = cfg.optimizer.grad_clip_norm
    starts, goals, oracle = ogbench_pairs(cfg.dataset.repo_id.split("/")[-1])
    loader = DataLoader(dataset, batch_size=cfg.batch_size, shuffle=True, drop_last=True)

    curve, step, start = [], 0, time.perf_counter()
    policy.train()
    while step < args.steps:
        for batch in loader:
            batch = preprocessor(batch)
            rows = policy.model.training_rows(batch, policy.ema_model, step)
            loss = policy.config.critic_loss_weight * policy.model.critic_loss(rows.goal_conditioned)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), clip)
            optimizer.step()
            optimizer.zero_grad()
            scheduler.step()
            policy.update()
            step += 1
            if step % args.eval_every == 0 or step == args.steps:
                d = critic_on_pairs(policy, preprocessor, starts, goals)
                minutes = (time.perf_counter() - start) / 60
                curve.append({"step": step, "minutes": minutes, "critic_steps": d, "loss": loss.item()})
                print(f"{step:6d} {minutes:5.1f} min  " + " ".join(f"{x:5.0f}" for x in d), flush=True)
            if step >= args.steps:
                break
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {"label": args.label, "overrides": args.overrides, "oracle": oracle, "curve": curve}, indent=1
        )
    )


if __name__ == "__main__":
    main()
