#!/usr/bin/env python
"""CPU benchmark of the five EFM agents (training steps/s and single-observation inference latency),
compared with the measured speed of the authors' reference implementation on a 2-core CPU
(../shared/docs/reference-implementation.md, last section).

Two configurations, with the policies' DEFAULT network sizes (the reference's architecture):

* ``state``: the paper's planar push (4-D state, 2-D absolute action, L_o/S_o 3/10, L_a/S_a 8/1, L_g 600).
* ``image``: the paper's Talos kitchen (one 128x128 RGB camera + 20-D proprio, 10-D action,
  L_o/S_o 3/15, L_a/S_a 16/3, L_g 1000, IMPALA latent 64).

(a) Training steps/s: one step is exactly what ``lerobot-train`` does per batch (``update_policy``):
    ``policy.forward(batch)``, ``backward``, ``clip_grad_norm_(policy.parameters(), 1.0)``, the policy's own
    AdamW preset step, ``zero_grad``, the policy's LR-scheduler step and ``policy.update()`` (EMA).
    Data loading is EXCLUDED: the batch is built once, synthetically, with exactly the keys the
    hindsight wrapper produces (the reference's numbers include data sampling, ~1% of its step).
    3 warm-up steps, then the median over ``--repeats`` timings of ``--train-steps`` steps.
(b) Inference latency: ``policy.eval()``, batch size 1, ``policy.predict_action_chunk(obs)`` (EMA weights,
    ``num_inference_steps`` Euler steps, 64 candidates for FM-PS/AS), 2 warm-up calls, then the median of
    ``--latency-calls`` calls, at ``--threads`` threads and at 1 thread. Pre/post-processing (normalisation)
    is not included, as in the reference's number.

Run:  .venv/bin/python benchmarks/bench_agents.py            (or ``make bench``)
Output: a markdown report (``--out``) and a JSON file with every raw timing next to it.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import statistics
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import torch  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[1]
if str(REPO_ROOT) not in sys.path:
    sys.path.insert(0, str(REPO_ROOT))

from lerobot.configs.policies import PreTrainedConfig  # noqa: E402
from lerobot.configs.types import FeatureType, PolicyFeature  # noqa: E402
from lerobot.policies.factory import get_policy_class  # noqa: E402

import lerobot_efm  # noqa: E402,F401  (registers the efm_* policy types)
from lerobot_efm.configuration_efm import (  # noqa: E402
    GOAL_DISTANCE_KEY,
    GOAL_PREFIX,
    OBS_PREFIX,
    RL_GOAL_PREFIX,
    TRAJ_PREFIX,
    mirror_key,
)
from lerobot_efm.modeling_efm import AGENT_NAMES  # noqa: E402

AGENT_TYPES = ["efm_gc", "efm_ac", "efm_pc", "efm_ps", "efm_as"]
REFERENCE_DOC = "../shared/docs/reference-implementation.md"
CONTENDED = " †"
CONTENTION_THRESHOLD = 0.8

# --------------------------------------------------------------------------------------------------
# Benchmark configurations
# --------------------------------------------------------------------------------------------------

CONFIGS = {
    "state": {
        "title": "state: planar push (4-D state, 2-D action, L_o/S_o 3/10, L_a/S_a 8/1, L_g 600)",
        "input_features": {"observation.state": PolicyFeature(FeatureType.STATE, (4,))},
        "action_dim": 2,
        "overrides": dict(
            obs_traj_len=3, obs_traj_stride=10, action_traj_len=8, action_traj_stride=1, max_goal_distance=600
        ),
        # The reference measured planar latency with 1 thread.
        "ref_latency_threads": 1,
    },
    "image": {
        "title": "image: Talos kitchen (128x128 RGB camera + 20-D state, 10-D action, L_o/S_o 3/15, L_a/S_a 16/3, L_g 1000)",
        "input_features": {
            "observation.images.front": PolicyFeature(FeatureType.VISUAL, (3, 128, 128)),
            "observation.state": PolicyFeature(FeatureType.STATE, (20,)),
        },
        "action_dim": 10,
        "overrides": dict(
            obs_traj_len=3,
            obs_traj_stride=15,
            action_traj_len=16,
            action_traj_stride=3,
            max_goal_distance=1000,
            image_latent_dim=64,
        ),
        # The Talos latency was presumably measured with the 2 threads of the same machine.
        "ref_latency_threads": 2,
    },
}

# Reference numbers (reference-implementation.md, "Measured speed of the reference implementation on a
# 2-core CPU", torch 2.11, 2 threads). Keys: (policy type, use_rl).
REFERENCE = {
    "state": {
        "params_m": {
            ("efm_gc", False): 3.42,
            ("efm_ac", False): 7.65,
            ("efm_pc", False): 9.82,
            ("efm_ps", False): 9.81,
            ("efm_as", False): 9.78,
        },
        "steps_per_s": {
            ("efm_gc", False): 5.3,
            ("efm_ac", False): 3.6,
            ("efm_ac", True): 1.4,
            ("efm_pc", False): 3.6,
            ("efm_pc", True): 1.6,
            ("efm_ps", False): 3.7,
            ("efm_ps", True): 1.4,
            ("efm_as", False): 3.4,
            ("efm_as", True): 1.6,
        },
        "latency_ms": {
            ("efm_gc", False): 136.0,
            ("efm_ac", False): 180.0,
            ("efm_ac", True): 194.0,
            ("efm_pc", False): 162.0,
            ("efm_ps", False): 448.0,
            ("efm_as", False): 810.0,
        },
    },
    "image": {
        # [CALC] parameter count of the reference's Talos FM-AC (IMPALA 4.30 + 2 x critic 2.28 + actor 4.02).
        "params_m": {("efm_ac", False): 12.9},
        "steps_per_s": {},
        "latency_ms": {("efm_ac", False): 198.0},
    },
}

# --------------------------------------------------------------------------------------------------
# Policy and synthetic batches
# --------------------------------------------------------------------------------------------------


def variant_name(policy_type: str, use_rl: bool) -> str:
    name = AGENT_NAMES[policy_type.removeprefix("efm_")]
    if policy_type == "efm_gc":
        return name
    return f"{name} {'use-RL' if use_rl else 'no-RL'}"


def parse_overrides(items: list[str]) -> dict:
    """``NAME=VALUE`` config overrides; VALUE is read as JSON (numbers, null, lists), else kept as a string."""
    overrides = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise SystemExit(f"--set {item!r}: expected NAME=VALUE")
        try:
            overrides[name] = json.loads(value)
        except json.JSONDecodeError:
            overrides[name] = value
    return overrides


def build_policy(
    config_name: str, policy_type: str, use_rl: bool, num_inference_steps: int, overrides: dict | None = None
):
    spec = CONFIGS[config_name]
    cfg = PreTrainedConfig.get_choice_class(policy_type)(
        device="cpu",
        use_rl=use_rl,
        num_inference_steps=num_inference_steps,
        input_features=dict(spec["input_features"]),
        output_features={"action": PolicyFeature(FeatureType.ACTION, (spec["action_dim"],))},
        **{**spec["overrides"], **(overrides or {})},
    )
    policy = get_policy_class(policy_type)(cfg)  # default network sizes
    return policy, policy.config


def _random_like(ft: PolicyFeature, lead: tuple[int, ...], gen: torch.Generator) -> torch.Tensor:
    shape = lead + tuple(ft.shape)
    if ft.type is FeatureType.VISUAL:
        return torch.rand(shape, generator=gen)  # float images in [0, 1] (LeRobot's convention)
    return torch.rand(shape, generator=gen) * 2 - 1  # MIN_MAX-normalised vectors in [-1, 1]


def make_training_batch(cfg, batch_size: int, seed: int = 0) -> dict[str, torch.Tensor]:
    """Exactly the keys HindsightGoalDataset + the pre-processor give the policy's forward."""
    gen = torch.Generator().manual_seed(seed)
    batch: dict[str, torch.Tensor] = {}
    for key, ft in cfg.observation_features.items():
        obs = _random_like(ft, (batch_size,), gen)
        batch[key] = obs
        for prefix in cfg.mirror_prefixes:
            name = mirror_key(key, prefix)
            if prefix == TRAJ_PREFIX:
                traj = _random_like(ft, (batch_size, cfg.obs_traj_len), gen)
                traj[:, 0] = obs  # tau^o starts at the current observation
                batch[name] = traj
            else:
                batch[name] = _random_like(ft, (batch_size,), gen)
    batch[GOAL_DISTANCE_KEY] = torch.randint(0, cfg.max_goal_distance, (batch_size,), generator=gen).float()
    action_dim = cfg.output_features["action"].shape[0]
    batch["action"] = torch.rand((batch_size, cfg.action_traj_len, action_dim), generator=gen) * 2 - 1
    return batch


