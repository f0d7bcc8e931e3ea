#!/usr/bin/env python
"""The paper's agent comparison (Fig. 5 OGBench table, Fig. 7 planar push table), run with LeRobot's own CLIs.

For every (variant, dataset) cell: ``lerobot-train --config_path=train_configs/<suite>.json
--policy.type=efm_xx --policy.use_rl=...`` (one fixed hyper-parameter set per suite, as in the paper), then
``lerobot-eval`` on the suite's evaluation tasks, then a markdown table of our success rate next to the paper's
(rows = the nine agent variants, columns = datasets) and a JSON file with every command, budget and wall time.

Suites:

* ``ogbench``: locally generated OGBench ``pointmaze-large-{navigate,stitch}-v0`` (official sizes, see
  ``datasets_cards/ogbench_pointmaze.md``), evaluated on OGBench's task1..task5 (``--env.task=all``: seeded
  resets cycle the five tasks, so ``--eval-episodes`` must be a multiple of 5).
* ``planar_push``: scripted ``expert`` / ``full`` / ``partitioned`` play recorded to the paper's dataset sizes,
  evaluated on the 10 fixed (start, goal) pairs (``--env.task=all``; a multiple of 10 episodes).

Budgets: the full paper budget is 200k steps at batch 128 (``--device cuda``, the configs' values). On CPU the
default is ``CPU_STEPS`` steps at batch ``CPU_BATCH`` (stated in the report); the EMA cutoff then shrinks to
``steps / 10`` when that is shorter than the paper's (an EMA with a 5000-update cutoff barely moves in 2000
updates), and LeRobot's cosine schedule scales its warm-up/decay down to a shorter budget by itself; a budget
longer than the config's ``scheduler_decay_steps`` stretches the decay to it.

Resumable: a cell whose ``result.json`` exists under ``--work-dir`` is not re-run; a finished training whose
evaluation is missing is only re-evaluated; an interrupted training resumes from its last checkpoint
(``lerobot-train --resume=true``), its time summed over the segments (``train_segments.json``). Datasets are
generated once under ``--data-root``. Cells of
several invocations (or machines) meet in one report through ``--cached-only`` and ``--import-report`` (the
committed JSON of an earlier report with the same budget).

    python benchmarks/paper_experiments.py --suite planar_push --variants all --device cpu
    python benchmarks/paper_experiments.py --suite ogbench --device cuda --steps 200000 --eval-episodes 100 --jobs 3
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import fcntl
import importlib
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from recorder_pins import PLANAR_PINS

from lerobot_efm.modeling_efm import AGENT_NAMES

REPO_ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
RESULT_FILE = "result.json"
CHECKPOINT = Path("checkpoints") / "last" / "pretrained_model"

FULL_STEPS, FULL_BATCH = 200_000, 128
CPU_STEPS, CPU_BATCH = 2_000, 64
EVAL_SEED = 1000  # lerobot-eval's default seed, passed explicitly: episode i runs seed EVAL_SEED + i

# variant name -> (policy type, use_rl, paper label): the paper's nine agent variants (Table I, Fig. 5 and 7)
VARIANTS: dict[str, tuple[str, bool, str]] = {
    **{
        short: (f"efm_{short}", False, name if short == "gc" else f"{name} no-RL")
        for short, name in AGENT_NAMES.items()
    },
    **{
        f"{short}_rl": (f"efm_{short}", True, f"{name} use-RL")
        for short, name in AGENT_NAMES.items()
        if short != "gc"
    },
}


@dataclass(frozen=True)
class Suite:
    name: str
    config: str  # train config under train_configs/
    env_args: tuple[str, ...]  # lerobot-eval env selection (dataset-independent part)
    datasets: tuple[str, ...]
    dataset_columns: dict[str, str]  # dataset -> column title
    num_tasks: int  # eval tasks cycled by seeded resets; eval episodes must be a multiple
    task_prefix: str
    first_task: int  # number of the task a seed divisible by num_tasks runs (task1 / pair0)
    paper: dict[str, dict[str, str]]  # variant -> dataset -> the paper's number (as printed)
    paper_source: str
    full_eval_episodes: int
    cpu_eval_episodes: int
    episodes_note: str
    progress_note: str = (
        ""  # the env runs with --env.reward=progress: what its sum_reward (closed share) measures
    )
    reference: str = ""  # "module:function" returning a scripted reference's {"pc_success", "pc_closed"}
    reference_name: str = ""


# Fig. 5 (OGBench success %, single run per cell in the paper); only the datasets we can generate offline.
OGBENCH_PAPER = {
    "pointmaze-large-navigate-v0": dict(
        gc=66, ac=60, pc=60, ps=31, **{"as": 29}, ac_rl=89, pc_rl=89, ps_rl=67, as_rl=64
    ),
    "pointmaze-large-stitch-v0": dict(
        gc=39, ac=37, pc=23, ps=15, **{"as": 14}, ac_rl=40, pc_rl=40, ps_rl=42, as_rl=44
    ),
}
# Fig. 7 (planar push final success %, mean ± std over 4 runs x 8 seeds): Expert / Full / Partitioned.
PLANAR_PAPER_ROWS = {
    "gc": ("96±5", "65±4", "47±5"),
    "ac": ("96±4", "97±2", "52±7"),
    "pc": ("99±2", "91±3", "62±5"),
    "ps": ("92±4", "73±6", "47±4"),
    "as": ("34±8", "82±6", "49±5"),
    "ac_rl": ("32±8", "89±3", "78±4"),
    "pc_rl": ("68±21", "89±4", "90±3"),
    "ps_rl": ("60±35", "67±9", "67±10"),
    "as_rl": ("42±18", "77±7", "68±5"),
}
PLANAR_DATASETS = ("expert", "full", "partitioned")
# Paper dataset sizes (frames of mouse teleoperation at 20 Hz): reach_goal / play_full / play_stitch.
PLANAR_FRAMES = {"expert": 46_793, "full": 36_661, "partitioned": 29_087}
OGBENCH_DATASETS = tuple(OGBENCH_PAPER)

SUITES: dict[str, Suite] = {
    "ogbench": Suite(
        name="ogbench",
        config="ogbench_pointmaze_efm.json",
        env_args=("--env.type=ogbench", "--env.task=all", "--env.reward=progress"),
        datasets=OGBENCH_DATASETS,
        dataset_columns={
            "pointmaze-large-navigate-v0": "pointmaze-large-navigate",
            "pointmaze-large-stitch-v0": "pointmaze-large-stitch",
        },
        num_tasks=5,
        task_prefix="task",
        first_task=1,
        paper={v: {d: str(OGBENCH_PAPER[d][v]) for d in OGBENCH_DATASETS} for v in VARIANTS},
        paper_source="paper Fig. 5 (OGBench, 5 tasks x 20 episodes, 200k steps)",
        full_eval_episodes=100,
        cpu_eval_episodes=10,
        episodes_note="OGBench task1..task5, seeded resets cycle them (task = seed % 5 + 1)",
        progress_note="1 - C_end / C_0, C = maze cells between the point and the goal along OGBench's BFS map",
        reference="lerobot_efm.ogbench.generate:evaluate_oracle",
        reference_name="the noise-free BFS oracle (`oracle_direction`, privileged maze map; navigate and stitch "
        "share the maze and its five tasks)",
    ),
    "planar_push": Suite(
        name="planar_push",
        config="planar_push_efm.json",
        env_args=("--env.type=planar_push", "--env.task=all", "--env.reward=progress"),
        datasets=PLANAR_DATASETS,
        dataset_columns={"expert": "Expert", "full": "Full", "partitioned": "Partitioned"},
        num_tasks=10,
        task_prefix="pair",
        first_task=0,
        paper={v: dict(zip(PLANAR_DATASETS, row, strict=True)) for v, row in PLANAR_PAPER_ROWS.items()},
        paper_source="paper Fig. 7 (planar push final success, mean±std of 4 runs x 8 seeds, 200k steps)",
        full_eval_episodes=60,
        cpu_eval_episodes=10,
        episodes_note="the 10 fixed (start, goal) pairs of `--env.task=all`",
        progress_note="1 - D_end / D_0, D = |disc - goal| + |effector - goal| (straight line)",
        reference="lerobot_efm.envs.planar_push.demonstrators:evaluate_expert",
        reference_name="the scripted expert (`ExpertReachGoal`, privileged state)",
    ),
}


# ------------------------------------------------------------------------------------------- helpers


def parse_list(values: list[str] | None, valid: tuple[str, ...] | list[str], what: str) -> list[str]:
    """``all`` or names (space- or comma-separated) -> list in ``valid``'s order; unknown names raise."""
    names = [n for v in (values or ["all"]) for n in v.replace(",", " ").split()]
    if not names or names == ["all"]:
        return list(valid)
    bad = [n for n in names if n not in valid]
    if bad:
        raise ValueError(f"Unknown {what} {bad}; valid: {list(valid)} or 'all'")
    return [v for v in valid if v in names]


