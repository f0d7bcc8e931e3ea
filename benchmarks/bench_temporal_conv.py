#!/usr/bin/env python
"""CPU training speed of the UNet actor's convolutions: PyTorch's ``conv1d`` against the GEMM path of
``TemporalConv1d`` (one matrix product over the stacked shifted windows, the default for CPU training).

Two measurements, both at ``--threads`` threads:

(a) every convolution shape of the Talos UNet (down dims 32/64/128, kernel 3, trajectory 16 -> 2 steps),
    forward + backward, ``--batch`` rows;
(b) a whole ``lerobot-train`` update (bench_agents' ``measure_training``: forward, backward, clip, AdamW,
    scheduler, EMA; data loading excluded) of the shipped Talos train configs (``--configs``), each path
    timed in alternation so both see the same machine load. The image config's auxiliary object-state head
    is left out (it needs the recording's min/max); it adds one small MLP to the update.

Run:  .venv/bin/python benchmarks/bench_temporal_conv.py --out benchmarks/results/bench_temporal_conv
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402
from lerobot.configs.policies import PreTrainedConfig  # noqa: E402
from lerobot.configs.types import FeatureType, PolicyFeature  # noqa: E402
from lerobot.policies.factory import get_policy_class  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from bench_agents import machine_info, make_training_batch, measure_training  # noqa: E402

from lerobot_efm.networks import TemporalConv1d  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
# (in, out, length) of the Talos UNet's kernel-3 convolutions (down 32/64/128 over 16 steps, up with skips)
UNET_SHAPES = [(10, 32, 16), (32, 32, 16), (32, 64, 8), (64, 64, 8), (64, 128, 4), (128, 128, 4),
               (128, 128, 2), (256, 128, 4), (192, 64, 8), (96, 32, 16)]  # fmt: skip
NOT_CONFIG_FIELDS = ("type", "input_features")


def time_layer(cin: int, cout: int, length: int, batch: int, gemm: bool, calls: int) -> float:
    """ms per forward + backward of one kernel-3 convolution."""
    conv = TemporalConv1d(cin, cout, 3, padding=1)
    x = torch.randn(batch, cin, length, requires_grad=True)
    run = (lambda: conv(x)) if gemm else (lambda: F.conv1d(x, conv.weight, conv.bias, padding=1))
    for _ in range(5):
        run().sum().backward()
    start = time.perf_counter()
    for _ in range(calls):
        run().sum().backward()
    return (time.perf_counter() - start) / calls * 1e3


def policy_from_train_config(path: Path):
    """The policy a ``lerobot-train --config_path`` run builds (features from the config, action 10-D)."""
    raw = json.loads(path.read_text())
    spec = raw["policy"]
    features = {
        k: PolicyFeature(FeatureType[v["type"]], tuple(v["shape"])) for k, v in spec["input_features"].items()
    }
    fields = {k: v for k, v in spec.items() if k not in NOT_CONFIG_FIELDS}
    fields["device"] = "cpu"
    if fields.get("auxiliary_state_key"):  # needs the recorded state's min/max; off for a speed measurement
        fields["auxiliary_state_key"] = None
    cfg = PreTrainedConfig.get_choice_class(spec["type"])(
        input_features=features,
        output_features={"action": PolicyFeature(FeatureType.ACTION, (10,))},
        **fields,
    )
    return get_policy_class(spec["type"])(cfg), cfg, raw["batch_size"]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--batch", type=int, default=64, help="rows of the per-layer timing (a)")
    p.add_argument("--layer-calls", type=int, default=100)
    p.add_argument(
        "--configs",
        nargs="+",
        default=[
            "train_configs/talos_kitchen_efm_ac_state.json",
            "train_configs/talos_kitchen_efm_ac_image_cpu.json",
        ],
    )
    p.add_argument("--train-steps", type=int, default=20, help="update steps per timed repeat")
    p.add_argument("--rounds", type=int, default=3, help="alternating (conv, GEMM) rounds per config")
    p.add_argument("--out", type=Path, default=None, help="writes OUT.md and OUT.json")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)

    layers = []
    for cin, cout, length in UNET_SHAPES:
        conv_ms = time_layer(cin, cout, length, args.batch, False, args.layer_calls)
        gemm_ms = time_layer(cin, cout, length, args.batch, True, args.layer_calls)
        layers.append({"in": cin, "out": cout, "length": length, "conv_ms": conv_ms, "gemm_ms": gemm_ms})
        print(
            f"layer {cin:>3}->{cout:<3} x{length:<2}: conv {conv_ms:.3f} ms, GEMM {gemm_ms:.3f} ms",
            flush=True,
        )

    updates = []
    for config in args.configs:
        policy, cfg, batch_size = policy_from_train_config(ROOT / config)
        batch = make_training_batch(cfg, batch_size)
        rates = {"conv": [], "gemm": []}
        for _ in range(args.rounds):
            for path in ("conv", "gemm"):
                TemporalConv1d.GEMM_FOR_CPU_TRAINING = path == "gemm"
                rates[path].append(
                    measure_training(policy, cfg, batch, args.threads, args.train_steps, repeats=1)[
                        "steps_per_s"
                    ]
                )
        TemporalConv1d.GEMM_FOR_CPU_TRAINING = True
        row = {"config": config, "batch": batch_size, **{f"{k}_steps_per_s": v for k, v in rates.items()}}
        row["speedup"] = statistics.median(rates["gemm"]) / statistics.median(rates["conv"])
        updates.append(row)
        print(
            f"{config}: conv {statistics.median(rates['conv']):.2f}, GEMM {statistics.median(rates['gemm']):.2f} "
            f"steps/s ({row['speedup']:.2f}x)",
            flush=True,
        )

    if args.out:
        write_report(args, layers, updates)


def write_report(args, layers: list[dict], updates: list[dict]) -> None:
    info = machine_info(args.threads)
    conv_total, gemm_total = sum(r["conv_ms"] for r in layers), sum(r["gemm_ms"] for r in layers)
    lines = [
        "# TemporalConv1d on the CPU: conv1d against one GEMM over the shifted windows",
        "",
        f"`{' '.join(['python', *sys.argv])}`",
        "",
        f"{info['cpu_model']}, {args.threads} thread(s), torch {info['torch']}, load average "
        f"{os.getloadavg()[0]:.2f} at the end.",
        "",
        f"**(a) Talos UNet layers**, forward + backward, batch {args.batch} (ms):",
        "",
        "| in -> out channels | steps | conv1d | GEMM |",
        "|---|---:|---:|---:|",
        *[
            f"| {r['in']} -> {r['out']} | {r['length']} | {r['conv_ms']:.3f} | {r['gemm_ms']:.3f} |"
            for r in layers
        ],
        f"| **sum** | | **{conv_total:.2f}** | **{gemm_total:.2f}** ({conv_total / gemm_total:.2f}x) |",
        "",
        f"**(b) whole update steps** (steps/s, median of {args.rounds} alternating rounds of {args.train_steps}):",
        "",
        "| train config | batch | conv1d | GEMM | speed-up |",
        "|---|---:|---:|---:|---:|",
        *[
            f"| `{r['config']}` | {r['batch']} | {statistics.median(r['conv_steps_per_s']):.2f} | "
            f"{statistics.median(r['gemm_steps_per_s']):.2f} | {r['speedup']:.2f}x |"
            for r in updates
        ],
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".md").write_text("\n".join(lines))
    payload = {"machine": info, "layers": layers, "updates": updates}
    args.out.with_suffix(".json").write_text(json.dumps(payload, indent=2))
    print(f"wrote {args.out.with_suffix('.md')}")


if __name__ == "__main__":
    main()
