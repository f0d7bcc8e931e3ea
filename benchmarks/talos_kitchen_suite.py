"""Per-task success of trained checkpoints on the Talos kitchen suite, through LeRobot's own ``lerobot-eval``.

One ``lerobot-eval`` run per (checkpoint, task); runs go ``--jobs`` at a time. Writes a markdown table and
the raw numbers (JSON) with the exact commands.

    python benchmarks/talos_kitchen_suite.py --policy efm_ac=outputs/talos/ac/checkpoints/last/pretrained_model \\
        --policy efm_gc=outputs/talos/gc/checkpoints/last/pretrained_model --episodes 5 --jobs 2 \\
        --out benchmarks/results/talos_kitchen_suite --policy.n_action_steps=20

Flags of ``lerobot-eval`` (``--policy.*``, ``--env.*``, ``--eval.*``) are passed on to every run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from lerobot_efm.envs.talos_kitchen.env import STEPS_PER_OBJECT
from lerobot_efm.envs.talos_kitchen.tasks import LONG_TASK, TASK_NAMES, TASKS

BIN = Path(sys.executable).parent
EVAL_FLAG_PREFIXES = ("--policy.", "--env.", "--eval.")  # lerobot-eval flags passed on to every run


SECONDS_FILE = "seconds.txt"  # next to a cell's eval_info.json: how long its lerobot-eval ran


def uses_images(checkpoint: str) -> bool:
    """Whether the checkpoint's policy reads a camera (its config's VISUAL input features)."""
    cfg = json.loads((Path(checkpoint) / "config.json").read_text())
    return any(f.get("type") == "VISUAL" for f in cfg.get("input_features", {}).values())


def eval_command(
    checkpoint: str,
    task: str,
    episodes: int,
    image_size: int,
    steps_per_subtask: int,
    out: Path,
    extra: list[str],
    video_frame_stride: int = 1,
) -> list[str]:
    return [
        str(BIN / "lerobot-eval"),
        f"--policy.path={checkpoint}",
        "--env.type=talos_kitchen",
        f"--env.task={task}",
        f"--env.image_size={image_size}",
        # a state policy needs no camera: nothing rendered per step (~10x cheaper steps) but lerobot-eval's videos
        *([] if uses_images(checkpoint) else ["--env.obs_type=state"]),
        # ... whose frames (the first 10 episodes, one per step) were 3/4 of its time: one every k-th step
        *([f"--env.video_frame_stride={video_frame_stride}"] if video_frame_stride != 1 else []),
        f"--env.episode_length={steps_per_subtask * TASKS[task].num_objects}",
        f"--eval.n_episodes={episodes}",
        "--eval.batch_size=1",
        "--policy.device=cpu",
        f"--output_dir={out}",
        *extra,
    ]


def run_one(label: str, checkpoint: str, task: str, args, root: Path) -> dict:
    out = root / label / task
    cmd = eval_command(
        checkpoint,
        task,
        args.episodes,
        args.image_size,
        args.steps_per_subtask,
        out,
        args.extra,
        video_frame_stride=args.video_frame_stride,
    )
    if not (out / "eval_info.json").exists():  # resumable: a finished (label, task) is not re-run
        t0 = time.perf_counter()
        env = {
            **os.environ,
            "HF_HUB_OFFLINE": "1",
            "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
            "OMP_NUM_THREADS": "1",
        }
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if proc.returncode:
            raise RuntimeError(f"lerobot-eval failed for {label}/{task}:\n{proc.stderr[-3000:]}")
        (out / SECONDS_FILE).write_text(f"{time.perf_counter() - t0:.1f}\n")
    # the cell's own evaluation time, also when an earlier run did it (None: run before this file existed)
    seconds = float((out / SECONDS_FILE).read_text()) if (out / SECONDS_FILE).exists() else None
    info = json.loads((out / "eval_info.json").read_text())
    successes = [bool(x) for t in info.get("per_task", []) for x in t["metrics"]["successes"]]
    took = "time not recorded" if seconds is None else f"{seconds:.0f} s"
    print(f"{label:>8} {task:<22} {info['overall']['pc_success']:5.1f}% ({took})", flush=True)
    return {
        "label": label,
        "task": task,
        "pc_success": info["overall"]["pc_success"],
        "n_episodes": info["overall"]["n_episodes"],
        "seconds": seconds,
        "successes": successes,
        "command": " ".join([os.path.relpath(cmd[0]), *cmd[1:]]),
    }  # no machine path


def table(results: list[dict], labels: list[str]) -> str:
    by = {(r["label"], r["task"]): r for r in results}
    lines = ["| task | description | " + " | ".join(labels) + " |", "|---|---|" + "---|" * len(labels)]
    for task in TASK_NAMES:
        cells = [f"{by[(lab, task)]['pc_success']:.0f}%" if (lab, task) in by else "-" for lab in labels]
        name = f"**{task}** (long)" if task == LONG_TASK else task
        lines.append(f"| {name} | {TASKS[task].description} | " + " | ".join(cells) + " |")
    means = []
    for lab in labels:
        vals = [by[(lab, t)]["pc_success"] for t in TASK_NAMES if (lab, t) in by]
        subset = f" ({len(vals)} tasks)" if len(vals) < len(TASK_NAMES) else ""  # not the suite's mean
        means.append(f"{sum(vals) / max(1, len(vals)):.0f}%{subset}")
    lines.append("| **mean** | | " + " | ".join(means) + " |")
    return "\n".join(lines)


def pooled(results: list[dict]) -> list[dict]:
    """One cell per (label, task): runs of the same cell on other seeds (``--extra=--seed=1010``) add their
    episodes to it rather than replace it, so two 10-episode runs give one 20-episode rate."""
    cells: dict[tuple[str, str], dict] = {}
    for r in results:
        key = (r["label"], r["task"])
        if key not in cells:
            cells[key] = {**r, "successes": list(r["successes"])}
            continue
        cell = cells[key]
        if r["command"] in cell["command"].split("\n"):  # same seeds: the same episodes counted twice
            raise ValueError(f"{key[0]}/{key[1]} is given twice with the same command: {r['command']}")
        cell["command"] += "\n" + r["command"]
        cell["successes"] += r["successes"]
        cell["n_episodes"] += r["n_episodes"]
        cell["pc_success"] = 100.0 * sum(cell["successes"]) / len(cell["successes"])
        cell["seconds"] = None if None in (cell["seconds"], r["seconds"]) else cell["seconds"] + r["seconds"]
    return list(cells.values())


def merged_table(json_files: list[Path]) -> str:
    """One table from several runs' JSON files (policies, tasks or seeds evaluated separately)."""
    results, labels = [], []
    for f in json_files:
        run = json.loads(Path(f).read_text())
        results += run["results"]
        labels += [lab for lab in run["policies"] if lab not in labels]
    cells = pooled(results)
    episodes = sorted({c["n_episodes"] for c in cells})
    return table(cells, labels) + f"\n\nEpisodes per cell: {', '.join(map(str, episodes))}."


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--merge", nargs="+", type=Path, help="print one table from these result JSON files and exit"
    )
    ap.add_argument("--policy", action="append", help="LABEL=CHECKPOINT_DIR (repeatable)")
    ap.add_argument("--tasks", nargs="*", default=list(TASK_NAMES))
    ap.add_argument("--episodes", type=int, default=5, help="episodes per task")
    ap.add_argument(
        "--image-size",
        type=int,
        default=128,
        help="camera size of the env; a state-only policy does not look at it (smaller renders faster)",
    )
    ap.add_argument(
        "--steps-per-subtask",
        type=int,
        default=STEPS_PER_OBJECT,
        help="episode limit per object to move (the scripted operator needs 210-420 control steps per sub-task)",
    )
    ap.add_argument(
        "--video-frame-stride",
        type=int,
        default=5,
        help="lerobot-eval's videos (first 10 episodes) get a new frame every k-th step, 5 frames/s at 5: "
        "rendering every step was 3/4 of a state policy's evaluation time (1: every step)",
    )
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--workdir", type=Path, default=Path("outputs/talos_suite"))
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/talos_kitchen_suite"))
    ap.add_argument(
        "--extra",
        action="append",
        default=[],
        help="one more lerobot-eval flag (repeatable), e.g. --extra=--policy.n_action_steps=10; "
        "--policy.* / --env.* / --eval.* flags given directly are passed on too",
    )
    return ap


