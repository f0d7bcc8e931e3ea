"""The README's main job, on an embedded default that needs no network: record synthetic play in the
PointReach environment as a LeRobot dataset, train ``efm_ac`` on it with LeRobot's own ``lerobot-train``
(hindsight goals), and evaluate the checkpoint with ``lerobot-eval`` on goal-reaching episodes.

    python -m lerobot_efm.demo [--output outputs/demo] [--steps N] [--episodes N]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from .synthetic import make_point_play_dataset

REPO_ID = "local/efm_point_play"
CONFIG = Path(__file__).resolve().parent / "train_configs" / "point_reach_efm_ac.json"  # package data


def _run(cli: str, *args: str, log: Path) -> None:
    """Run a LeRobot console script from this interpreter's environment, its output kept in ``log``."""
    cmd = [str(Path(sys.executable).parent / cli), *args]
    print("$", " ".join(cmd), flush=True)
    env = {**os.environ, "HF_HUB_OFFLINE": os.environ.get("HF_HUB_OFFLINE", "1")}
    with log.open("w") as out:
        proc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
    if proc.returncode:
        sys.exit(f"{cli} failed with exit code {proc.returncode}; see {log}:\n" + log.read_text()[-3000:])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--output", type=Path, default=Path("outputs/demo"))
    parser.add_argument("--episodes", type=int, default=40, help="play episodes to record (200 frames each)")
    parser.add_argument("--steps", type=int, default=None, help="training steps (default: the config's)")
    parser.add_argument("--eval-episodes", type=int, default=20)
    args = parser.parse_args(argv)

    data, run, evaluation = args.output / "data", args.output / "train", args.output / "eval"
    args.output.mkdir(parents=True, exist_ok=True)
    if not (data / "meta" / "info.json").exists():
        shutil.rmtree(data, ignore_errors=True)
        dataset = make_point_play_dataset(
            data, repo_id=REPO_ID, num_episodes=args.episodes, episode_length=200
        )
        print(f"recorded {dataset.num_episodes} play episodes ({dataset.num_frames} frames) in {data}")
    shutil.rmtree(run, ignore_errors=True)
    shutil.rmtree(evaluation, ignore_errors=True)

    start = time.time()
    steps = [f"--steps={args.steps}", f"--save_freq={args.steps}"] if args.steps else []
    _run(
        "lerobot-train",
        f"--config_path={CONFIG}",
        f"--dataset.root={data}",
        f"--output_dir={run}",
        *steps,
        log=args.output / "train.log",
    )
    print(f"trained in {time.time() - start:.0f} s -> {run / 'checkpoints' / 'last' / 'pretrained_model'}")

    _run(
        "lerobot-eval",
        f"--policy.path={run / 'checkpoints' / 'last' / 'pretrained_model'}",
        "--env.type=efm_point_reach",
        "--env.task=random",
        f"--eval.n_episodes={args.eval_episodes}",
        f"--eval.batch_size={min(args.eval_episodes, 10)}",
        "--policy.device=cpu",
        f"--output_dir={evaluation}",
        log=args.output / "eval.log",
    )
    overall = json.loads((evaluation / "eval_info.json").read_text())["overall"]
    print(
        f"lerobot-eval on efm_point_reach (random start and goal): success {overall['pc_success']:.0f}% "
        f"over {overall['n_episodes']} episodes; videos in {evaluation / 'videos'}"
    )


if __name__ == "__main__":
    main()