def run_logged(cmd: list[str], log: Path, cwd: Path = REPO_ROOT) -> float:
    """Run ``cmd`` with its output in ``log``; returns the wall time. Raises with the log tail on failure."""
    env = {
        **os.environ,
        "HF_HUB_OFFLINE": os.environ.get("HF_HUB_OFFLINE", "1"),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    }
    log.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with log.open("w") as out:
        proc = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=cwd)
    wall = time.perf_counter() - start
    if proc.returncode:
        raise RuntimeError(
            f"{Path(cmd[0]).name} failed (exit {proc.returncode}); log {log}:\n{log.read_text()[-2500:]}"
        )
    return wall


def shell(cmd: list[str]) -> str:
    """A command as one would type it (paths relative to the repo root where possible)."""

    def rel(a: str) -> str:
        for prefix in (str(BIN) + os.sep, str(REPO_ROOT) + os.sep):
            a = a.replace(prefix, "")
        return a

    return " ".join(shlex.quote(rel(a)) for a in cmd)


# ------------------------------------------------------------------------------------------- datasets


@dataclass
class DataSpec:
    """How big a generated dataset is; ``None`` = the paper's / OGBench's official size."""

    ogbench_episodes: int | None = None
    ogbench_episode_steps: int | None = None
    planar_frames: int | None = None

    def tag(self, suite: str) -> str:
        if suite == "ogbench" and (self.ogbench_episodes or self.ogbench_episode_steps):
            return f"-e{self.ogbench_episodes or 'full'}x{self.ogbench_episode_steps or 'full'}"
        if suite == "planar_push" and self.planar_frames:
            return f"-f{self.planar_frames}"
        return ""


def dataset_repo_id(suite: str, dataset: str) -> str:
    return f"local/{dataset}" if suite == "ogbench" else f"local/planar_push_{dataset}"


def dataset_root(data_root: Path, suite: str, dataset: str, spec: DataSpec) -> Path:
    return data_root / suite / f"{dataset}{spec.tag(suite)}"


def generate_command(suite: str, dataset: str, root: Path, spec: DataSpec) -> list[str]:
    py = [sys.executable, "-m"]
    if suite == "ogbench":
        cmd = [
            *py,
            "lerobot_efm.ogbench.generate",
            f"--ogbench_dataset={dataset}",
            f"--dataset.repo_id={dataset_repo_id(suite, dataset)}",
            f"--dataset.root={root}",
        ]
        if spec.ogbench_episodes:
            cmd.append(f"--num_episodes={spec.ogbench_episodes}")
        if spec.ogbench_episode_steps:
            cmd.append(f"--episode_steps={spec.ogbench_episode_steps}")
        return cmd
    frames = spec.planar_frames or PLANAR_FRAMES[dataset]
    return [
        *py,
        "lerobot_efm.envs.planar_push.demonstrators",
        f"--operator.type=planar_push_{dataset}",
        *[f"--operator.{option}" for option in PLANAR_PINS.get(dataset, ())],
        f"--dataset.repo_id={dataset_repo_id(suite, dataset)}",
        f"--dataset.root={root}",
        f"--num_frames={frames}",
    ]


