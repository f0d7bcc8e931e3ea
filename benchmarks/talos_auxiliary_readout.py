"""Does an image policy's latent know where the door, tray and pot are? Talos kitchen, auxiliary head.

A checkpoint trained with ``--policy.auxiliary_state_key=observation.environment_state`` carries a head that
reads the object state from the latent of camera + proprioception (:mod:`lerobot_efm.auxiliary`). This runs it
on recorded frames and prints, per object coordinate, the mean absolute error against the recorded value, next
to the error of always answering the training play's mean (what a latent blind to the objects can do). Run it
on the training play and on a recording the policy never saw (another recorder seed) to tell reading from
remembering.

    python benchmarks/talos_auxiliary_readout.py --checkpoint outputs/.../checkpoints/last/pretrained_model \\
        --dataset train=outputs/talos13/play48 --dataset heldout=outputs/talos13/play_heldout --frames 1000
"""

from __future__ import annotations

import argparse
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
            f"{time.perf_counter() - start:.0f} s on one thread.",
            "",
            *lines,
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


if __name__ == "__main__":
    main()
