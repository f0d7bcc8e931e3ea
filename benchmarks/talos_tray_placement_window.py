"""Where on the pulled-out tray a scripted pot placement comes to rest on the tray floor.

From ``pot_to_tray``'s initial state the scripted arm pulls the tray to its joint stop, then
``primitives.pot_pick_place`` carries the pot (lifted as the play operator does) to tray-frame x offsets
along the tray and sets it down. Per offset: where the pot rests, in the tray frame, and how high above the
tray floor. A pot resting more than 2 cm high sits on the front wall's rim, or was knocked off by the closed
door above the tray's back half; the offsets whose pot rests on the floor are the window a goal placement
(``tasks.POT_TRAY_XY``) and the operator's jitter around it must stay inside.

    MUJOCO_GL=egl python benchmarks/talos_tray_placement_window.py \\
        --out benchmarks/results/talos_tray_placement_window
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

from lerobot_efm.envs.talos_kitchen import play, primitives, scene, tasks  # noqa: E402
from lerobot_efm.envs.talos_kitchen.env import TalosKitchenEnv  # noqa: E402

ON_FLOOR_DZ = 0.02  # m above the settled height: higher, the pot rests on a rim


def place_at(env: TalosKitchenEnv, dx: float, dy: float = 0.0) -> dict:
    """Pull the tray out, put the pot at tray-frame (``dx``, ``dy``), go home, settle; where does it rest?"""
    obs, _ = env.reset(seed=0, options={"task": "pot_to_tray"})
    d, h = env.data, env.h
    last = obs["agent_pos"][:10].astype(float)
    for c in primitives.tray_move(d, h, last, tasks.TRAY_STOP):
        env.advance(c)
        last = np.asarray(c, float)
    pulled = scene.tray_slide(d, h)
    x0, y0, _ = scene.TRAY_POS0
    for c in primitives.pot_pick_place(d, h, last, (x0 + pulled + dx, y0 + dy), place_z=play.TRAY_TOP_Z):
        env.advance(c)
        last = np.asarray(c, float)
    home = primitives.home_command()
    for c in primitives.move(last, home):
        env.advance(c)
    for _ in range(25):
        env.advance(home)
    pos, _ = scene.pot_pose(d, h)
    slide = scene.tray_slide(d, h)
    rest = pos - np.array([x0 + slide, y0, play.TRAY_TOP_Z])
    dz = float(rest[2])
    return {
        "dx": dx,
        "tray_pulled_to": round(pulled, 3),
        "tray_at_end": round(slide, 3),
        "rest_x": round(float(rest[0]), 3),
        "rest_y": round(float(rest[1]), 3),
        "rest_dz": round(dz, 3),
        "on_floor": bool(abs(dz) < ON_FLOOR_DZ),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--offsets", type=float, nargs="+", default=[round(-0.08 + 0.01 * i, 2) for i in range(11)]
    )
    p.add_argument("--out", type=Path, default=None, help="write OUT.md and OUT.json")
    args = p.parse_args()
    env = TalosKitchenEnv(task="pot_to_tray", image_size=32, randomize=False, terminate_on_success=False)
    t0 = time.time()
    rows = []
    for dx in args.offsets:
        rows.append(place_at(env, dx))
        print(rows[-1], flush=True)
    env.close()
    floor = [r["dx"] for r in rows if r["on_floor"]]
    lines = [
        f"# Pot placements along the pulled-out tray (tray stop {tasks.TRAY_STOP} m, goal x {tasks.POT_TRAY_XY[0]})",
        "",
        "| target x (tray frame, m) | tray pulled to | tray at the end | rests at x | rests at y | above the floor (m) | on the floor |",
        "|---:|---:|---:|---:|---:|---:|---|",
        *(
            f"| {r['dx']:+.3f} | {r['tray_pulled_to']} | {r['tray_at_end']} | {r['rest_x']:+.3f} | {r['rest_y']:+.3f} | "
            f"{r['rest_dz']:+.3f} | {'yes' if r['on_floor'] else 'no'} |"
            for r in rows
        ),
        "",
        f"On the floor at {len(floor)} of {len(rows)} offsets"
        + (f" (from {min(floor):+.3f} to {max(floor):+.3f})" if floor else "")
        + f"; {time.time() - t0:.0f} s.",
    ]
    print("\n".join(lines))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")
        record = {"tray_stop": tasks.TRAY_STOP, "goal_x": tasks.POT_TRAY_XY[0], "placements": rows}
        args.out.with_suffix(".json").write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