def make_inference_obs(cfg, seed: int = 1) -> dict[str, torch.Tensor]:
    gen = torch.Generator().manual_seed(seed)
    obs = {}
    for key, ft in cfg.observation_features.items():
        obs[key] = _random_like(ft, (1,), gen)
        obs[mirror_key(key, GOAL_PREFIX)] = _random_like(ft, (1,), gen)
    return obs


def count_params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def check_batch_keys(cfg, batch: dict) -> None:
    expected = {"action", GOAL_DISTANCE_KEY}
    for key in cfg.observation_features:
        expected.add(key)
        expected.update(mirror_key(key, p) for p in cfg.mirror_prefixes)
    assert set(batch) == expected, (sorted(batch), sorted(expected))
    assert all(k.startswith(OBS_PREFIX) or k == "action" for k in batch)
    assert (RL_GOAL_PREFIX in cfg.mirror_prefixes) == cfg.use_rl


# --------------------------------------------------------------------------------------------------
# Measurements
# --------------------------------------------------------------------------------------------------


def measure_training(
    policy, cfg, batch, threads: int, train_steps: int, repeats: int, warmup: int = 3
) -> dict:
    """steps/s of lerobot-train's update_policy step (data loading excluded)."""
    torch.set_num_threads(threads)
    optimizer = cfg.get_optimizer_preset().build(policy.get_optim_params())
    scheduler = cfg.get_scheduler_preset().build(optimizer, cfg.scheduler_decay_steps)
    clip = cfg.get_optimizer_preset().grad_clip_norm  # 1.0
    policy.train()

    def step():
        loss, info = policy.forward(batch)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(policy.parameters(), clip)
        optimizer.step()
        optimizer.zero_grad()
        scheduler.step()
        policy.update()
        return loss.item(), info

    for _ in range(warmup):
        loss, info = step()
    timings, cpu = [], []
    for _ in range(repeats):
        cpu_start, start = time.process_time(), time.perf_counter()
        for _ in range(train_steps):
            loss, info = step()
        timings.append(time.perf_counter() - start)
        cpu.append(time.process_time() - cpu_start)
    rates = [train_steps / t for t in timings]
    return {
        "steps_per_s": statistics.median(rates),
        "steps_per_s_all": rates,
        "seconds_per_repeat": timings,
        "cpu_utilisation": sum(cpu) / (sum(timings) * threads),
        "load_average": os.getloadavg()[0],
        "rows_per_step": info.get("rows"),
        "final_loss": loss,
    }