def ensure_dataset(
    suite: str, dataset: str, data_root: Path, spec: DataSpec
) -> tuple[Path, str | None, float]:
    """Generate the dataset unless ``meta/info.json`` exists; returns (root, generating command, seconds).

    A cached dataset reports the command and time saved next to it when it was generated (else None, 0)."""
    root = dataset_root(data_root, suite, dataset, spec)
    root.parent.mkdir(parents=True, exist_ok=True)
    # Two runner processes sharing a data root (two 1-thread jobs side by side) must not both generate it: the
    # second would delete the first's half-written recording. The lock makes the second wait, then reuse it.
    with open(root.with_name(f"{root.name}.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if (root / "meta" / "info.json").exists():
            return (root, *dataset_provenance(root))
        shutil.rmtree(root, ignore_errors=True)  # a half-written dataset from an interrupted run
        shutil.rmtree(Path(f"{root}-npz"), ignore_errors=True)
        cmd = generate_command(suite, dataset, root, spec)
        print(f"generating {suite}/{dataset}: {shell(cmd)}", flush=True)
        wall = run_logged(cmd, data_root / suite / f"{root.name}.log")
        provenance_path(root).write_text(
            json.dumps({"command": shell(cmd), "seconds": round(wall, 1)}, indent=2)
        )
        return root, shell(cmd), wall


def provenance_path(root: Path) -> Path:
    return root.with_name(f"{root.name}.generated.json")


def dataset_provenance(root: Path) -> tuple[str | None, float]:
    """(generating command, seconds) saved next to a generated dataset; (None, 0) when unknown."""
    path = provenance_path(root)
    saved = json.loads(path.read_text()) if path.exists() else {}
    return saved.get("command"), float(saved.get("seconds", 0.0))


def import_report(report: Path, suite_name: str, budget: Budget, run_root: Path) -> dict[str, dict]:
    """Write the cells of an earlier report's JSON (e.g. the committed one) as finished cells of this budget.

    Lets a fresh checkout add cells to committed results without re-running them; cells already on disk win.
    Returns the report's dataset notes (provenance of datasets that may no longer exist here)."""
    payload = json.loads(report.read_text())
    ours = json.loads(json.dumps(asdict(budget)))
    theirs = {
        "config": None,
        "seed": 1000,
        "curve_points": 1,
        **(payload.get("budget") or {}),
    }  # older reports
    if payload.get("suite") != suite_name or theirs != ours:
        raise ValueError(
            f"--import-report {report}: its suite {payload.get('suite')!r} and budget "
            f"{theirs} must equal this run's {suite_name!r} and {ours}"
        )
    for cell in payload["cells"]:
        path = run_root / cell["dataset"] / cell["variant"] / RESULT_FILE
        if not cell.get("error") and not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps({k: v for k, v in cell.items() if k != "cached"}, indent=2))
    return payload.get("datasets", {})


# ------------------------------------------------------------------------------------------- one cell


@dataclass
class Budget:
    device: str
    steps: int
    batch_size: int
    eval_episodes: int
    eval_batch_size: int
    eval_async: (
        bool  # AsyncVectorEnv: one process per env, each importing MuJoCo (minutes on a busy 2-core CPU)
    )
    ema_cutoff: float | None  # None: the config's (paper) value
    num_workers: int | None
    train_args: list[str] = field(default_factory=list)  # extra lerobot-train arguments (e.g. tiny networks)
    eval_args: list[str] = field(default_factory=list)  # extra lerobot-eval arguments
    config: str | None = None  # train config under train_configs/ (None: the suite's paper-size config)
    seed: int = 1000  # lerobot-train's --seed (the configs' value by default)
    curve_points: int = 1  # checkpoints saved (every steps/curve_points) and evaluated: the learning curve


def config_name(suite: Suite, budget: Budget) -> str:
    return budget.config or suite.config


def load_config(suite: Suite, budget: Budget) -> dict:
    return json.loads((REPO_ROOT / "train_configs" / config_name(suite, budget)).read_text())


def train_command(
    suite: Suite, variant: str, data: Path, repo_id: str, out: Path, budget: Budget
) -> list[str]:
    policy_type, use_rl, _ = VARIANTS[variant]
    cmd = [
        str(BIN / "lerobot-train"),
        f"--config_path={REPO_ROOT / 'train_configs' / config_name(suite, budget)}",
        f"--policy.type={policy_type}",
        f"--policy.use_rl={str(use_rl).lower()}",
        f"--dataset.repo_id={repo_id}",
        f"--dataset.root={data}",
        f"--output_dir={out}",
        f"--policy.device={budget.device}",
        f"--steps={budget.steps}",
        f"--seed={budget.seed}",
        f"--save_freq={curve_step(budget, 1)}",
        f"--batch_size={budget.batch_size}",
        f"--log_freq={max(1, min(1000, budget.steps // 20))}",
    ]
    if budget.ema_cutoff is not None:
        cmd.append(f"--policy.ema_cutoff={budget.ema_cutoff:g}")
    config = json.loads((REPO_ROOT / "train_configs" / config_name(suite, budget)).read_text())["policy"]
    if budget.steps > config.get("scheduler_decay_steps", 200_000):
        # LeRobot shrinks the cosine schedule to a shorter budget but never stretches it: past the config's
        # decay steps the learning rate would stay at 0 and the rest of the run would not learn.
        cmd.append(f"--policy.scheduler_decay_steps={budget.steps}")
    if budget.num_workers is not None:
        cmd.append(f"--num_workers={budget.num_workers}")
    return cmd + list(budget.train_args)


def curve_step(budget: Budget, k: int) -> int:
    """Training step of the k-th (1-based) evaluated checkpoint; the last one is ``budget.steps``."""
    return budget.steps * k // budget.curve_points


def eval_command(suite: Suite, dataset: str, checkpoint: Path, out: Path, budget: Budget) -> list[str]:
    env = list(suite.env_args) + ([f"--env.dataset={dataset}"] if suite.name == "ogbench" else [])
    return [
        str(BIN / "lerobot-eval"),
        f"--policy.path={checkpoint}",
        *env,
        f"--eval.n_episodes={budget.eval_episodes}",
        f"--eval.batch_size={budget.eval_batch_size}",
        f"--eval.use_async_envs={str(budget.eval_async).lower()}",
        f"--policy.device={budget.device}",
        f"--seed={EVAL_SEED}",
        f"--output_dir={out}",
        *budget.eval_args,
    ]


def parse_eval_info(
    info: dict, num_tasks: int, task_prefix: str, first_task: int, seed: int = EVAL_SEED
) -> dict:
    """``eval_info.json`` -> success % overall and per evaluation task.

    With ``--env.task=all`` lerobot-eval reports one task holding per-episode ``successes``; episode i ran
    seed ``seed + i``, and our envs pick task ``first_task + seed % num_tasks`` for a seeded reset, which gives the
    per-task split."""
    try:
        overall = info["overall"]
        pc, n = float(overall["pc_success"]), int(overall["n_episodes"])
        successes = [bool(s) for task in info["per_task"] for s in task["metrics"]["successes"]]
        rewards = [float(r) for task in info["per_task"] for r in task["metrics"]["sum_rewards"]]
    except (KeyError, TypeError) as err:
        raise ValueError(
            f"eval_info.json lacks {err}; expected overall.pc_success, overall.n_episodes and "
            f"per_task[i].metrics.successes / sum_rewards"
        ) from err
    if len(successes) != n or len(rewards) != n:
        raise ValueError(
            f"eval_info.json: overall.n_episodes={n} but per_task holds {len(successes)} successes "
            f"and {len(rewards)} sum_rewards"
        )
    out = {
        "pc_success": pc,
        "n_episodes": n,
        "n_success": int(sum(successes)),
        "mean_sum_reward": sum(rewards) / n if n else None,
        "per_task": None,
    }
    if n:
        per: dict[str, list[int]] = {}
        for i in range(n):
            per.setdefault(f"{task_prefix}{first_task + (seed + i) % num_tasks}", []).append(i)
        out["per_task"] = {
            k: {
                "pc_success": 100.0 * sum(successes[i] for i in idx) / len(idx),
                "n_episodes": len(idx),
                "mean_sum_reward": sum(rewards[i] for i in idx) / len(idx),
            }
            for k, idx in sorted(per.items())
        }
    return out


def run_cell(suite: Suite, variant: str, dataset: str, data: Path, cell_dir: Path, budget: Budget) -> dict:
    """Train (unless a finished checkpoint exists) and evaluate one cell; writes ``cell_dir/result.json``."""
    result_path = cell_dir / RESULT_FILE
    train_dir, eval_dir = cell_dir / "train", cell_dir / "eval"
    checkpoint = train_dir / CHECKPOINT
    tcmd = train_command(suite, variant, data, dataset_repo_id(suite.name, dataset), train_dir, budget)
    if (checkpoint / "config.json").exists():  # a cached result or a resumed run: same hyper-parameters only
        check_config_unchanged(trained_policy_config(checkpoint), tcmd, load_config(suite, budget), cell_dir)
    if result_path.exists():
        return {**json.loads(result_path.read_text()), "cached": True}
    train_time = cell_dir / "train_seconds.txt"  # kept for re-evaluations of a finished training
    if not train_time.exists():
        seconds = train_or_resume(tcmd, train_dir, cell_dir, budget, suite, dataset, variant)
        if seconds is not None:
            train_time.write_text(f"{seconds:.1f}\n")
    train_s = float(train_time.read_text()) if train_time.exists() else None
    curve = []
    for k in range(1, budget.curve_points):  # intermediate checkpoints, each evaluated once (resumable)
        step = curve_step(budget, k)
        point = evaluate_checkpoint(
            suite,
            dataset,
            train_dir / "checkpoints" / f"{step:06d}" / "pretrained_model",
            cell_dir / f"eval_{step:06d}",
            budget,
            f"{suite.name}/{dataset}/{variant}@{step}",
        )
        curve.append(curve_point(point, step, budget, train_s))
    shutil.rmtree(eval_dir, ignore_errors=True)
    ecmd = eval_command(suite, dataset, checkpoint, eval_dir, budget)
    print(f"[{suite.name}/{dataset}/{variant}] evaluating: {shell(ecmd)}", flush=True)
    eval_s = run_logged(ecmd, cell_dir / "eval.log")
    metrics = parse_eval_info(
        json.loads((eval_dir / "eval_info.json").read_text()),
        suite.num_tasks,
        suite.task_prefix,
        suite.first_task,
        EVAL_SEED,
    )
    curve.append(curve_point(metrics, budget.steps, budget, train_s))
    result = {
        "suite": suite.name,
        "variant": variant,
        "agent": VARIANTS[variant][2],
        "policy_type": VARIANTS[variant][0],
        "use_rl": VARIANTS[variant][1],
        "dataset": dataset,
        **metrics,
        "paper": suite.paper[variant][dataset],
        "steps": budget.steps,
        "batch_size": budget.batch_size,
        "device": budget.device,
        "train_s": train_s,
        "eval_s": eval_s,
        "seed": budget.seed,
        "config": f"train_configs/{config_name(suite, budget)}",
        "steps_per_s": round(budget.steps / train_s, 2) if train_s else None,
        "curve": curve,
        "policy_config": trained_policy_config(checkpoint),
        "train_command": shell(tcmd),
        **train_segments(cell_dir),
        "eval_command": shell(ecmd),
        "finished": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    result_path.write_text(json.dumps(result, indent=2))
    print(
        f"[{suite.name}/{dataset}/{variant}] success {metrics['pc_success']:.0f}% (paper {result['paper']})",
        flush=True,
    )
    return result


def trained_policy_config(checkpoint: Path) -> dict:
    """The hyper-parameters the checkpoint was trained with (its ``config.json``: config file plus every CLI
    override, resolved by lerobot-train): what a report's cell ran, even after the config file changes."""
    saved = json.loads((checkpoint / "config.json").read_text())
    return {k: v for k, v in saved.items() if k not in ("input_features", "output_features")}


def check_config_unchanged(trained: dict, tcmd: list[str], config: dict, cell_dir: Path) -> None:
    """Refuse a cell whose checkpoint was trained with other values than its config file holds now (the file
    was edited since: e.g. the CPU configs' learning rate): its cached result or resumed training would be
    reported under the new values. Keys the train command sets (agent, device, budget, --train-arg) are its own."""
    on_cli = {arg.split("=", 1)[0].removeprefix("--policy.") for arg in tcmd if arg.startswith("--policy.")}
    changed = [
        f"{key}: trained {trained[key]!r}, config now {value!r}"
        for key, value in config["policy"].items()
        if key not in on_cli and key in trained and trained[key] != value
    ]
    if changed:
        raise RuntimeError(
            f"{cell_dir} was trained with other hyper-parameters than its config now holds ({'; '.join(changed)}): "
            "pass another --work-dir, or delete that directory to retrain it"
        )


def train_or_resume(
    tcmd: list[str], train_dir: Path, cell_dir: Path, budget: Budget, suite: Suite, dataset: str, variant: str
) -> float | None:
    """Train the cell, or resume an interrupted training from its last checkpoint; returns the training seconds
    of all segments (None: a finished training of unknown duration). LeRobot resumes sample-exactly (weights,
    EMA, optimiser, schedule, RNG, data order); the seconds of an interrupted segment up to its checkpoint are
    read from its progress bar."""
    name = f"{suite.name}/{dataset}/{variant}"
    saved = saved_step(train_dir)
    if saved is None:
        shutil.rmtree(train_dir, ignore_errors=True)  # nothing saved yet: lerobot-train refuses to overwrite
        print(f"[{name}] training: {shell(tcmd)}", flush=True)
        return run_logged(tcmd, cell_dir / "train.log")
    segments_path = cell_dir / "train_segments.json"
    segments = json.loads(segments_path.read_text()) if segments_path.exists() else []
    if saved < budget.steps:
        log = cell_dir / "train.log"
        start = segments[-1]["to_step"] if segments else 0
        seconds = progress_bar_seconds(log, budget.steps, saved)
        segments.append({"from_step": start, "to_step": saved, "seconds": round(seconds, 1)})
        log.rename(cell_dir / f"train_until_{saved:06d}.log")
        segments_path.write_text(json.dumps(segments, indent=2))
        rcmd = [
            str(BIN / "lerobot-train"),
            f"--config_path={train_dir / 'checkpoints' / 'last' / 'pretrained_model' / 'train_config.json'}",
            "--resume=true",
        ]
        print(f"[{name}] resuming at step {saved}: {shell(rcmd)}", flush=True)
        wall = run_logged(rcmd, log)
        segments.append({"from_step": saved, "to_step": budget.steps, "seconds": round(wall, 1)})
        segments_path.write_text(json.dumps(segments, indent=2))
    return sum(s["seconds"] for s in segments) if segments else None


def train_segments(cell_dir: Path) -> dict:
    """``{"train_segments": [...]}`` for a training resumed after an interruption, else nothing."""
    path = cell_dir / "train_segments.json"
    return {"train_segments": json.loads(path.read_text())} if path.exists() else {}


def saved_step(train_dir: Path) -> int | None:
    """Training step of the last checkpoint lerobot-train saved in ``train_dir`` (None: no checkpoint)."""
    state = train_dir / "checkpoints" / "last" / "training_state" / "training_step.json"
    return json.loads(state.read_text())["step"] if state.exists() else None


def progress_bar_seconds(log: Path, total_steps: int, step: int) -> float:
    """Wall seconds lerobot-train's progress bar shows at ``step`` (extrapolated at its rate from the last
    refresh before it). A resumed run's bar counts ``n / (total_steps - start)`` from its own start."""
    best = None
    for n, total, elapsed in re.findall(r"(\d+)/(\d+) \[([\d:]+)<", log.read_text(errors="replace")):
        at = total_steps - int(total) + int(n)
        if int(n) > 0 and at <= step and (best is None or at > best[0]):
            best = (at, int(n), clock_seconds(elapsed))
    if best is None:
        raise RuntimeError(f"{log}: no progress bar up to step {step}; cannot account its training time")
    at, n, seconds = best
    return seconds * (n + step - at) / n


def clock_seconds(text: str) -> float:
    """'1:48:04' or '05:23' (tqdm's elapsed) in seconds."""
    seconds = 0.0
    for part in text.split(":"):
        seconds = seconds * 60 + int(part)
    return seconds


def evaluate_checkpoint(
    suite: Suite, dataset: str, checkpoint: Path, eval_dir: Path, budget: Budget, name: str
) -> dict:
    """lerobot-eval of one intermediate checkpoint; its metrics are cached in ``eval_dir/metrics.json``."""
    cached = eval_dir / "metrics.json"
    if cached.exists():
        return json.loads(cached.read_text())
    shutil.rmtree(eval_dir, ignore_errors=True)
    ecmd = eval_command(suite, dataset, checkpoint, eval_dir / "lerobot_eval", budget)
    print(f"[{name}] evaluating: {shell(ecmd)}", flush=True)
    run_logged(ecmd, eval_dir / "eval.log")
    metrics = parse_eval_info(
        json.loads((eval_dir / "lerobot_eval" / "eval_info.json").read_text()),
        suite.num_tasks,
        suite.task_prefix,
        suite.first_task,
        EVAL_SEED,
    )
    cached.write_text(json.dumps(metrics, indent=2))
    return metrics


def curve_point(metrics: dict, step: int, budget: Budget, train_s: float | None) -> dict:
    """One point of the learning curve. CPU minutes of training up to ``step`` assume the constant step rate
    of the whole run (checkpoint saving aside, LeRobot's training loop does the same work every step)."""
    minutes = None if train_s is None else round(train_s * step / budget.steps / 60.0, 2)
    return {
        "step": step,
        "train_min": minutes,
        "pc_success": metrics["pc_success"],
        "mean_sum_reward": metrics["mean_sum_reward"],
    }


# ------------------------------------------------------------------------------------------- report


def fmt_pct(value: float | None) -> str:
    return "–" if value is None else f"{value:.0f}"


def results_table(
    suite: Suite, variants: list[str], datasets: list[str], cells: dict[tuple[str, str], dict]
) -> str:
    """Rows = variants, one column per dataset: ``ours (paper)`` success %."""
    head = "| agent | " + " | ".join(f"{suite.dataset_columns[d]}: ours | paper" for d in datasets) + " |"
    sep = "|---|" + "---:|---:|" * len(datasets)
    rows = [head, sep]
    for v in variants:
        parts = []
        for d in datasets:
            cell = cells.get((v, d))
            ours = (
                "failed" if cell and cell.get("error") else fmt_pct(cell.get("pc_success") if cell else None)
            )
            parts.append(f"{ours} | {suite.paper[v][d]}")
        rows.append(f"| {VARIANTS[v][2]} | " + " | ".join(parts) + " |")
    return "\n".join(rows)


def progress_table(
    suite: Suite, variants: list[str], datasets: list[str], cells: dict[tuple[str, str], dict]
) -> str:
    """Rows = variants: mean share (%) of the initial goal distance closed at the end of the episode."""
    rows = [
        "| agent | " + " | ".join(suite.dataset_columns[d] for d in datasets) + " |",
        "|---|" + "---:|" * len(datasets),
    ]
    for v in variants:
        values = []
        for d in datasets:
            r = (cells.get((v, d)) or {}).get("mean_sum_reward")
            values.append(fmt_pct(None if r is None else 100.0 * r))
        rows.append(f"| {VARIANTS[v][2]} | " + " | ".join(values) + " |")
    return "\n".join(rows)


def per_task_table(
    suite: Suite, variants: list[str], datasets: list[str], cells: dict[tuple[str, str], dict]
) -> str:
    lines = []
    for d in datasets:
        tasks = sorted(
            {t for v in variants for t in ((cells.get((v, d)) or {}).get("per_task") or {})},
            key=lambda t: int(t[len(suite.task_prefix) :]),
        )
        if not tasks:
            continue
        lines += [
            f"**{suite.dataset_columns[d]}**",
            "",
            "| agent | " + " | ".join(tasks) + " |",
            "|---|" + "---:|" * len(tasks),
        ]
        for v in variants:
            per = (cells.get((v, d)) or {}).get("per_task") or {}
            lines.append(
                f"| {VARIANTS[v][2]} | "
                + " | ".join(fmt_pct(per.get(t, {}).get("pc_success")) for t in tasks)
                + " |"
            )
        lines.append("")
    return "\n".join(lines)


def curve_table(
    suite: Suite, variants: list[str], datasets: list[str], cells: dict[tuple[str, str], dict]
) -> str:
    """One row per cell with a learning curve: success (training minutes) per checkpoint, and the step rate."""
    rows = []
    for d in datasets:
        for v in variants:
            cell = cells.get((v, d)) or {}
            curve = cell.get("curve") or []
            if len(curve) < 2:
                continue
            if not rows:
                rows = [
                    "| dataset | agent | " + " | ".join(f"step {p['step']}" for p in curve) + " | steps/s |",
                    "|---|---|" + "---:|" * (len(curve) + 1),
                ]
            points = " | ".join(
                f"{p['pc_success']:.0f} ({p['train_min']:.0f} min)"
                if p.get("train_min") is not None
                else f"{p['pc_success']:.0f}"
                for p in curve
            )
            rows.append(
                f"| {suite.dataset_columns[d]} | {VARIANTS[v][2]} | {points} | {cell.get('steps_per_s') or '–'} |"
            )
    return "\n".join(rows)


def gpu_command(suite: Suite) -> str:
    return (
        f".venv/bin/python benchmarks/paper_experiments.py --suite {suite.name} --variants all --datasets all "
        f"--device cuda --steps {FULL_STEPS} --batch-size {FULL_BATCH} --eval-episodes {suite.full_eval_episodes} "
        f"--jobs 3 --out benchmarks/results/paper_experiments_{suite.name}_gpu.md"
    )


def write_report(
    out: Path,
    suite: Suite,
    variants: list[str],
    datasets: list[str],
    cells: dict,
    budget: Budget,
    argv: list[str],
    datasets_info: dict,
    wall_s: float,
) -> None:
    full = budget.steps >= FULL_STEPS and budget.batch_size >= FULL_BATCH
    cfg = load_config(suite, budget)
    ema = budget.ema_cutoff if budget.ema_cutoff is not None else cfg["policy"]["ema_cutoff"]
    budget_line = (
        f"**Budget: {budget.steps} training steps at batch {budget.batch_size} on `{budget.device}`** "
        f"({'the paper budget' if full else f'the paper trains {FULL_STEPS} steps at batch {FULL_BATCH}'}), "
        f"EMA cutoff {ema:g} updates, evaluation {budget.eval_episodes} episodes per cell "
        f"(batch {budget.eval_batch_size}) on {suite.episodes_note}, eval seed {EVAL_SEED}."
    )
    failed = [f"{d}/{v}" for (v, d), c in cells.items() if c.get("error")]
    md = [
        f"# Paper agent comparison: {suite.name}",
        "",
        f"Generated {datetime.now(UTC).isoformat(timespec='seconds')} by",
        "",
        "```bash",
        f".venv/bin/python benchmarks/paper_experiments.py {shlex.join(argv)}",
        "```",
        "",
        f"in {wall_s:.0f} s (cached cells not re-run) on {platform.node() or 'this machine'} "
        f"({os.cpu_count()} CPUs, Python {platform.python_version()}).",
        "",
        budget_line,
        "",
        f"Hyper-parameters: `train_configs/{config_name(suite, budget)}`, training seed {budget.seed} (one fixed set for every agent and dataset, as in the "
        f"paper), with `--policy.type` / `--policy.use_rl` per agent"
        + (" and the budget overrides above" if not full else "")
        + "; the values each cell trained with (config file and overrides, resolved by lerobot-train) are its "
        "`policy_config` in the JSON file next to this report.",
        "",
        f"## Success rate (%): ours | {suite.paper_source}",
        "",
        results_table(suite, variants, datasets, cells),
        "",
    ]
    if not full:
        md += [
            "Our numbers come from a much smaller budget than the paper's and a single seed: they check that the "
            "pipeline trains and evaluates every agent, not the paper's ranking.",
            "",
        ]
    if failed:
        md += [f"Failed cells (see their `train.log` / `eval.log`): {', '.join(failed)}.", ""]
    if len(cells) < len(variants) * len(datasets):
        md += ["`–`: not run at this budget.", ""]
    if suite.progress_note and any(c.get("mean_sum_reward") is not None for c in cells.values()):
        md += [
            "## Goal distance closed (%)",
            "",
            f"Mean over episodes of {suite.progress_note}: lerobot-eval's `sum_reward` under "
            "`--env.reward=progress`. 100 = on the goal, 0 = no closer than at the start (holding still), "
            "negative = further away. A graded score for budgets too small for successes; the paper reports "
            "success only.",
            "",
            progress_table(suite, variants, datasets, cells),
            "",
        ]
        if suite.reference:
            module, func = suite.reference.split(":")
            ref = getattr(importlib.import_module(module), func)()
            md += [
                f"Reference, measured now: {suite.reference_name}, same protocol: {ref['pc_success']:.0f} % "
                f"success, {ref['pc_closed']:.0f} % closed.",
                "",
            ]
    curves_md = curve_table(suite, variants, datasets, cells)
    if curves_md:
        md += [
            "## Learning curves: success % (training minutes) at each evaluated checkpoint",
            "",
            "Minutes of training on one CPU core up to the checkpoint (the run's mean step rate); plots: "
            "`benchmarks/plot_learning_curves.py`.",
            "",
            curves_md,
            "",
        ]
    tasks_md = per_task_table(suite, variants, datasets, cells)
    if tasks_md:
        md += ["## Success per evaluation task (%)", "", tasks_md]
    md += [
        "## Wall time (s): train / eval",
        "",
        "| agent | " + " | ".join(suite.dataset_columns[d] for d in datasets) + " |",
        "|---|" + "---:|" * len(datasets),
    ]
    for v in variants:
        md.append(
            f"| {VARIANTS[v][2]} | "
            + " | ".join(
                f"{fmt_pct((cells.get((v, d)) or {}).get('train_s'))} / {fmt_pct((cells.get((v, d)) or {}).get('eval_s'))}"
                for d in datasets
            )
            + " |"
        )
    resumed = [(k, c["train_segments"]) for k, c in cells.items() if c and c.get("train_segments")]
    if resumed:
        md += ["", "Resumed after an interruption (`lerobot-train --resume=true`; steps: seconds):", ""]
        md += [
            f"- {VARIANTS[v][2]} on {d}: "
            + ", ".join(f"{s['from_step']}-{s['to_step']}: {s['seconds']:.0f}" for s in segments)
            for (v, d), segments in resumed
        ]
    md += ["", "## Datasets", ""]
    for d, info in datasets_info.items():
        gen = (
            f"generated by `{info['command']}`"
            + (f" in {info['generate_s']:.0f} s" if info.get("generate_s") else "")
            if info["command"]
            else "provenance unknown"
        )
        md.append(f"- `{d}`: `{info['root']}` ({gen})")
    md += ["", "## Commands", "", "Every cell runs (paths under the work dir):", "", "```bash"]
    example = next((c for c in cells.values() if c.get("train_command")), None)
    if example:
        md += [example["train_command"], example["eval_command"]]
    md += [
        "```",
        "",
        "The exact command of every cell is in the JSON file next to this report.",
        "",
        "Full paper budget on a GPU (all nine agents, every dataset):",
        "",
        "```bash",
        gpu_command(suite),
        "```",
        "",
    ]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(md))
    payload = {
        "suite": suite.name,
        "argv": argv,
        "budget": asdict(budget),
        "wall_s": wall_s,
        "config": f"train_configs/{config_name(suite, budget)}",
        "paper_source": suite.paper_source,
        "gpu_command": gpu_command(suite),
        "datasets": datasets_info,
        "variants": variants,
        "cells": [cells[(v, d)] for v in variants for d in datasets if (v, d) in cells],
    }
    out.with_suffix(".json").write_text(json.dumps(payload, indent=2))


# ------------------------------------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--suite", required=True, choices=sorted(SUITES))
    ap.add_argument("--datasets", nargs="+", default=["all"], help="dataset names or 'all'")
    ap.add_argument("--variants", nargs="+", default=["all"], help=f"{list(VARIANTS)} or 'all'")
    ap.add_argument("--device", default="cpu", choices=["cpu", "cuda"])
    ap.add_argument(
        "--steps",
        type=int,
        default=None,
        help=f"training steps (default: {CPU_STEPS} on cpu, {FULL_STEPS} on cuda)",
    )
    ap.add_argument(
        "--batch-size", type=int, default=None, help=f"default: {CPU_BATCH} on cpu, {FULL_BATCH} on cuda"
    )
    ap.add_argument(
        "--eval-episodes", type=int, default=None, help="per cell; a multiple of the suite's task count"
    )
    ap.add_argument("--eval-batch-size", type=int, default=10, help="parallel envs in lerobot-eval")
    ap.add_argument(
        "--eval-async", action="store_true", help="lerobot-eval's AsyncVectorEnv (default: sync envs)"
    )
    ap.add_argument(
        "--ema-cutoff",
        type=float,
        default=None,
        help="default: the config's, or steps/10 when shorter (short budgets)",
    )
    ap.add_argument("--jobs", type=int, default=1, help="cells trained/evaluated in parallel")
    ap.add_argument(
        "--config",
        default=None,
        help="train config under train_configs/ (default: the suite's paper-size config)",
    )
    ap.add_argument("--seed", type=int, default=1000, help="training seed (lerobot-train --seed)")
    ap.add_argument(
        "--curve-points",
        type=int,
        default=1,
        help="evaluate this many checkpoints, every steps/N (learning curve); 1 = the last only",
    )
    ap.add_argument(
        "--cached-only",
        action="store_true",
        help="run nothing: report the finished cells of this budget (e.g. from several invocations)",
    )
    ap.add_argument("--out", type=Path, default=None, help="markdown report (JSON next to it)")
    ap.add_argument(
        "--import-report",
        type=Path,
        action="append",
        default=[],
        help="JSON of an earlier report with this budget: its cells count as finished (repeatable)",
    )
    ap.add_argument("--work-dir", type=Path, default=REPO_ROOT / "outputs" / "paper_experiments" / "runs")
    ap.add_argument("--data-root", type=Path, default=REPO_ROOT / "outputs" / "paper_experiments" / "data")
    ap.add_argument(
        "--ogbench-episodes", type=int, default=None, help="generated episodes (default: official)"
    )
    ap.add_argument(
        "--ogbench-episode-steps", type=int, default=None, help="rows per episode (default: official)"
    )
    ap.add_argument(
        "--planar-frames", type=int, default=None, help="recorded frames (default: the paper's sizes)"
    )
    ap.add_argument(
        "--train-arg", action="append", default=[], help="extra lerobot-train argument (repeatable)"
    )
    ap.add_argument(
        "--eval-arg", action="append", default=[], help="extra lerobot-eval argument (repeatable)"
    )
    return ap


def resolve_budget(args, suite: Suite) -> Budget:
    gpu = args.device == "cuda"
    steps = args.steps or (FULL_STEPS if gpu else CPU_STEPS)
    batch = args.batch_size or (FULL_BATCH if gpu else CPU_BATCH)
    episodes = args.eval_episodes or (suite.full_eval_episodes if gpu else suite.cpu_eval_episodes)
    if steps < 1 or batch < 1 or episodes < 1 or args.jobs < 1 or args.eval_batch_size < 1:
        raise ValueError(
            f"--steps, --batch-size, --eval-episodes, --eval-batch-size and --jobs must be >= 1, got "
            f"{steps}, {batch}, {episodes}, {args.eval_batch_size}, {args.jobs}"
        )
    if not 1 <= args.curve_points <= steps:
        raise ValueError(f"--curve-points must be in 1..--steps ({steps}), got {args.curve_points}")
    if args.config is not None and not (REPO_ROOT / "train_configs" / args.config).is_file():
        raise ValueError(f"--config {args.config!r}: no such file under train_configs/")
    if episodes % suite.num_tasks:
        raise ValueError(
            f"--eval-episodes={episodes} must be a multiple of {suite.num_tasks} for suite {suite.name!r} "
            f"(every evaluation task equally often)"
        )
    ema = args.ema_cutoff
    if ema is None:
        paper_ema = json.loads((REPO_ROOT / "train_configs" / (args.config or suite.config)).read_text())[
            "policy"
        ]["ema_cutoff"]
        ema = None if steps / 10 >= paper_ema else steps / 10
    return Budget(
        device=args.device,
        steps=steps,
        batch_size=batch,
        eval_episodes=episodes,
        eval_batch_size=min(args.eval_batch_size, episodes),
        eval_async=args.eval_async,
        ema_cutoff=ema,
        num_workers=None if gpu else 0,
        train_args=list(args.train_arg),
        eval_args=list(args.eval_arg),
        config=args.config,
        seed=args.seed,
        curve_points=args.curve_points,
    )


def budget_tag(budget: Budget) -> str:
    """Names the run directory and the default report: a config, seed or curve of its own never mixes."""
    tag = f"{budget.device}-s{budget.steps}-b{budget.batch_size}"
    if budget.config:
        tag += "-" + Path(budget.config).stem
    if budget.seed != 1000:
        tag += f"-seed{budget.seed}"
    return tag + (f"-c{budget.curve_points}" if budget.curve_points > 1 else "")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    suite = SUITES[args.suite]
    datasets = parse_list(args.datasets, suite.datasets, f"{suite.name} dataset(s)")
    variants = parse_list(args.variants, tuple(VARIANTS), "variant(s)")
    budget = resolve_budget(args, suite)
    # --jobs trainings share the CPU: one OpenMP pool each of cpus/jobs threads (oversubscribed OpenMP pools
    # spin-wait on each other and can stall for minutes on a loaded machine)
    os.environ.setdefault("OMP_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // args.jobs)))
    out = (
        args.out
        or REPO_ROOT / "benchmarks" / "results" / f"paper_experiments_{suite.name}_{budget_tag(budget)}.md"
    )
    spec = DataSpec(args.ogbench_episodes, args.ogbench_episode_steps, args.planar_frames)
    start = time.perf_counter()

    # The budget and dataset size name the cell directory, so another budget never reuses these results.
    run_root = args.work_dir / suite.name / f"{budget_tag(budget)}{spec.tag(suite.name)}"
    if budget.train_args or budget.eval_args:  # custom CLI arguments: keep apart from the stated budgets
        run_root = run_root.with_name(run_root.name + "-custom")
    imported: dict[str, dict] = {}
    for report in args.import_report:
        imported.update(import_report(report, suite.name, budget, run_root))

    datasets_info, roots = {}, {}
    for d in datasets:
        if args.cached_only:
            root = dataset_root(args.data_root, suite.name, d, spec)
            cmd, wall = dataset_provenance(root)
        else:
            root, cmd, wall = ensure_dataset(suite.name, d, args.data_root, spec)
        roots[d] = root
        datasets_info[d] = {
            "root": shell([str(root)]),
            "repo_id": dataset_repo_id(suite.name, d),
            "command": cmd,
            "generate_s": wall or None,
        }
        if cmd is None and imported.get(d, {}).get("command"):  # generated elsewhere: keep that report's note
            datasets_info[d] = imported[d]
    jobs = [(v, d) for d in datasets for v in variants]
    cells: dict[tuple[str, str], dict] = {}

    def one(vd):
        v, d = vd
        if args.cached_only and not (run_root / d / v / RESULT_FILE).exists():
            return vd, None
        try:
            return vd, run_cell(suite, v, d, roots[d], run_root / d / v, budget)
        except Exception as err:  # noqa: BLE001 - one failed cell must not stop the others
            print(f"[{suite.name}/{d}/{v}] FAILED: {err}", file=sys.stderr, flush=True)
            return vd, {"variant": v, "dataset": d, "error": str(err)[-2500:]}

    with cf.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        for vd, cell in pool.map(one, jobs):
            if cell is not None:
                cells[vd] = cell

    write_report(
        out, suite, variants, datasets, cells, budget, argv, datasets_info, time.perf_counter() - start
    )
    print(f"wrote {out} and {out.with_suffix('.json')}", flush=True)
    print(results_table(suite, variants, datasets, cells), flush=True)
    return 1 if any(c.get("error") for c in cells.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