def parse_args(
    argv: list[str] | None = None, ap: argparse.ArgumentParser | None = None
) -> argparse.Namespace:
    """This script's flags; lerobot-eval's own (``--policy.n_action_steps=20``) go on to every run."""
    ap = ap or build_parser()
    args, unknown = ap.parse_known_args(argv)
    passed_on = [a for a in unknown if a.startswith(EVAL_FLAG_PREFIXES)]
    rest = [a for a in unknown if a not in passed_on]
    if rest:
        ap.error(
            f"unrecognized arguments: {' '.join(rest)} (lerobot-eval flags start with {EVAL_FLAG_PREFIXES}, written --flag=value)"
        )
    args.extra = [*args.extra, *passed_on]
    return args


def main(argv: list[str] | None = None) -> None:
    ap = build_parser()
    args = parse_args(argv, ap)
    if args.merge:
        print(merged_table(args.merge))
        return
    if not args.policy:
        ap.error("--policy LABEL=CHECKPOINT_DIR is required (or --merge)")

    policies = dict(p.split("=", 1) for p in args.policy)
    jobs = [(lab, ckpt, task) for task in args.tasks for lab, ckpt in policies.items()]
    t0 = time.perf_counter()
    with ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda j: run_one(*j, args, args.workdir), jobs))
    minutes = (time.perf_counter() - t0) / 60
    labels = list(policies)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(
        json.dumps(
            {
                "policies": policies,
                "episodes_per_task": args.episodes,
                "results": results,
                "minutes": minutes,
            },
            indent=1,
        )
    )
    md = table(results, labels)
    recorded = [r["seconds"] for r in results if r["seconds"] is not None]
    args.out.with_suffix(".md").write_text(
        f"# Talos kitchen suite: success per task ({args.episodes} episodes per task, lerobot-eval)\n\n{md}\n\n"
        f"Episode limit: {args.steps_per_subtask} control steps (20 s) per object to move (door, tray, pot), "
        "e.g. 500 for open_door, 1500 for store_pot. "
        f"Evaluation time {sum(recorded) / 60:.0f} min summed over {len(recorded)} of {len(results)} cells "
        f"(each cell's lerobot-eval, 1 thread); this run's wall time {minutes:.0f} min with {args.jobs} "
        "parallel runs. Checkpoints: "
        + ", ".join(f"`{k}` = `{v}`" for k, v in policies.items())
        + ".\n\nCommand of one cell:\n\n```\n"
        + results[0]["command"]
        + "\n```\n"
    )
    print(md)


if __name__ == "__main__":
    main()
