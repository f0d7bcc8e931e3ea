"""Grasp success of the scripted Talos play operator, and how fast the simulated gripper closes.

Every closure of the gripper (command > 0.5) in a play run is classified by
``lerobot_efm.envs.talos_kitchen.grasps`` as held / abandoned / touched / missed. The operator's
abandoned closures are the aborted grasps the policies learn from (issue 14), so their share and
where they happen matter as much as the held rate. Physics only (``env.advance``, no rendering).

    MUJOCO_GL=egl python benchmarks/talos_grasps.py --episodes 4 --steps 3000 \\
        --out benchmarks/results/talos_grasps
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np


def free_closing(env, max_frames: int = 100) -> dict:
    """Frames (25 Hz) from a close command to 50 % / 95 % measured closure, on air at the home pose."""
    from lerobot_efm.envs.talos_kitchen import scene

    env.reset(seed=0)
    cmd = env.observe()["agent_pos"][:10].astype(np.float32).copy()
    cmd[9] = 1.0
    out = {"frames_to_50": None, "frames_to_95": None}
    for t in range(1, max_frames + 1):
        env.advance(cmd)
        c = scene.gripper_opening(env.data, env.h)
        if out["frames_to_50"] is None and c >= 0.5:
            out["frames_to_50"] = t
        if c >= 0.95:
            out["frames_to_95"] = t
            break
    return out


def operator_closures(env, episodes: int, steps: int, seed: int):
    """(intended grasps, deliberate misses): closures of ``episodes`` play runs of ``steps`` commands."""
    from lerobot_efm.envs.talos_kitchen import grasps, play

    op = play.TalosPlayOperator(env, np.random.default_rng(seed))
    intended, missed = [], []
    for _ in range(episodes):
        op.reset()
        samples, missing = [], []
        for _ in range(steps):
            a = op.act(None)
            missing.append(op.missing_grasp)
            env.advance(a)
            samples.append(grasps.sample(env.data, env.h, float(a[9])))
        for run in grasps.closures(samples):
            (missed if missing[run.start] else intended).append(run)
    return intended, missed


def to_markdown(report: dict) -> str:
    s, f = report["summary"], report["free_closing"]
    lines = [
        "# Talos kitchen grasps: scripted play operator",
        "",
        f"Command: `{report['command']}`",
        "",
        f"{report['episodes']} play runs x {report['steps']} commands (25 Hz), seed {report['seed']}, "
        f"{report['seconds']:.0f} s.",
        "",
        f"Free closing on air (command 0 -> 1 at home): 50 % closure after {f['frames_to_50']} frames, "
        f"95 % after {f['frames_to_95']} frames (25 Hz).",
        "",
        "| closures | count | held | abandoned | touched | missed | held rate | median frames to weld |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for label, key in (("intended grasps", "summary"), ("deliberate misses", "deliberate_misses")):
        r = report[key]
        lines.append(
            f"| {label} | {r['closures']} | {r['held']} | {r['abandoned']} | {r['touched']} | {r['missed']} | "
            f"{100 * r['held_rate']:.0f} % | {r['median_frames_to_weld']:.0f} |"
        )
    lines += [
        "",
        "Intended grasps per object:",
        "",
        "| object | closures | held |",
        "|---|---:|---:|",
    ]
    lines += [f"| {k} | {v['closures']} | {v['held']} |" for k, v in s["per_object"].items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--steps", type=int, default=3000, help="commands per play run")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/talos_grasps"))
    args = ap.parse_args(argv)
    os.environ.setdefault("MUJOCO_GL", "egl")
    from lerobot_efm.envs.talos_kitchen import grasps
    from lerobot_efm.envs.talos_kitchen.env import TalosKitchenEnv

    env = TalosKitchenEnv(image_size=32)
    t0 = time.perf_counter()
    runs, misses = operator_closures(env, args.episodes, args.steps, args.seed)
    report = {
        "command": "python benchmarks/talos_grasps.py "
        f"--episodes {args.episodes} --steps {args.steps} --seed {args.seed} --out {args.out}",
        "episodes": args.episodes,
        "steps": args.steps,
        "seed": args.seed,
        "free_closing": free_closing(env),
        "summary": grasps.summarize(runs),
        "deliberate_misses": grasps.summarize(misses),
        "closures": grasps.as_rows(runs),
        "deliberate_miss_closures": grasps.as_rows(misses),
    }
    report["seconds"] = time.perf_counter() - t0
    env.close()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=1))
    args.out.with_suffix(".md").write_text(to_markdown(report))
    print(to_markdown(report))


if __name__ == "__main__":
    main()
