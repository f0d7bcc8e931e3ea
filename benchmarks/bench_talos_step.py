"""Talos kitchen: speed of one control step (Cartesian IK + physics substeps) + one 128x128 render.

Single process, no torch. Prints a markdown table; ``--out`` also writes it to a file, e.g.
``MUJOCO_GL=egl .venv/bin/python benchmarks/bench_talos_step.py --out benchmarks/results/talos_step_cpu.md``.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from lerobot_efm.envs.talos_kitchen import control, scene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--image-size", type=int, default=128)
    ap.add_argument("--substeps", type=int, default=20)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()

    t0 = time.perf_counter()
    model, data, h = scene.build_kitchen(args.image_size)
    build_s = time.perf_counter() - t0
    ctrl = control.CartesianController(model, h, n_substeps=args.substeps)
    rend = scene.KitchenRenderer(model, args.image_size)
    start = control.hand_pose10(data, h)

    def command(i):  # a slow circle in front of the robot, gripper opening/closing
        c = start.copy()
        c[0] += 0.05 * np.sin(0.1 * i)
        c[1] += 0.08 * np.sin(0.05 * i)
        c[2] += 0.05 * np.cos(0.1 * i)
        c[9] = 0.5 + 0.5 * np.sin(0.07 * i)
        return c

    rows = {"control step (IK + physics)": [], "render 128x128": [], "control step + render": []}
    for _ in range(args.repeats):
        scene.reset_kitchen(model, data, h)
        ctrl.reset(data)
        for i in range(3):  # warm-up
            ctrl.step(data, command(i))
            rend.render(data)
        t_ctrl = t_rend = 0.0
        for i in range(args.steps):
            t = time.perf_counter()
            ctrl.step(data, command(i))
            t_ctrl += time.perf_counter() - t
            t = time.perf_counter()
            rend.render(data)
            t_rend += time.perf_counter() - t
        n = args.steps
        rows["control step (IK + physics)"].append(n / t_ctrl)
        rows["render 128x128"].append(n / t_rend)
        rows["control step + render"].append(n / (t_ctrl + t_rend))
    rend.close()

    dt = ctrl.control_dt
    lines = [
        "# Talos kitchen: control-step speed on CPU",
        "",
        f"`benchmarks/bench_talos_step.py --steps {args.steps} --repeats {args.repeats}`; one process, "
        f"MuJoCo {mujoco.__version__}, MUJOCO_GL={os.environ.get('MUJOCO_GL')}, Python {platform.python_version()}, "
        f"{os.cpu_count()} logical CPUs, load average at end {', '.join(f'{x:.2f}' for x in os.getloadavg())}.",
        f"Model build (cold, incl. URDF parse + compile): {build_s:.2f} s. Control period {dt * 1000:.0f} ms "
        f"({args.substeps} x {model.opt.timestep * 1000:.0f} ms physics substeps), IK <= {ctrl.ik_iters} "
        "DLS iterations per step; render = `front` camera, no shadows/MSAA.",
        "",
        "| part | median per second | min | max | x real time |",
        "|---|---|---|---|---|",
    ]
    for name, v in rows.items():
        med = float(np.median(v))
        rt = f"{med * dt:.2f}" if "step" in name else "–"
        lines.append(f"| {name} | {med:.1f} | {min(v):.1f} | {max(v):.1f} | {rt} |")
    lines += ["", "Target: >= 25 control steps + renders per second."]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)


if __name__ == "__main__":
    main()