def measure_latency(policy, obs, threads: int, calls: int, warmup: int = 2) -> dict:
    torch.set_num_threads(threads)
    policy.eval()
    for _ in range(warmup):
        chunk = policy.predict_action_chunk(obs)
    times = []
    cpu_start = time.process_time()
    for _ in range(calls):
        start = time.perf_counter()
        chunk = policy.predict_action_chunk(obs)
        times.append((time.perf_counter() - start) * 1e3)
    cpu = time.process_time() - cpu_start
    assert torch.isfinite(chunk).all()
    return {
        "ms": statistics.median(times),
        "ms_all": times,
        "cpu_utilisation": cpu * 1e3 / (sum(times) * threads),
        "load_average": os.getloadavg()[0],
        "chunk_shape": list(chunk.shape),
    }


# --------------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------------


def machine_info(threads: int) -> dict:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        lerobot_version = __import__("importlib.metadata").metadata.version("lerobot")
    except Exception:  # noqa: BLE001
        lerobot_version = "unknown"
    return {
        "cpu_model": cpu,
        "logical_cpus": os.cpu_count(),
        "affinity_cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "torch": torch.__version__,
        "lerobot": lerobot_version,
        "python": platform.python_version(),
        "threads": threads,
        "interop_threads": torch.get_num_interop_threads(),
        "mkldnn": torch.backends.mkldnn.is_available(),
        "load_average_at_start": os.getloadavg() if hasattr(os, "getloadavg") else None,
    }


def _fmt(x, spec=".2f", missing="–"):
    return missing if x is None else format(x, spec)


