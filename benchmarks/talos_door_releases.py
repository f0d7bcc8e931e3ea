"""Where a Talos policy lets go of the door, and what its critic believes afterwards.

The play operator moves the door part of the way in 20 % of its door sub-tasks (open to U(-0.9, -0.3) rad,
close to U(-0.6, -0.25)). This rolls a policy out on a door task (``lerobot-efm-log-rollouts``, the same
episodes as ``lerobot-eval`` for a seed), reads the ``.rrd`` back and reports, per episode, the door angle at
each release of the handle and the critic's distance to the goal at the last replanning: a policy that imitates
the partial moves lets go short of the goal's tolerance and then idles where its critic reads the goal as
reached.

    MUJOCO_GL=egl python benchmarks/talos_door_releases.py --policy CKPT --task close_door --episodes 10 \\
        --out benchmarks/results/talos_door_releases_close_door
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
from pathlib import Path

HELD_DOOR = 2  # lerobot_efm.envs.talos_kitchen.grasps.HELD_CODE["door"]


def scalars(rows: list[dict]) -> list[tuple[int, float]]:
    return [(r["step"], r["Scalars:scalars"][0]) for r in rows if r.get("Scalars:scalars") is not None]


def camera_flags(policy: str) -> list[str]:
    """The env flags a checkpoint needs: its camera size if it reads one, else the camera-free state env."""
    features = json.loads((Path(policy) / "config.json").read_text()).get("input_features", {})
    sizes = [f["shape"][-1] for f in features.values() if f.get("type") == "VISUAL"]
    return [f"--env.image_size={sizes[0]}"] if sizes else ["--env.obs_type=state"]


def rollouts_rrd(policy: str, task: str, episodes: int, seed: int) -> dict[str, list[dict]]:
    """Roll ``policy`` out on a Talos task with ``lerobot-efm-log-rollouts`` and read the ``.rrd`` back."""
    from lerobot_efm.viz.rrd import read_rrd

    with tempfile.TemporaryDirectory() as tmp:
        rrd_path = Path(tmp) / "rollouts.rrd"
        cmd = [
            "lerobot-efm-log-rollouts",
            f"--policy.path={policy}",
            "--env.type=talos_kitchen",
            f"--env.task={task}",
            *camera_flags(policy),
            f"--eval.n_episodes={episodes}",
            f"--seed={seed}",
            "--render=false",
            f"--output={rrd_path}",
        ]
        env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
        subprocess.run(cmd, check=True, env=env, capture_output=True)
        return read_rrd(rrd_path)


def episode_summary(rrd: dict, e: int, goal_door: float) -> dict:
    """Releases of the door handle (command falls under 0.5 while the door is held) and the state after."""
    door = dict(scalars(rrd[f"episode_{e}/objects/door"]))
    grip = scalars(rrd[f"episode_{e}/info/grip_command"])
    held = dict(scalars(rrd[f"episode_{e}/info/held"]))
    success = any(v > 0 for _, v in scalars(rrd[f"episode_{e}/success"]))
    releases = [
        round(door[s], 3)
        for (_, prev), (s, now) in zip(grip, grip[1:], strict=False)
        if prev >= 0.5 > now and held.get(s - 1) == HELD_DOOR
    ]
    critic = scalars(rrd[f"episode_{e}/distance/critic"])
    last_step = max(door)
    return {
        "episode": e,
        "success": success,
        "steps": last_step,  # the state is logged before the first step and after each
        "door_at_releases": releases,
        "final_door": round(door[last_step], 3),
        "final_door_error": round(abs(door[last_step] - goal_door), 3),
        "last_critic_distance": round(critic[-1][1], 1) if critic else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", required=True, help="checkpoint dir (pretrained_model)")
    ap.add_argument("--task", default="close_door", choices=["open_door", "close_door"])
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=None, help="writes OUT.json and OUT.md")
    args = ap.parse_args()

    from lerobot_efm.envs.talos_kitchen.tasks import DOOR_TOL, TASKS

    goal_door = TASKS[args.task].goal.door
    rrd = rollouts_rrd(args.policy, args.task, args.episodes, args.seed)
    episodes = [episode_summary(rrd, e, goal_door) for e in range(args.episodes)]
    failures = [ep for ep in episodes if not ep["success"]]
    short = [ep for ep in failures if any(abs(d - goal_door) >= DOOR_TOL for d in ep["door_at_releases"])]
    lines = [
        f"# Door releases: {args.task}, {args.episodes} episodes (seeds {args.seed}-{args.seed + args.episodes - 1})",
        "",
        f"Policy `{args.policy}`; goal door {goal_door} rad, tolerance {DOOR_TOL} rad.",
        "",
        "| episode | success | steps | door at each release (rad) | final door error | critic distance at the end |",
        "|---:|---|---:|---|---:|---:|",
        *(
            f"| {ep['episode']} | {ep['success']} | {ep['steps']} | {ep['door_at_releases']} | "
            f"{ep['final_door_error']} | {ep['last_critic_distance']} |"
            for ep in episodes
        ),
        "",
        f"Successes {len(episodes) - len(failures)} / {len(episodes)}; failures that let go of the door outside "
        f"the goal's tolerance: {len(short)} / {len(failures)}.",
    ]
    print("\n".join(lines))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".json").write_text(
            json.dumps({"policy": args.policy, "task": args.task, "episodes": episodes}, indent=1)
        )
        args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
