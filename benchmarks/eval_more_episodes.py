"""Re-evaluate planar push checkpoints with more episodes and fresh seeds, to tell a real gap from noise.

The paper runner evaluates 50 episodes (5 per pair, eval seed 1000): one checkpoint's success moves by up to
8 points between neighbours, so two cells 2-14 points apart may not differ at all. This runs ``lerobot-eval`` on
each ``LABEL=CHECKPOINT`` with ``--episodes`` (default 200 = 20 per pair) and another seed, then prints success,
goal distance closed and success per pair (episode i plays pair i mod 10, as in the runner's tables). An
existing ``<work-dir>/<label>/eval_info.json`` is reused.

``--variant NAME="--policy.a=1 --policy.b=2"`` (repeatable) evaluates every checkpoint once more with those
``lerobot-eval`` overrides, e.g. an inference-time setting such as the acting critic query's ODE solver; each
variant's rows sit under the checkpoint's ``as trained`` row, on the same episodes.

    python benchmarks/eval_more_episodes.py noRL=outputs/.../checkpoints/024000/pretrained_model \\
        slack=outputs/.../checkpoints/024000/pretrained_model --out benchmarks/results/x.md
    python benchmarks/eval_more_episodes.py ac=CKPT --episodes 50 --seed 1000 \\
        --variant heun5="--policy.critic_inference_solver=heun --policy.critic_inference_steps=5"
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from paper_experiments import parse_eval_info  # noqa: E402

BIN = Path(sys.executable).parent
PAIRS = 10


def evaluate(
    checkpoint: str, out: Path, episodes: int, seed: int, overrides: tuple[str, ...] = ()
) -> list[str]:
    cmd = [
        "lerobot-eval",
        f"--policy.path={checkpoint}",
        "--env.type=planar_push",
        "--env.task=all",
        "--env.reward=progress",
        f"--eval.n_episodes={episodes}",
        "--eval.batch_size=50",
        "--eval.use_async_envs=false",
        "--policy.device=cpu",
        f"--seed={seed}",
        f"--output_dir={out}",
        *overrides,
    ]
    if not (out / "eval_info.json").is_file():
        env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "1")}
        subprocess.run([str(BIN / cmd[0]), *cmd[1:]], check=True, env=env, capture_output=True)
    return cmd


def parse_variant(text: str) -> tuple[str, tuple[str, ...]]:
    """``'heun5=--policy.a=1 --policy.b=2'`` -> ``('heun5', ('--policy.a=1', '--policy.b=2'))``."""
    name, _, args = text.partition("=")
    overrides = tuple(shlex.split(args))
    if not name or not overrides or not all(a.startswith("--") for a in overrides):
        raise SystemExit(f'--variant expects NAME="--flag=value ...", got {text!r}')
    return name, overrides


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoints", nargs="+", help="LABEL=CHECKPOINT_DIR")
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=5000, help="eval seed (the runner uses 1000)")
    ap.add_argument("--work-dir", type=Path, default=Path("outputs/eval_more"))
    ap.add_argument("--out", type=Path, default=None, help="markdown report")
    ap.add_argument(
        "--variant",
        action="append",
        default=[],
        metavar='NAME="--policy.x=1 ..."',
        help="also evaluate every checkpoint with these lerobot-eval overrides (repeatable)",
    )
    args = ap.parse_args(argv)
    variants = [("as trained", ())] + [parse_variant(v) for v in args.variant]
    lines = [
        f"| checkpoint | setting | episodes | success % | closed % | success % per pair 0-{PAIRS - 1} |",
        "|---|---|---:|---:|---:|---|",
    ]
    commands = []
    for item in args.checkpoints:
        label, _, checkpoint = item.partition("=")
        if not checkpoint:
            raise SystemExit(f"expected LABEL=CHECKPOINT_DIR, got {item!r}")
        for name, overrides in variants:
            out = args.work_dir / (label if not overrides else f"{label}-{name}")
            commands.append(" ".join(evaluate(checkpoint, out, args.episodes, args.seed, overrides)))
            info = json.loads((out / "eval_info.json").read_text())
            s = parse_eval_info(info, PAIRS, "pair", 0, seed=args.seed)
            pairs = " / ".join(f"{t['pc_success']:.0f}" for t in s["per_task"].values())
            lines.append(
                f"| {label} | {name} | {s['n_episodes']} | {s['pc_success']:.1f} "
                f"| {100 * s['mean_sum_reward']:.0f} | {pairs} |"
            )
    report = "\n".join(lines) + "\n\nCommands:\n\n```bash\n" + "\n".join(commands) + "\n```\n"
    print(report)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(report)


if __name__ == "__main__":
    main()
