"""Does an image policy's latent know where the door, tray and pot are? Talos kitchen, auxiliary head.

A checkpoint trained with ``--policy.auxiliary_state_key=observation.environment_state`` carries a head that
reads the object state from the latent of camera + proprioception (:mod:`lerobot_efm.auxiliary`). This runs it
on recorded frames and prints, per object coordinate, the mean absolute error against the recorded value, next
to the error of always answering the training play's mean (what a latent blind to the objects can do). Run it
on the training play and on a recording the policy never saw (another recorder seed) to tell reading from
remembering. With ``--rollout-task`` it also rolls the policy out in the Talos kitchen
(``lerobot-efm-log-rollouts``, one thread) and reports the head's error on the frames the policy itself reached,
at every replan: the observation's and the goal image's, split by episodes that succeeded and failed. A policy
that reads the play's frames well but its own badly acts on a wrong belief where the play never went.

    python benchmarks/talos_auxiliary_readout.py --checkpoint outputs/.../checkpoints/last/pretrained_model \\
        --dataset train=outputs/talos13/play48 --dataset heldout=outputs/talos13/play_heldout --frames 1000 \\
        --rollout-task store_pot --rollout-task push_tray --rollout-episodes 2
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np
import torch

IMAGE, STATE = "observation.images.front", "observation.state"
# (name, dimension of observation.environment_state, unit scale, unit) of what is reported
REPORTED = (
    ("door angle", 0, 180 / np.pi, "deg"),
    ("tray slide", 1, 100.0, "cm"),
    ("pot x", 2, 100.0, "cm"),
    ("pot y", 3, 100.0, "cm"),
    ("pot z", 4, 100.0, "cm"),
)


def load(checkpoint: str):
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies import make_pre_post_processors
    from lerobot.policies.factory import get_policy_class

    import lerobot_efm  # noqa: F401  (registers the policies)

    cfg = PreTrainedConfig.from_pretrained(checkpoint)
    cfg.device = "cpu"
    if not cfg.auxiliary_state_key:
        raise ValueError(
            f"{checkpoint}: trained without --policy.auxiliary_state_key; it has no readout head"
        )
    policy = get_policy_class(cfg.type).from_pretrained(checkpoint, config=cfg).eval()
    pre, _ = make_pre_post_processors(policy_cfg=cfg, pretrained_path=checkpoint)
    return cfg, policy, pre


@torch.no_grad()
def readout(loaded, root: str, frames: int, batch: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """(recorded, predicted) object states of ``frames`` evenly spaced frames of the recording at ``root``."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    cfg, policy, pre = loaded
    key = cfg.auxiliary_state_key
    dataset = LeRobotDataset("local/readout", root=root)
    rows = np.linspace(0, dataset.num_frames - 1, min(frames, dataset.num_frames)).astype(int)
    recorded, predicted = [], []
    for start in range(0, len(rows), batch):
        items = [dataset[int(i)] for i in rows[start : start + batch]]
        obs = {
            IMAGE: torch.stack([it[IMAGE] for it in items]),  # the pre-processor crops / resizes as deployed
            STATE: torch.stack([it[STATE] for it in items]),
        }
        obs = pre(obs)
        latent = policy.ema_model.encoder({k: obs[k] for k in cfg.observation_features})
        predicted.append(policy.ema_model.auxiliary_head.predict(latent).numpy())
        recorded.append(torch.stack([it[key] for it in items]).numpy())
    return np.concatenate(recorded), np.concatenate(predicted)


def rollout_errors(args, workdir: Path) -> list[dict]:
    """One ``lerobot-efm-log-rollouts`` run per ``--rollout-task``: each episode's result with its task and
    ``auxiliary_readout_error`` (mean absolute error per dimension over its replans)."""
    from lerobot_efm.envs.talos_kitchen.env import STEPS_PER_OBJECT
    from lerobot_efm.envs.talos_kitchen.tasks import TASKS
    from lerobot_efm.scripts import log_rollouts

    episodes = []
    for task in args.rollout_task:
        results = log_rollouts.main(
            [
                f"--policy.path={args.checkpoint}",
                "--env.type=talos_kitchen",
                f"--env.task={task}",
                f"--env.image_size={args.image_size}",
                f"--env.episode_length={STEPS_PER_OBJECT * TASKS[task].num_objects}",
                f"--eval.n_episodes={args.rollout_episodes}",
                f"--seed={args.seed}",
                "--render=false",
                f"--output={workdir / f'{task}.rrd'}",
            ]
        )
        episodes += [{**r, "task": task} for r in results]
    return episodes