def render_markdown(results: dict) -> str:
    args, machine = results["args"], results["machine"]
    t1, t2 = 1, args["threads"]
    lines = [
        "# EFM agents: CPU speed vs. the reference implementation",
        "",
        f"Generated {results['date']} by `{results['command']}` in {results['total_seconds']:.0f} s.",
        "",
        f"Machine: {machine['cpu_model']}, {machine['logical_cpus']} logical CPUs, torch {machine['torch']}, "
        f"lerobot {machine['lerobot']}, Python {machine['python']}; training at {t2} threads "
        f"(`torch.set_num_threads`), load average at start {_fmt_load(machine['load_average_at_start'])}.",
        "",
        *([f"Config overrides for every variant: `{' '.join(args['set'])}`.", ""] if args.get("set") else []),
        "* **train steps/s**: one step = `policy.forward(batch)` + `backward` + `clip_grad_norm_(…, 1.0)` + AdamW step "
        "(the policy's preset) + `zero_grad` + LR-scheduler step + `policy.update()` (EMA), i.e. lerobot-train's "
        "`update_policy`; **data loading excluded** (the reference's numbers include its data sampling, ~1% of a step). "
        "Median of `repeats` x `train-steps` steps after 3 warm-up steps, on one fixed synthetic batch "
        "with the hindsight wrapper's keys (vectors U[-1,1], images U[0,1]).",
        "* **latency**: `policy.eval()`, batch 1, `policy.predict_action_chunk(obs)` (EMA weights, "
        f"{args['num_inference_steps']} Euler steps per flow, 64 candidates for FM-PS/AS), median of "
        f"{args['latency_calls']} calls after 2 warm-ups; normalisation processors not included.",
        "* **params**: trainable parameters of `policy.model` (the EMA copy, same size, excluded).",
        "* **speed-up** = ours / reference steps/s (target >= 2). **ratio** = our latency at the reference's thread "
        "count / reference latency (target <= 0.33). Reference: `hucebot/extremum_flow_matching_code` measured on a "
        f"2-core CPU, torch 2.11 ({REFERENCE_DOC}).",
        "",
    ]
    for config_name, cres in results["configs"].items():
        spec = CONFIGS[config_name]
        ref_t = spec["ref_latency_threads"]
        lines += [f"## {spec['title']}", ""]
        lines.append(
            f"Training: median of {cres['repeats']} x {cres['train_steps']} steps, batch {cres['batch_size']}"
            + (
                " (REDUCED from 128 with --image-batch: steps/s are not comparable with a batch-128 run)"
                if cres["batch_size"] != 128
                else ""
            )
            + f"; reference latency measured at {ref_t} thread(s)."
        )
        lines.append("")
        lines.append(
            f"| agent | params (M) | ref params (M) | train steps/s | reference steps/s | speed-up | "
            f"latency ms ({t2} threads) | latency ms ({t1} thread) | reference latency ms | ratio |"
        )
        lines.append("|---|---|---|---|---|---|---|---|---|---|")
        for v in cres["variants"]:
            key = (v["type"], v["use_rl"])
            ref = REFERENCE[config_name]
            ref_sps = ref["steps_per_s"].get(key)
            ref_lat = ref["latency_ms"].get(key)
            ref_params = ref["params_m"].get(key)
            train = v.get("train", {})
            sps = train.get("steps_per_s")
            lat = {int(k): d["ms"] for k, d in v.get("latency", {}).items()}
            util = {int(k): d["cpu_utilisation"] for k, d in v.get("latency", {}).items()}
            speedup = sps / ref_sps if (sps is not None and ref_sps) else None
            ratio = lat[ref_t] / ref_lat if (ref_lat and ref_t in lat) else None
            mark = lambda u: CONTENDED if (u is not None and u < CONTENTION_THRESHOLD) else ""  # noqa: E731
            lines.append(
                f"| {v['name']} | {v['params'] / 1e6:.2f} | {_fmt(ref_params)} | {_fmt(sps)}{mark(train.get('cpu_utilisation'))} | "
                f"{_fmt(ref_sps, '.1f')} | {_fmt(speedup, '.2f')}{'x' if speedup else ''} | "
                f"{_fmt(lat.get(t2), '.1f')}{mark(util.get(t2))} | {_fmt(lat.get(t1), '.1f')}{mark(util.get(t1))} | "
                f"{_fmt(ref_lat, '.0f')} | {_fmt(ratio, '.2f')} |"
            )
        rows = [f"{v['name']}: {v['train']['rows_per_step']:.0f}" for v in cres["variants"] if v.get("train")]
        if rows:
            lines += [
                "",
                "Rows per training step (batch + 32 reached rows, + batch bootstrap rows with use-RL): "
                + ", ".join(rows)
                + ".",
            ]
        lines.append("")
    lines += [
        f"{CONTENDED} = the process got less than {CONTENTION_THRESHOLD:.0%} of the requested threads' CPU time during "
        "that measurement (process CPU time / (wall time x threads)): other processes were competing for the cores, "
        "so the number is pessimistic. Load average at start: "
        + _fmt_load(machine["load_average_at_start"])
        + ".",
        "",
        "Raw timings (every repeat and call) are in the JSON file next to this report.",
        "",
    ]
    return "\n".join(lines)


def _fmt_load(load):
    return "n/a" if not load else ", ".join(f"{x:.2f}" for x in load)


# --------------------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------------------


