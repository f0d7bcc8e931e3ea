#!/usr/bin/env python
"""Learning curves of paper-runner cells: success (%) against training steps and against training minutes.

Reads the JSON reports of ``benchmarks/paper_experiments.py`` runs made with ``--curve-points N`` (each cell
holds ``curve``: one point per evaluated checkpoint) and draws one line per (dataset, agent, seed); cells of
several reports (seeds, configs, ``--train-arg`` overrides such as ``--policy.state_encoder=fourier``) go on the
same axes, one panel per dataset: one colour per agent, one line style per setting (config, overrides,
steps).

    .venv/bin/python benchmarks/plot_learning_curves.py benchmarks/results/planar_push_cpu_*.json \
        --out benchmarks/results/planar_push_cpu_curves.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from config_baselines import LABEL_BASELINES
from recorder_pins import STANDARD_OPTIONS


def number_spelling(value: str) -> str:
    """``'0.0003'`` and ``'3e-4'`` -> ``'3e-4'``, ``'5.0'`` -> ``'5'``: one spelling per number, so that a value set
    by flag and the same value read from a checkpoint label one setting; other text is kept."""
    try:
        number = float(value)
    except ValueError:
        return value
    if number != 0 and abs(number) < 1e-2:
        mantissa, exponent = f"{number:e}".split("e")
        return f"{float(mantissa):g}e{int(exponent)}"
    return f"{number:g}"


def _differs(value, baseline) -> bool:
    """Numbers compare by value (1e-3 == 0.001), other settings by their spelling."""
    if isinstance(baseline, (int, float)):
        return float(value) != baseline
    return str(value) != str(baseline)


def overrides_name(train_args: list[str], policy_config: dict | None = None, config: str = "") -> str:
    """``['--policy.state_encoder=fourier']`` -> ``'state_encoder=fourier'``: what set a run apart, sorted by name;
    plus every value of the cell's resolved ``policy_config`` that departs from the value its config held when
    the older reports were made (``config_baselines``)."""
    named: dict[str, str] = {}
    for arg in train_args:
        name, sep, value = arg.removeprefix("--").removeprefix("policy.").partition("=")
        named[name] = f"{name}={number_spelling(value)}" if sep else name
    for key, baseline in LABEL_BASELINES.get(config, {}).items():
        resolved = (policy_config or {}).get(key)
        if key not in named and resolved is not None and _differs(resolved, baseline):
            named[key] = f"{key}={number_spelling(str(resolved))}"
    return " ".join(named[name] for name in sorted(named))


def recording_name(payload: dict, dataset: str) -> str:
    """``'recorded with corner_episodes=1.0'``: the recorder options beyond the standard ones of the recording a
    cell trained on (from the report's dataset provenance), so that cells of another recording are another
    setting instead of more seeds of this one."""
    command = str((payload.get("datasets") or {}).get(dataset, {}).get("command") or "")
    options = [
        arg.removeprefix("--operator.")
        for arg in command.split()
        if arg.startswith("--operator.") and not arg.startswith("--operator.type=")
    ]
    extra = [o for o in options if o not in STANDARD_OPTIONS]
    return f"recorded with {' '.join(extra)}" if extra else ""


def load_cells(reports: list[Path], require_curve: bool = True) -> list[dict]:
    """Every cell (with a learning curve unless ``require_curve`` is false), tagged with its report's seed and
    setting (config, overrides, budget, recording)."""
    cells = []
    for path in reports:
        payload = json.loads(path.read_text())
        budget = payload.get("budget", {})
        budget_steps = f"{budget['steps'] // 1000}k steps" if budget.get("steps") else ""
        for cell in payload.get("cells", []):
            if cell.get("curve") or not require_curve:
                config = Path(cell.get("config") or payload.get("config", "")).stem
                overrides = overrides_name(budget.get("train_args", []), cell.get("policy_config"), config)
                recording = recording_name(payload, cell.get("dataset", ""))
                setting = " ".join(part for part in (config, overrides, budget_steps, recording) if part)
                cells.append(
                    {
                        **cell,
                        "seed": cell.get("seed", budget.get("seed")),
                        "config_name": config,
                        "setting": setting,
                    }
                )
    if not cells and require_curve:
        raise ValueError(
            f"No cell with a learning curve in {[str(p) for p in reports]}; run the paper runner "
            "with --curve-points N (N > 1)"
        )
    return cells


def select(cells: list[dict], datasets: list[str] | None, variants: list[str] | None) -> list[dict]:
    """The cells of these datasets and runner variants (``ac``, ``pc_rl``, ...; None: all), so that one plot can
    set two configs' runs of a few cells side by side out of reports that hold many."""
    kept = [
        c
        for c in cells
        if (not datasets or c["dataset"] in datasets) and (not variants or c.get("variant") in variants)
    ]
    if not kept:
        raise ValueError(f"No cell of datasets {datasets} and variants {variants} in the reports")
    return kept


def label(cell: dict, several_settings: bool) -> str:
    text = f"{cell['agent']} (seed {cell['seed']})"
    return f"{text} [{cell['setting']}]" if several_settings else text


def plot(cells: list[dict], out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    datasets = sorted({c["dataset"] for c in cells})
    settings = sorted({c["setting"] for c in cells})
    several_settings = len(settings) > 1
    styles = {s: ("-", "--", ":", "-.")[i % 4] for i, s in enumerate(settings)}
    agents = sorted({c["agent"] for c in cells})
    colours = {a: plt.cm.tab10(i % 10) for i, a in enumerate(agents)}
    # Seeds of one agent and setting share colour and line style: the marker tells them apart.
    markers = {s: "os^Dv"[i % 5] for i, s in enumerate(sorted({c["seed"] for c in cells}, key=str))}
    # A panel as wide as its longest legend line (7 pt), so that two legends side by side do not overlap.
    longest = max(len(label(c, several_settings)) for c in cells)
    width = max(5.2, 0.06 * longest + 0.8)
    fig, axes = plt.subplots(2, len(datasets), figsize=(width * len(datasets), 7.5), squeeze=False)
    for col, dataset in enumerate(datasets):
        for cell in sorted(
            (c for c in cells if c["dataset"] == dataset), key=lambda c: (c["agent"], c["setting"], c["seed"])
        ):
            name = label(cell, several_settings)
            style, colour, marker = styles[cell["setting"]], colours[cell["agent"]], markers[cell["seed"]]
            success = [p["pc_success"] for p in cell["curve"]]
            axes[0, col].plot(
                [p["step"] for p in cell["curve"]], success, style, marker=marker, color=colour, label=name
            )
            minutes = [p["train_min"] for p in cell["curve"]]
            if all(m is not None for m in minutes):
                axes[1, col].plot(minutes, success, style, marker=marker, color=colour, label=name)
        axes[0, col].set_title(f"{title}: {dataset}")
        axes[0, col].set_xlabel("training steps")
        axes[1, col].set_xlabel("training minutes (one CPU core)")
        for row in range(2):
            axes[row, col].set_ylabel("success (%)")
            axes[row, col].set_ylim(-3, 103)
            axes[row, col].grid(alpha=0.3)
        # Below the panels: long setting names would hide the curves.
        axes[1, col].legend(
            *axes[0, col].get_legend_handles_labels(),
            fontsize=7,
            loc="upper center",
            bbox_to_anchor=(0.5, -0.15),
        )
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reports", nargs="+", type=Path, help="JSON reports of benchmarks/paper_experiments.py")
    ap.add_argument("--out", type=Path, required=True, help="PNG file")
    ap.add_argument("--title", default="planar push")
    ap.add_argument("--datasets", nargs="*", default=None, help="keep only these datasets")
    ap.add_argument(
        "--variants", nargs="*", default=None, help="keep only these runner variants (ac, pc_rl, ...)"
    )
    args = ap.parse_args(argv)
    plot(select(load_cells(args.reports), args.datasets, args.variants), args.out, args.title)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