def rollout_table(episodes: list[dict]) -> list[str]:
    """Per coordinate: the head's mean absolute error on the policy's own frames (observation: all, succeeded,
    failed episodes) and on the goal images, each episode's mean over its replans weighted alike."""
    groups = {
        "rollouts: all": episodes,
        "rollouts: succeeded": [e for e in episodes if e["success"]],
        "rollouts: failed": [e for e in episodes if not e["success"]],
    }
    header = "| coordinate | " + " | ".join(f"{g} ({len(e)})" for g, e in groups.items()) + " | goal images |"
    lines = [header, "|---|" + "---:|" * (len(groups) + 1)]
    for label, dim, scale, unit in REPORTED:
        cells = []
        for group in groups.values():
            errs = [e["auxiliary_readout_error"]["observation"][dim] for e in group]
            cells.append(f"{np.mean(errs) * scale:.1f} {unit}" if errs else "–")
        goal = [e["auxiliary_readout_error"]["goal"][dim] for e in episodes]
        cells.append(f"{np.mean(goal) * scale:.1f} {unit}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    tasks = dict.fromkeys(e["task"] for e in episodes)
    wins = ", ".join(
        f"{t} {sum(e['success'] for e in episodes if e['task'] == t)}/{sum(e['task'] == t for e in episodes)}"
        for t in tasks
    )
    return ["", f"On the policy's own rollouts (successes: {wins}):", "", *lines]


PHASES = ("resting, not yet held", "held in the hand", "released after a hold")


def pot_phase_lines(rrd_files: list[Path]) -> list[str]:
    """The 3-D pot readout error at the replans of every episode in ``rrd_files``, split by where the pot was:
    untouched at its start, in the hand (env info ``held``), or let go somewhere after a hold. A reading that
    is only bad once the policy has moved the pot is a consequence of the carry as much as a cause."""
    from lerobot_efm.envs.talos_kitchen.grasps import HELD_CODE
    from lerobot_efm.viz import read_rrd

    def wanted(entity: str) -> bool:  # not the camera frames: read whole, 13 files fill 10+ GB
        return any(name in entity for name in ("/objects/pot_", "/objects/read_pot_", "/info/held"))

    errors: dict[str, list[float]] = {phase: [] for phase in PHASES}
    for path in rrd_files:
        data = read_rrd(path, keep=wanted)
        for ep in sorted({k.split("/")[0] for k in data if k.startswith("episode_")}):

            def series(name, ep=ep, data=data):
                return {
                    r["step"]: r["Scalars:scalars"][0]
                    for r in data[f"{ep}/{name}"]
                    if r.get("step") is not None
                }

            true, read = ([series(f"objects/{p}pot_{c}") for c in "xyz"] for p in ("", "read_"))
            was_held = False
            for step, code in sorted(series("info/held").items()):
                holds = int(code) == HELD_CODE["pot"]
                if step in read[0]:
                    phase = PHASES[1] if holds else PHASES[2] if was_held else PHASES[0]
                    errors[phase].append(
                        float(np.linalg.norm([read[i][step] - true[i][step] for i in range(3)]))
                    )
                was_held |= holds
    lines = ["| pot at the replan | replans | 3-D error: median | mean |", "|---|---:|---:|---:|"]
    for phase, e in errors.items():
        cells = f"{np.median(e) * 100:.1f} cm | {np.mean(e) * 100:.1f} cm" if e else "– | –"
        lines.append(f"| {phase} | {len(e)} | {cells} |")
    return ["", "The pot's reading by where the pot was (all rollout episodes):", "", *lines]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--checkpoint", required=True)
    parser.add_argument(
        "--dataset", action="append", required=True, help="NAME=ROOT; the first is the training play"
    )
    parser.add_argument("--frames", type=int, default=1000, help="evenly spaced frames read per recording")
    parser.add_argument("--out", type=Path, help="also write the table to this markdown file")
    parser.add_argument(
        "--rollout-task", action="append", default=[], help="also roll out on this Talos task (repeatable)"
    )
    parser.add_argument("--rollout-episodes", type=int, default=2, help="episodes per rollout task")
    parser.add_argument("--seed", type=int, default=1000, help="initial state of the first rollout episode")
    parser.add_argument(
        "--image-size", type=int, default=128, help="the env's camera size (as the policy's training play)"
    )
    parser.add_argument(
        "--workdir", type=Path, default=Path("outputs/readout_rollouts"), help="the rollouts' .rrd files"
    )
    args = parser.parse_args(argv)

    torch.set_num_threads(1)
    loaded = load(args.checkpoint)
    results, mean = {}, None
    start = time.perf_counter()
    for spec in args.dataset:
        name, _, root = spec.partition("=")
        recorded, predicted = readout(loaded, root, args.frames)
        mean = recorded.mean(0) if mean is None else mean  # the training play's mean: the blind answer
        results[name] = (recorded, predicted)

    episodes = rollout_errors(args, args.workdir) if args.rollout_task else []

    names = list(results)
    header = "| coordinate | " + " | ".join(f"{n}: head | {n}: mean answer" for n in names) + " |"
    lines = [header, "|---|" + "---:|---:|" * len(names)]
    for label, dim, scale, unit in REPORTED:
        cells = []
        for name in names:
            recorded, predicted = results[name]
            cells.append(f"{np.abs(predicted[:, dim] - recorded[:, dim]).mean() * scale:.1f} {unit}")
            cells.append(f"{np.abs(mean[dim] - recorded[:, dim]).mean() * scale:.1f} {unit}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    frames = ", ".join(f"{n}: {len(results[n][0])}" for n in names)
    text = "\n".join(
        [
            f"Mean absolute error of the auxiliary head on recorded frames ({frames}); "
            f"{time.perf_counter() - start:.0f} s on one thread{' with the rollouts' if episodes else ''}.",
            "",
            *lines,
            *(rollout_table(episodes) if episodes else []),
            *(pot_phase_lines([args.workdir / f"{t}.rrd" for t in args.rollout_task]) if episodes else []),
            "",
            "```",
            "python benchmarks/talos_auxiliary_readout.py "
            + shlex.join(sys.argv[1:] if argv is None else argv),
            "```",
        ]
    )
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
        if episodes:  # every rollout episode's result, readout errors per dimension in the recording's units
            args.out.with_suffix(".json").write_text(json.dumps(episodes, indent=1) + "\n")


if __name__ == "__main__":
    main()
