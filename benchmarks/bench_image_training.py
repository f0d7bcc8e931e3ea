#!/usr/bin/env python
"""Where a Talos image training step goes on the CPU: ``lerobot-train`` of the CPU image config
(``train_configs/talos_kitchen_efm_ac_image_cpu.json``: 64x64 camera + 20-D proprioception, no object state) on a
Talos play recording (128x128 AV1 video, 2000-frame episodes as the results' recording), with frames decoded per
sample (``--policy.cache_frames=false``) and decoded once into RAM (``true``).

Numbers come from lerobot-train's own log: ``updt_s`` (forward, backward, optimiser, EMA) and ``data_s``
(waiting for the batch) averaged over each ``log_freq`` window, the first window dropped (warm-up, cache
building). steps/s = 1 / (updt_s + data_s).

    MUJOCO_GL=egl .venv/bin/python benchmarks/bench_image_training.py --threads 2 \\
        --out benchmarks/results/talos_image_train_cpu.md
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
CONFIG = "train_configs/talos_kitchen_efm_ac_image_cpu.json"
LOG_LINE = re.compile(r"step:(\S+) .*updt_s:([\d.]+) data_s:([\d.]+)")
CACHE_LINE = re.compile(
    r"cache_frames: decoding the (\d+) frames of (\S+) once, kept in RAM as (.*) uint8 \((\d+) MB\)"
)


def env(threads: int) -> dict:
    return {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl", "OMP_NUM_THREADS": str(threads)}


def record(root: Path, episodes: int, frames: int, threads: int) -> float:
    """A Talos play recording of ``episodes`` x ``frames`` frames (kept between runs)."""
    if (root / "meta" / "info.json").is_file():
        return 0.0
    start = time.perf_counter()
    subprocess.run(
        [
            BIN / "lerobot-efm-record",
            "--env.type=talos_kitchen",
            f"--dataset.root={root}",
            "--dataset.repo_id=local/talos_bench_play",
            f"--dataset.num_episodes={episodes}",
            f"--dataset.episode_time_s={frames / 25}",  # the kitchen runs at 25 fps
            "--dataset.push_to_hub=false",
            "--seed=1000",
        ],
        env=env(threads),
        check=True,
        capture_output=True,
    )
    return time.perf_counter() - start


def train(root: Path, out: Path, cache: bool, steps: int, log_freq: int, threads: int, batch: int) -> dict:
    start = time.perf_counter()
    proc = subprocess.run(
        [
            BIN / "lerobot-train",
            f"--config_path={CONFIG}",
            f"--dataset.root={root}",
            "--dataset.repo_id=local/talos_bench_play",
            f"--policy.cache_frames={str(cache).lower()}",
            f"--batch_size={batch}",
            f"--steps={steps}",
            f"--log_freq={log_freq}",
            f"--save_freq={steps}",
            "--save_checkpoint=false",
            f"--output_dir={out}",
        ],
        env=env(threads),
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise RuntimeError(f"lerobot-train failed:\n{proc.stderr[-3000:]}")
    text = proc.stdout + proc.stderr
    windows = [(float(u), float(d)) for _, u, d in LOG_LINE.findall(text)][1:]
    if not windows:
        raise RuntimeError(f"no lerobot-train log line with updt_s/data_s in:\n{text[-2000:]}")
    updt = statistics.median(u for u, _ in windows)
    data = statistics.median(d for _, d in windows)
    cache_info = CACHE_LINE.search(text)
    return {
        "cache_frames": cache,
        "batch": batch,
        "updt_s": updt,
        "data_s": data,
        "steps_per_s": 1.0 / (updt + data),
        "wall_s": wall,
        "cache": None if cache_info is None else f"{cache_info.group(3)}, {cache_info.group(4)} MB",
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--log-freq", type=int, default=50)
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--frames", type=int, default=2000, help="frames per recorded episode")
    ap.add_argument("--work-dir", default="outputs/bench_image_training")
    ap.add_argument("--out", default=None)
    ap.add_argument(
        "--batch-sizes",
        type=int,
        nargs="+",
        default=[64],
        help="cached-frame runs at each batch size (the per-sample decoding run uses the first)",
    )
    args = ap.parse_args()

    work = REPO_ROOT / args.work_dir
    root = work / "play"
    record_s = record(root, args.episodes, args.frames, args.threads)
    first = args.batch_sizes[0]
    runs = [(False, first)] + [(True, b) for b in args.batch_sizes]
    rows = [
        train(root, work / f"train_cache_{c}_b{b}", c, args.steps, args.log_freq, args.threads, b)
        for c, b in runs
    ]
    load = os.getloadavg()
    lines = [
        "# Talos image training step on CPU: decoding per sample vs. frames cached once",
        "",
        f"Generated {datetime.now(UTC).isoformat(timespec='seconds')} by "
        f"`benchmarks/bench_image_training.py --threads {args.threads} --steps {args.steps} "
        f"--batch-sizes {' '.join(map(str, args.batch_sizes))}` on {platform.node()} "
        f"({os.cpu_count()} CPUs, Python {platform.python_version()}), load average at the end "
        f"{load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}.",
        "",
        f"Config `{CONFIG}` (FM-AC no-RL, 64x64 camera + 20-D proprioception), {args.threads} thread(s); "
        f"recording: {args.episodes} Talos play episodes x {args.frames} frames, 128x128 video"
        + (f" (recorded in {record_s:.0f} s)" if record_s else "")
        + ". Medians over lerobot-train's log windows of "
        f"{args.log_freq} steps, the first dropped.",
        "",
        "| cache_frames | batch | update s/step | data s/step | steps/s | run wall s | cache |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        lines.append(
            f"| {str(r['cache_frames']).lower()} | {r['batch']} | {r['updt_s']:.3f} | {r['data_s']:.3f} | {r['steps_per_s']:.2f} | "
            f"{r['wall_s']:.0f} | {r['cache'] or '–'} |"
        )
    report = "\n".join(lines) + "\n"
    print(report)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(report)


if __name__ == "__main__":
    main()