def parse_args(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    p.add_argument(
        "--threads", type=int, default=2, help="torch threads for training and the main latency column"
    )
    p.add_argument(
        "--repeats", type=int, default=3, help="timed repeats of --train-steps steps (median reported)"
    )
    p.add_argument("--train-steps", type=int, default=30, help="training steps per timed repeat")
    p.add_argument(
        "--latency-calls", type=int, default=10, help="timed predict_action_chunk calls (median reported)"
    )
    p.add_argument(
        "--agents", nargs="+", default=AGENT_TYPES, choices=AGENT_TYPES, help="policy types to benchmark"
    )
    p.add_argument(
        "--rl", choices=["both", "no", "use"], default="both", help="use_rl variants of efm_ac/pc/ps/as"
    )
    p.add_argument("--configs", nargs="+", default=["state", "image"], choices=list(CONFIGS))
    p.add_argument("--batch", type=int, default=128, help="training batch size of the state config")
    p.add_argument(
        "--image-batch",
        type=int,
        default=128,
        help="training batch size of the image config (reduce if too slow)",
    )
    p.add_argument(
        "--image-train-steps",
        type=int,
        default=None,
        help="--train-steps of the image config (default: --train-steps)",
    )
    p.add_argument(
        "--num-inference-steps",
        type=int,
        default=20,
        help="Euler steps per flow at inference (reference: 20)",
    )
    p.add_argument("--skip-train", action="store_true", help="latency only")
    p.add_argument("--skip-latency", action="store_true", help="training only")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("benchmarks/results/agents_cpu.md"),
        help="markdown report; the JSON goes next to it",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="config field for every variant (repeatable), e.g. rl_target_solver=heun",
    )
    return p.parse_args(argv)


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def main(argv=None) -> dict:
    args = parse_args(argv)
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    started = time.perf_counter()
    variants = []
    for t in args.agents:
        if t == "efm_gc":
            variants.append((t, False))
            continue
        if args.rl in ("both", "no"):
            variants.append((t, False))
        if args.rl in ("both", "use"):
            variants.append((t, True))
    latency_threads = sorted({args.threads, 1}, reverse=True)
    overrides = parse_overrides(args.set)

    results = {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": " ".join(
            [".venv/bin/python", "benchmarks/bench_agents.py", *(sys.argv[1:] if argv is None else argv)]
        ),
        "args": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "machine": machine_info(args.threads),
        "configs": {},
    }
    for config_name in args.configs:
        batch_size = args.image_batch if config_name == "image" else args.batch
        train_steps = (
            args.image_train_steps
            if (config_name == "image" and args.image_train_steps)
            else args.train_steps
        )
        cres = {"batch_size": batch_size, "train_steps": train_steps, "repeats": args.repeats, "variants": []}
        results["configs"][config_name] = cres
        for policy_type, use_rl in variants:
            name = variant_name(policy_type, use_rl)
            torch.manual_seed(args.seed)
            policy, cfg = build_policy(config_name, policy_type, use_rl, args.num_inference_steps, overrides)
            v = {
                "name": name,
                "type": policy_type,
                "use_rl": use_rl,
                "params": count_params(policy.model),
                "params_by_component": {n: count_params(m) for n, m in policy.model.named_children()},
                "config_overrides": {name: getattr(cfg, name) for name in overrides},
            }
            log(f"{config_name} / {name}: {v['params'] / 1e6:.2f} M params")
            if not args.skip_train:
                batch = make_training_batch(cfg, batch_size, args.seed)
                check_batch_keys(cfg, batch)
                v["train"] = measure_training(policy, cfg, batch, args.threads, train_steps, args.repeats)
                log(
                    f"  train: {v['train']['steps_per_s']:.2f} steps/s  (repeats {[round(r, 2) for r in v['train']['steps_per_s_all']]})"
                )
                del batch
            if not args.skip_latency:
                obs = make_inference_obs(cfg, args.seed + 1)
                v["latency"] = {}
                for threads in latency_threads:
                    v["latency"][str(threads)] = measure_latency(policy, obs, threads, args.latency_calls)
                    log(f"  latency @{threads} thread(s): {v['latency'][str(threads)]['ms']:.1f} ms")
                torch.set_num_threads(args.threads)
            cres["variants"].append(v)
            del policy
            gc.collect()
    results["total_seconds"] = time.perf_counter() - started

    out = args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    md = render_markdown(results)
    out.write_text(md)
    out.with_suffix(".json").write_text(json.dumps(results, indent=2))
    print(md)
    log(f"wrote {out} and {out.with_suffix('.json')} ({results['total_seconds']:.0f} s)")
    return results


if __name__ == "__main__":
    main()
