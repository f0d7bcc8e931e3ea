"""Grasp bookkeeping for the Talos kitchen: which closures of the gripper ended holding an object.

Why: the kitchen's failures are grasps (issue 14), and a success rate cannot tell a grasp that was
abandoned half-way (the command dropped while the fingers were still closing) from one that closed
on air or touched the handle with one finger only. A *closure* is a maximal run of frames whose
gripper command is above :data:`GATE` (the weld gate of :class:`~.control.GraspWeld`); each is
classified from per-frame samples of the command, the measured closure, the contacts of the two
finger sides and the active weld:

* ``held``: an object was welded during the run;
* ``abandoned``: no weld and the command dropped while the gripper was still closing (measured
  closure rising and below :data:`CLOSED_ON_AIR`);
* ``touched``: no weld, the gripper closed, a finger touched a grasp geom (one side only, or late);
* ``missed``: no weld, the gripper closed on air.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from . import scene
from .primitives import welded

GATE = 0.5  # gripper command above which GraspWeld may weld (control.GraspWeld.update)
OBJECTS = ("pot", "door", "tray")
HELD_CODE = {None: 0, "pot": 1, "door": 2, "tray": 3}  # numeric code for env info / rerun scalars
RISING = 0.01  # measured-closure increase over the last two frames that counts as "still closing"
CLOSED_ON_AIR = 0.9  # measured closure past any handle: the fingers (nearly) meet


@dataclass(frozen=True)
class GraspSample:
    """One control step: gripper command, measured closure, touched and welded object (or None)."""

    command: float
    closure: float
    touched: str | None = None
    held: str | None = None


@dataclass(frozen=True)
class Closure:
    """One run of frames with the gripper command above :data:`GATE`; ``end`` is exclusive."""

    start: int
    end: int
    outcome: str  # "held" | "abandoned" | "touched" | "missed"
    obj: str | None  # held object, else the touched one, else None
    frames_to_weld: int | None  # frames from the closing command to the weld
    peak_closure: float
    peak_command: float

    @property
    def frames(self) -> int:
        return self.end - self.start


def grasp_geoms(handles: scene.KitchenHandles) -> dict[str, frozenset]:
    """The geoms each object is grasped by (what GraspWeld checks for contact)."""
    return {"pot": handles.pot_geoms, "door": handles.door_handle_geoms, "tray": handles.tray_handle_geoms}


def touched_object(data, handles: scene.KitchenHandles) -> str | None:
    """The object whose grasp geoms touch either finger side (pot first), or None."""
    fingers = handles.finger_geoms_a | handles.finger_geoms_b
    hit = set()
    for i in range(data.ncon):
        c = data.contact[i]
        g1, g2 = int(c.geom1), int(c.geom2)
        for finger, other in ((g1, g2), (g2, g1)):
            if finger in fingers:
                hit.add(other)
    for name, geoms in grasp_geoms(handles).items():
        if hit & geoms:
            return name
    return None


def sample(data, handles: scene.KitchenHandles, command: float) -> GraspSample:
    """The grasp state after a control step that sent gripper ``command``."""
    return GraspSample(
        command=float(command),
        closure=scene.gripper_opening(data, handles),
        touched=touched_object(data, handles),
        held=welded(data, handles),
    )


def _still_closing(closing: Sequence[float]) -> bool:
    """The measured closure was still rising (and short of closed on air) at the run's last frame."""
    if closing[-1] >= CLOSED_ON_AIR:
        return False
    return len(closing) < 3 or closing[-1] - closing[-3] > RISING


def info(data, handles: scene.KitchenHandles, command: float) -> dict:
    """The grasp state as numbers for env infos, so lerobot-eval and rerun rollouts (``info/<key>``) carry it:
    ``held`` / ``touched`` object codes (:data:`HELD_CODE`), ``grip_closure`` and ``grip_command``."""
    s = sample(data, handles, command)
    return {
        "held": HELD_CODE[s.held],
        "touched": HELD_CODE[s.touched],
        "grip_closure": s.closure,
        "grip_command": s.command,
    }


def from_info(info: dict) -> GraspSample:
    """Inverse of :func:`info` (e.g. the per-step infos of a policy rollout)."""
    name = {v: k for k, v in HELD_CODE.items()}
    return GraspSample(
        command=float(info["grip_command"]),
        closure=float(info["grip_closure"]),
        touched=name[int(info["touched"])],
        held=name[int(info["held"])],
    )


def closures(samples: Sequence[GraspSample]) -> list[Closure]:
    """Split a trajectory into its closures and classify each (see the module docstring)."""
    out = []
    n, t = len(samples), 0
    while t < n:
        if samples[t].command <= GATE:
            t += 1
            continue
        start = t
        while t < n and samples[t].command > GATE:
            t += 1
        run = samples[start:t]
        weld = next((i for i, s in enumerate(run) if s.held), None)
        touched = next((s.touched for s in run if s.touched), None)
        closing = [s.closure for s in run]
        ended = t < n  # the command dropped (not the end of the recording)
        if weld is not None:
            outcome, obj = "held", run[weld].held
        elif ended and _still_closing(closing):
            outcome, obj = "abandoned", touched
        else:
            outcome, obj = ("touched" if touched else "missed"), touched
        out.append(
            Closure(
                start=start,
                end=t,
                outcome=outcome,
                obj=obj,
                frames_to_weld=weld,
                peak_closure=float(max(closing)),
                peak_command=float(max(s.command for s in run)),
            )
        )
    return out


def summarize(runs: Iterable[Closure]) -> dict:
    """Counts per outcome and per object, held rate and the median frames from closing to weld."""
    runs = list(runs)
    outcomes = {k: sum(r.outcome == k for r in runs) for k in ("held", "abandoned", "touched", "missed")}
    per_object = {}
    for name in OBJECTS:
        mine = [r for r in runs if r.obj == name]
        per_object[name] = {
            "closures": len(mine),
            "held": sum(r.outcome == "held" for r in mine),
        }
    weld_frames = [r.frames_to_weld for r in runs if r.frames_to_weld is not None]
    return {
        "closures": len(runs),
        **outcomes,
        "held_rate": outcomes["held"] / len(runs) if runs else float("nan"),
        "median_frames_to_weld": float(np.median(weld_frames)) if weld_frames else float("nan"),
        "per_object": per_object,
    }


def as_rows(runs: Iterable[Closure]) -> list[dict]:
    """Plain dicts (for JSON reports)."""
    return [asdict(r) | {"frames": r.frames} for r in runs]
