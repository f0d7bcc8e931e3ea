"""Scripted demonstrators of the planar push datasets (the paper's three human behaviours) and their recorder.

* :class:`ExpertReachGoal` pushes the disc from a random start along a grid shortest path to a maze corner
  (or, given ``goal``, to any 4-D goal: disc first, then the effector around it; it solves the eval pairs).
* :class:`PlayFullSpace` pushes the disc to random targets anywhere, against walls and (sliding it along a wall)
  into corners, with detours, effector-only wandering and pauses; it never finishes.
* :class:`PlayPartitioned` does the same inside one region per episode (``maze.REGION_NAMES``): the disc
  touches the region's border line at most, so reaching a far goal needs pieces of several episodes, joined
  at the states that neighbouring regions share along their borders (stitching).

All follow the operator protocol of ``lerobot-efm-record``: ``reset() -> obs``, ``act(obs) -> command``,
``done``. Pushing is closed-loop: the effector stages behind the disc w.r.t. the next path waypoint (moving
around the disc when needed), then pushes with a command ``lead`` past the contact point; the static disc
friction (2) equals the spring force at 0.04 of lead, so ``lead = remaining + 0.035`` stops on the target.
Every command trails the effector like a mouse cursor, at most :data:`CURSOR_REACH` from it.

CLI (LeRobot-style flags; operators as in ``lerobot-efm-record``, :mod:`lerobot_efm.operators`)::

    python -m lerobot_efm.envs.planar_push.demonstrators --operator.type=planar_push_expert \
        --dataset.root=data/planar_push_expert --num_frames=47000 [--operator.noise=0.003] [--images=true]
"""

from __future__ import annotations

import time
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lerobot_efm.dataset_writer import DatasetTarget
from lerobot_efm.operators import OperatorConfig, choice_name, default_operator, register_operators

from .maze import (
    ARENA,
    CORNER,
    EFFECTOR_CLEARANCE,
    EFFECTOR_RADIUS,
    GRID_COORDS,
    GRID_H,
    MAZE_CELLS,
    OBJECT_CLEARANCE,
    OBJECT_RADIUS,
    REGION_NAMES,
    distance_field,
    free_disc_cells,
    free_mask,
    grid_index,
    grid_path,
    grid_point,
    inside_region,
    lookahead,
    maze_cell_of,
    nearest_free,
    segment_clear,
    wall_distance,
)

PUSH_GAP = OBJECT_RADIUS + EFFECTOR_RADIUS  # centre distance at contact
AVOID = PUSH_GAP + 0.015  # effector centres keep this far from the disc centre when going around it
STAGE = PUSH_GAP + 0.04  # staging distance behind the disc
ALIGN_COS = np.cos(np.deg2rad(22.0))
STATIC_LEAD = 0.035  # just under 0.04 = friction 2 / KP 50: a push with this lead stalls
MAX_LEAD = 0.1  # full push: spring force 5 (the clip)
CORNERS = np.array([[-CORNER, -CORNER], [CORNER, -CORNER], [-CORNER, CORNER], [CORNER, CORNER]])
START_MARGIN = 0.16  # random disc starts/targets: room for the effector between disc and wall
# Human operators rest on a reached goal: in the authors' expert recordings the disc rests at its final spot
# for a median of 91 frames. Without a rest the last max(L_o*S_o, L_a*S_a) frames of an episode, i.e. the
# final approach and the stop, are never training start frames, and stopping on a goal is never observed.
EXPERT_REST = (40, 140)  # frames held at the goal at the end of an expert episode (median 90)
PLAY_REST = (20, 100)  # frames of a play pause (after a disc leg with probability PLAY_REST_AFTER_DISC)
PLAY_REST_AFTER_DISC = 0.5
# Humans push the disc against walls and into corners too (nothing stops it there); without such legs no
# play frame has the disc within 0.04 of 8 of the 10 evaluation goals (corners), which no agent can then reach.
PLAY_WALL_TARGETS = 0.5  # share of the other disc legs aimed at a wall-adjacent spot, stopped on
WALL_BAND = 0.06  # a wall-adjacent target's disc lies within this of its closest allowed distance to a wall
REST_NOISE = 0.002  # a resting hand's tremor on the command
# Push speed is very sensitive to the lead: the disc's net force is 50 * lead - 2 (friction), 3 at lead 0.1 and 1
# at 0.06. Humans push at the force clip (their action lead, 0.083 on average, includes every slower phase); play
# pushing at U(0.06, 0.1) moved the disc at 0.27 /s against the expert's 0.41 /s, so the fastest routes between
# two play states were slow and the critic's minimum distance with them.
PLAY_MIN_LEAD = 0.09
# Humans keep the hand around the disc between pushes; wandering to any point of the maze (as before) added
# long effector-only stretches that no goal reached by pushing needs.
PLAY_EFFECTOR_NEAR: float | None = 0.6
# A hand's noise is smooth; i.i.d. noise on every command is jitter the actor has to model as such (0.01 before).
PLAY_NOISE = 0.005
# A disc pushed into a corner rests against both walls and no push can get it out (no room behind it): play that
# went on after a corner flailed around the wedged disc for the rest of the episode (30 % of the full-play frames,
# and every hindsight goal of those stretches was "stay in the corner"). Humans end a session with the disc in a
# corner instead (their episodes end after the disc rested a median 51 frames at its final spot). So a corner leg
# is the last one of an episode: a share PLAY_CORNER_EPISODES of the episodes push the disc into a corner with
# the first disc leg after a random frame in [0.4, 1] x PLAY_CORNER_AFTER, rest there and end.
# Eight of the ten evaluation goals are corners: with 0.6 / 400 full play showed each corner goal in 4-6 of its 52
# episodes; ending every episode in a corner (1.0 / 250: 76 shorter episodes) in 13-14, and FM-AC no-RL (CPU
# config, 12k steps, seeds 1000 / 2000) went from 30 / 18 to 40 / 46 %. Partitioned play did not gain (same
# change, seed 1000: no-RL 20 -> 16 %, use-RL 40 -> 38 %), so it keeps PARTITIONED_CORNER_*.
PLAY_CORNER_AFTER = 250
PLAY_CORNER_EPISODES = 1.0
PARTITIONED_CORNER_AFTER = 400
PARTITIONED_CORNER_EPISODES = 0.6
# A leg during which neither hand nor disc moves (by STALL_MOVE) for STALL_FRAMES is dropped: a human tries
# something else instead of pressing the hand into a wall (3.6-6.5 % of the play frames before).
STALL_FRAMES, STALL_MOVE = 10, 0.002
# A human's region is a dashed line on the screen, and "keep the disc in the region" lets the disc touch the line:
# its centre crosses it by up to a radius. Neighbouring regions' episodes then share the states near their border,
# the only places where the eq. 5 backup can join them; with disc paths kept 0.06 inside their regions (as before),
# no disc position of one region came within 0.15 of another region's.
REGION_OVERLAP = OBJECT_RADIUS
# Humans slide a disc into a corner along one of its walls; a straight diagonal push leaves the hand on the
# diagonal, where no evaluation goal has it (the goals are last frames of human pushes: the hand behind the disc
# along a wall). Corner legs first bring the disc onto a wall's line this far from the corner.
CORNER_SLIDE = 0.35
VIA_TOL = 0.02  # the disc stops this close to such a via point, lined up for the slide
# The final approach to a corner goal is a slide along a wall, yet a play episode holds at most one (its last
# leg: a wedged disc ends it), ~30 in the whole full-play recording against the expert's ~175; rollouts carried
# the disc to the goal's wall and stopped short. Humans also slide a disc along a wall towards a corner and stop
# before it: a share PLAY_WALL_SLIDES of the wall legs line the disc up WALL_SLIDE_FROM from a corner and slide
# it to WALL_SLIDE_TO from it, where the hand still fits between disc and corner (diameter 0.15). Full play,
# FM-AC no-RL, same config and budget: 12/24/16/22 % at 3k/6k/9k/12k steps without, 14/14/38/30 with 0.6.
PLAY_WALL_SLIDES = 0.6
WALL_SLIDE_FROM = (0.4, 0.7)
WALL_SLIDE_TO = (0.18, 0.3)
SLIDE_TILT = 0.08  # a slide pushes this much into its wall (isotropic friction: else it may stop short of it)
# A human moves a mouse cursor that the effector trails (the authors' recordings: |cmd - eff| = 0.063 on
# average); a script may instead command a far target at once. Beyond MAX_LEAD = 0.1 from the effector the force
# is clipped (5), so every command along that ray moves the hand the same way: the recorded action is then an
# arbitrary point of a ray (up to 1.9 away in our play), which the actor must model and which no state predicts.
# The operators send their command at most this far from the effector: the same motion, a determined action.
CURSOR_REACH = 0.12
PUSH_LOOKAHEAD = 0.35  # the disc is pushed at the farthest point of its grid path this far along it in sight
# The paper's evaluation goals are last frames of held-out expert episodes, so the expert's goal distribution
# contains them. Ours has 8 corner goals and 2 in open space (a band, the left passage); an expert that only ever
# went to corners never showed a stop in open space (1 and 0 of 46,943 frames near those two goals).
EXPERT_CORNER_SHARE = 0.75  # share of expert episodes aimed at a corner; the others at a random free spot
OPEN_GOAL_HAND = 0.36  # an open-space goal's hand lies at most this far from its disc centre (contact: 0.275)
# A braked push in open space has no wall to stop the disc: the scripted expert never overshot one (76 open-space
# episodes: the disc never left 0.04 of its final spot once there), so the data never showed the way back, and
# the policies that overshoot by 0.05-0.15 (FM-AC on the two open-space evaluation pairs) then hover behind a
# disc that lies past the goal. In this share of the open-space episodes the expert overshoots, as a human does
# now and then, and pushes the disc back from the other side.
EXPERT_OVERSHOOT_SHARE = 0.5
OVERSHOOT = (0.06, 0.15)  # how far past the goal such a push brakes the disc
OVERSHOOT_ARM = 0.3  # decided once the disc is this close to its goal, along the direction it comes from
# Full play had the expert's defect: its free-space disc legs pushed the disc to within 0.08 of a target without
# braking, so the disc coasted to a stop wherever it did, and never past a spot and back. FM-AC no-RL on it
# (24k steps) reached seven pairs at 60-100 % but neither open-space pair (0 %). A share PLAY_OPEN_STOPS of
# the free-space legs now brakes the disc on its target as the expert does (PLAY_OPEN_OVERSHOOT of them past it
# first, then back from the other side), moves the hand beside the resting disc and pauses there.
PLAY_OPEN_STOPS = 0.5
PLAY_OPEN_OVERSHOOT = 0.5
# Which corner an episode ends in was drawn at random: over ~24 corner endings one recording ended 12 times in
# the bottom-left corner and twice in the bottom-right one (375 frames with the disc on it against 855 in the
# previous recording), and FM-AC's success on the four pairs that end there fell from 60-100 % to 0-20 %. A
# recording's corner coverage then decides the result more than the method. With PLAY_BALANCED_CORNERS the
# operator heads for the corner it has ended an episode in least often so far (ties drawn at random).
PLAY_BALANCED_CORNERS = True


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.array([1.0, 0.0])


def _rot(u: np.ndarray, deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])


class Pusher:
    """Closed-loop disc pushing and effector navigation shared by the demonstrators.

    ``region`` confines disc paths (and targets sampled by :meth:`sample_disc`) to one maze region.
    """

    def __init__(
        self,
        region: int | None = None,
        region_margin: float = -REGION_OVERLAP,
        lookahead: float = PUSH_LOOKAHEAD,
    ):
        self.region, self.lookahead = region, float(lookahead)
        self.obj_free = free_mask(OBJECT_RADIUS + OBJECT_CLEARANCE, region, region_margin)
        self.start_free = free_mask(OBJECT_RADIUS + START_MARGIN, region, region_margin + 0.04)
        self.eff_free = free_mask(EFFECTOR_RADIUS + 0.01)
        # wall-adjacent disc targets: free for the disc, but not WALL_BAND further from the walls
        self.wall_nodes = np.argwhere(
            self.obj_free & ~free_mask(OBJECT_RADIUS + OBJECT_CLEARANCE + WALL_BAND)
        )
        # the maze corners a disc of this region can stop in (planned paths keep OBJECT_CLEARANCE off the walls,
        # a corner only CORNER's gap: its nearest free node is that much further on each axis)
        reach = GRID_H + np.sqrt(2) * (CORNER - (ARENA - OBJECT_RADIUS - OBJECT_CLEARANCE))
        self.corners = [
            c for c in CORNERS if np.linalg.norm(grid_point(*nearest_free(self.obj_free, c)) - c) < reach
        ]
        self._obj_fields: dict[tuple[int, int], np.ndarray] = {}
        self._eff_plan: tuple | None = None

    # ---------------------------------------------------------------- sampling
    def sample_disc(self, rng: np.random.Generator) -> np.ndarray:
        idx = np.argwhere(self.start_free)
        i, j = idx[rng.integers(len(idx))]
        return grid_point(i, j) + rng.uniform(-0.02, 0.02, 2)

    def disc_fits(self, p: np.ndarray) -> bool:
        """A disc at ``p`` leaves the hand room between it and every wall (to push it back from any side)."""
        return wall_distance(p) >= OBJECT_RADIUS + START_MARGIN and (
            self.region is None or inside_region(p, self.region, -REGION_OVERLAP)
        )

    def sample_wall_disc(self, rng: np.random.Generator) -> np.ndarray:
        """A disc target against a wall, not in a corner (a disc wedged there cannot be pushed out): a free spot
        within WALL_BAND of the walls."""
        i, j = self.wall_nodes[rng.integers(len(self.wall_nodes))]
        return grid_point(i, j)

    def corner_via(self, corner: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
        """A point CORNER_SLIDE from ``corner`` along one of its two walls (random, among those the disc may
        use), from which a straight push slides the disc along the wall into the corner; None if neither, or if
        ``corner`` is not a maze corner."""
        if np.abs(corner).min() < CORNER - 1e-9:
            return None
        inward = -np.sign(corner)
        vias = [
            corner + inward * axis * CORNER_SLIDE for axis in (np.array([1.0, 0.0]), np.array([0.0, 1.0]))
        ]
        fits = OBJECT_RADIUS + 0.004  # on the wall's line: as close to the wall as the corner itself
        vias = [
            v
            for v in vias
            if wall_distance(v) >= fits
            and segment_clear(v, corner, fits)
            and (self.region is None or inside_region(v, self.region, -REGION_OVERLAP))
        ]
        return vias[rng.integers(len(vias))].copy() if vias else None

    def wall_slide(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
        """(start, stop) of a slide along a wall towards a random corner of this region that stops short of it
        (WALL_SLIDE_FROM / WALL_SLIDE_TO from the corner); None when no wall line fits."""
        if not self.corners:
            return None
        corner = self.corners[rng.integers(len(self.corners))]
        inward = -np.sign(corner) * np.eye(2)[rng.integers(2)]
        start, stop = (
            corner + inward * rng.uniform(*WALL_SLIDE_FROM),
            corner + inward * rng.uniform(*WALL_SLIDE_TO),
        )
        fits = OBJECT_RADIUS + 0.004
        if wall_distance(start) < fits or not segment_clear(start, stop, fits):
            return None
        if self.region is not None and not inside_region(start, self.region, -REGION_OVERLAP):
            return None
        return start, stop

    def sample_effector(
        self, rng: np.random.Generator, obj: np.ndarray, near: float | None = None
    ) -> np.ndarray:
        """A free effector position clear of the disc (within ``near`` of it if given)."""
        for _ in range(1000):
            if near is None:
                p = rng.uniform(-ARENA, ARENA, 2)
            else:
                p = obj + _rot(np.array([rng.uniform(PUSH_GAP + 0.04, near), 0.0]), rng.uniform(0, 360))
            if (
                wall_distance(p) >= EFFECTOR_RADIUS + EFFECTOR_CLEARANCE
                and np.linalg.norm(p - obj) > AVOID + 0.02
            ):
                return p
        raise RuntimeError(f"no free effector position around disc {obj.tolist()}")

    def path_length(self, obj: np.ndarray, target: np.ndarray) -> float:
        field = self._field(target)
        return float(field[nearest_free(self.obj_free, obj)])

    # ---------------------------------------------------------------- control
    def _field(self, target: np.ndarray) -> np.ndarray:
        key = nearest_free(self.obj_free, target)
        if key not in self._obj_fields:
            self._obj_fields[key] = distance_field(self.obj_free, grid_point(*key))
        return self._obj_fields[key]

    def _push_direction(self, obj: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, bool]:
        """Unit push direction (rotated until there is room behind the disc) and whether it aims at the target."""
        direct = np.linalg.norm(target - obj) < 0.3 and segment_clear(obj, target, OBJECT_RADIUS + 0.004)
        if direct:
            waypoint = target
        else:
            path = grid_path(self._field(target), obj, self.obj_free)
            waypoint = lookahead(path, obj, OBJECT_RADIUS + 0.01, self.lookahead)
        u = _unit(waypoint - obj)
        for deg in (0, 15, -15, 30, -30, 45, -45, 60, -60, 75, -75, 90, -90):  # room behind the disc?
            v = _rot(u, deg)
            if wall_distance(obj - v * STAGE) >= EFFECTOR_RADIUS + 0.005:
                return v, direct
        return u, direct

    def move_effector(self, eff: np.ndarray, obj: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Command toward ``target`` that goes around the disc and the walls (grid path when blocked)."""
        if segment_clear(eff, target, EFFECTOR_RADIUS + 0.005, obj, AVOID):
            return target.copy()
        key = (grid_index(obj), grid_index(target))
        if self._eff_plan is None or self._eff_plan[0] != key:
            d = np.linalg.norm(
                np.stack(np.meshgrid(GRID_COORDS, GRID_COORDS, indexing="ij"), -1) - obj, axis=-1
            )
            free = self.eff_free & (d > AVOID)
            try:  # only the hand's side of the disc and walls: a target in a pocket behind the disc is approached
                free &= np.isfinite(distance_field(free, eff))  # as close as it gets (else no path at all)
                self._eff_plan = (key, free, distance_field(free, target))
            except ValueError:  # nothing free: back off from the disc
                return eff + _unit(eff - obj) * 0.1
        _, free, field = self._eff_plan
        try:
            path = grid_path(field, eff, free)
        except ValueError:
            return eff + _unit(eff - obj) * 0.1
        return lookahead(path, eff, EFFECTOR_RADIUS + 0.005, 0.4, obj, AVOID)

    def push(
        self,
        state: np.ndarray,
        target: np.ndarray,
        final: bool,
        lead: float = MAX_LEAD,
        direction: np.ndarray | None = None,
    ) -> np.ndarray:
        """Command that moves the disc toward ``target`` (stopping on it when ``final``); a given ``direction``
        is pushed along as it is (a straight slide, e.g. along a wall)."""
        eff, obj = state[:2], state[2:]
        u, direct = (direction, True) if direction is not None else self._push_direction(obj, target)
        to_obj = obj - eff
        dist = float(np.linalg.norm(to_obj))
        if dist < PUSH_GAP + 0.06 and float(np.dot(to_obj / max(dist, 1e-9), u)) > ALIGN_COS:
            if final and direct:  # slow down near the target, stall on it (no overshoot into a wall)
                lead = float(np.clip(0.6 * np.dot(target - obj, u) + STATIC_LEAD + 0.003, 0.0, lead))
            return obj - u * PUSH_GAP + u * lead
        return self.move_effector(eff, obj, obj - u * STAGE)


def slide_direction(obj: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """Push direction of a slide along a wall into ``corner``: at it, tilted SLIDE_TILT into the wall the disc slides
    along (the axis on which it is closest to the corner), so that it rides the wall and ends against both."""
    to_corner = corner - obj
    along = int(np.argmin(np.abs(to_corner)))
    tilt = np.zeros(2)
    tilt[along] = SLIDE_TILT * np.sign(corner[along])
    return _unit(_unit(to_corner) + tilt)


def _clip(cmd: np.ndarray) -> np.ndarray:
    return np.clip(cmd, -ARENA, ARENA).astype(np.float32)


def _send(eff: np.ndarray, cmd: np.ndarray, reach: float | None, noise: float, rng: np.random.Generator):
    """The command an operator sends: within ``reach`` of the hand (a cursor), with hand noise, in the arena."""
    return _clip(cursor(eff, cmd, reach) + rng.normal(0.0, noise, 2))


def cursor(eff: np.ndarray, cmd: np.ndarray, reach: float | None = CURSOR_REACH) -> np.ndarray:
    """``cmd`` brought within ``reach`` of the effector along the same ray (None: unchanged)."""
    if reach is None:
        return cmd
    offset = cmd - eff
    n = float(np.linalg.norm(offset))
    return eff + offset * (reach / n) if n > reach else cmd


class ExpertReachGoal:
    """Pushes the disc along a shortest path to a random goal at least ``min_path`` away (the paper's
    "Expert reach goal"): a corner with probability ``corner_share``, its last stretch slid along one of the
    corner's walls as play does it (the hand then ends where the corner evaluation goals have it), else a free
    spot in open space where the disc is braked, then the hand is moved to a random spot beside it (open-space
    goals name the hand too; in ``overshoot_share`` of them the disc is first braked past the goal and pushed
    back); ``done`` once both rest there. With ``goal`` (4-D [eff, obj])
    it keeps the env's current state as start, brings the disc to ``goal[2:]`` then the effector to ``goal[:2]``."""

    def __init__(
        self,
        env,
        rng: np.random.Generator,
        goal=None,
        noise: float = 0.003,
        min_path: float = 0.8,
        tolerance: float = 0.025,
        rest: tuple[int, int] = EXPERT_REST,
        cursor_reach: float | None = CURSOR_REACH,
        corner_share: float = EXPERT_CORNER_SHARE,
        overshoot_share: float = EXPERT_OVERSHOOT_SHARE,
    ):
        self.env, self.rng, self.noise, self.min_path, self.tol = (
            env,
            rng,
            float(noise),
            float(min_path),
            tolerance,
        )
        if not 0.0 <= corner_share <= 1.0:
            raise ValueError(f"corner_share must be in [0, 1], got {corner_share!r}")
        self.corner_share = float(corner_share)
        if not 0.0 <= overshoot_share <= 1.0:
            raise ValueError(f"overshoot_share must be in [0, 1], got {overshoot_share!r}")
        self.overshoot_share = float(overshoot_share)
        self._will_overshoot = False  # this episode overshoots its open-space goal (decided at reset)
        self._overshoot: np.ndarray | None = None  # the spot past the goal the disc is braked on first
        self.cursor_reach = cursor_reach
        self.fixed_goal = None if goal is None else np.asarray(goal, dtype=np.float64).reshape(4)
        self.rest = (int(rest[0]), int(rest[1]))
        self.pusher = Pusher()
        self.target = CORNERS[0].copy()
        self.effector_goal: np.ndarray | None = None
        self._pushing = True
        self._done = False
        self._rest_left: int | None = None  # frames still to rest on the goal (None: not arrived yet)
        self._rest_at = np.zeros(2)
        self._via: np.ndarray | None = None  # the corner's wall line point to line the disc up on first
        self._slide: np.ndarray | None = None  # the slide's push direction, fixed where it starts

    def reset(self) -> dict:
        self._done, self._pushing, self._rest_left, self._via, self._slide = False, True, None, None, None
        self._will_overshoot, self._overshoot = False, None
        if self.fixed_goal is not None:
            self.effector_goal, self.target = self.fixed_goal[:2].copy(), self.fixed_goal[2:].copy()
            return self.env.observe()
        self.effector_goal = None
        to_corner = self.rng.random() < self.corner_share
        for _ in range(100):
            obj = self.pusher.sample_disc(self.rng)
            goals = CORNERS if to_corner else [self.pusher.sample_disc(self.rng) for _ in range(4)]
            far = [c for c in goals if self.pusher.path_length(obj, c) >= self.min_path]
            if far:
                break
        self.target = far[self.rng.integers(len(far))].copy()
        self._via = self.pusher.corner_via(self.target, self.rng)
        if (
            not to_corner
        ):  # an open-space goal names the hand too: placed beside the resting disc, as the eval's
            self.effector_goal = self.pusher.sample_effector(self.rng, self.target, near=OPEN_GOAL_HAND)
            self._will_overshoot = bool(self.rng.random() < self.overshoot_share)
        eff = self.pusher.sample_effector(self.rng, obj, near=0.6)
        self.env.set_state(np.concatenate([eff, obj]))
        return self.env.observe()

    def act(self, obs: dict) -> np.ndarray:
        s = np.asarray(obs["agent_pos"], dtype=np.float64)
        eff, obj = s[:2], s[2:]
        if self._rest_left is not None:  # arrived: hold still where the hand stopped, then finish
            self._rest_left -= 1
            self._done = self._rest_left <= 0
            return _clip(self._rest_at + self.rng.normal(0.0, REST_NOISE, 2))
        if self._via is not None:
            if np.linalg.norm(obj - self._via) > VIA_TOL:
                return self._command(eff, self.pusher.push(s, self._via, final=True))
            self._via, self._slide = None, slide_direction(obj, self.target)
        if self._will_overshoot and np.linalg.norm(obj - self.target) < OVERSHOOT_ARM:
            self._will_overshoot = False
            past = self.target + _unit(self.target - obj) * self.rng.uniform(*OVERSHOOT)
            if self.pusher.disc_fits(past):  # never past the goal into a wall
                self._overshoot = past
        if self._overshoot is not None:
            if np.linalg.norm(obj - self._overshoot) > self.tol:
                return self._command(eff, self.pusher.push(s, self._overshoot, final=True))
            self._overshoot = None  # braked past the goal: now back from the other side
        err = float(np.linalg.norm(obj - self.target))
        # hysteresis: stop pushing within tol, push again if the disc drifted past 1.5 tol
        self._pushing = err > (self.tol if self._pushing else 1.5 * self.tol)
        if self._pushing:  # a slide needs no braking: the walls stop the disc
            cmd = self.pusher.push(s, self.target, final=self._slide is None, direction=self._slide)
        elif self.effector_goal is not None and np.linalg.norm(eff - self.effector_goal) > self.tol:
            cmd = self.pusher.move_effector(eff, obj, self.effector_goal)
        else:
            self._rest_left, self._rest_at = (
                int(self.rng.integers(self.rest[0], self.rest[1] + 1)),
                eff.copy(),
            )
            return self.act(obs)
        return self._command(eff, cmd)

    def _command(self, eff: np.ndarray, cmd: np.ndarray) -> np.ndarray:
        return _send(eff, cmd, self.cursor_reach, self.noise, self.rng)

    @property
    def done(self) -> bool:
        return self._done


@dataclass
class Leg:
    """One step of a play plan. ``kind``: "disc" (push the disc near ``target``), "disc_via" (push it onto
    ``target``, lining it up for the next leg), "disc_stop" (push it onto ``target`` and stop there),
    "effector" (move the hand alone) or "pause" (hold the hand where it is for ``frames``; ``target`` is set
    when the pause starts). A ``slide`` pushes along the straight line from where the disc is when the leg
    starts (``direction``, set then)."""

    kind: str
    target: np.ndarray | None = None
    frames: int = 0
    slide: bool = False
    direction: np.ndarray | None = None
    last: bool = False  # the episode ends with this leg
    overshoot: float = 0.0  # a "disc_stop" first brakes the disc this far past ``target`` (see OVERSHOOT_ARM)


class PlayFullSpace:
    """Goal-free play: push the disc to random targets (sometimes via a detour), move the effector alone,
    pause; mild command noise. Done after a corner (a wedged disc cannot be pushed out), else episodes end at the
    recorder's length."""

    region: int | None = None

    def __init__(
        self,
        env,
        rng: np.random.Generator,
        noise: float = PLAY_NOISE,
        leg_budget: int = 250,
        cursor_reach: float | None = CURSOR_REACH,
        pause_share: float = 0.12,
        effector_share: float = 0.18,
        rest_after_disc: float = PLAY_REST_AFTER_DISC,
        push_lookahead: float = PUSH_LOOKAHEAD,
        min_lead: float = PLAY_MIN_LEAD,
        effector_near: float | None = PLAY_EFFECTOR_NEAR,
        corner_after: int = PLAY_CORNER_AFTER,
        corner_episodes: float = PLAY_CORNER_EPISODES,
        wall_slides: float = PLAY_WALL_SLIDES,
        open_stops: float = PLAY_OPEN_STOPS,
        open_overshoot: float = PLAY_OPEN_OVERSHOOT,
        balanced_corners: bool = PLAY_BALANCED_CORNERS,
        **_,
    ):
        self.env, self.rng, self.noise, self.leg_budget = env, rng, float(noise), int(leg_budget)
        self.cursor_reach = cursor_reach
        self.pause_share, self.effector_share = float(pause_share), float(effector_share)
        self.rest_after_disc, self.push_lookahead = float(rest_after_disc), float(push_lookahead)
        if not 0.0 < min_lead <= MAX_LEAD:
            raise ValueError(f"min_lead must be in (0, {MAX_LEAD}], got {min_lead!r}")
        self.min_lead = float(min_lead)
        self.effector_near = None if effector_near is None else float(effector_near)
        if not 0.0 <= corner_episodes <= 1.0:
            raise ValueError(f"corner_episodes must be in [0, 1], got {corner_episodes!r}")
        self.corner_after, self.corner_episodes = int(corner_after), float(corner_episodes)
        if not 0.0 <= wall_slides <= 1.0:
            raise ValueError(f"wall_slides must be in [0, 1], got {wall_slides!r}")
        self.wall_slides = float(wall_slides)
        for name, share in (("open_stops", open_stops), ("open_overshoot", open_overshoot)):
            if not 0.0 <= share <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {share!r}")
        self.open_stops, self.open_overshoot = float(open_stops), float(open_overshoot)
        self.balanced_corners = bool(balanced_corners)
        self._corner_endings: dict[tuple[float, float], int] = {}  # corner -> episodes ended there so far
        self._frame, self._done, self._closing_frame = 0, False, None
        self._last_state, self._stalled = np.zeros(4), 0
        self.pusher = Pusher(self.region, lookahead=self.push_lookahead)
        self._queue: list[Leg] = []
        self._budget = 0
        self._lead = MAX_LEAD

    def _choose_region(self) -> None:
        """Hook for the partitioned variant."""

    def reset(self) -> dict:
        self._choose_region()
        obj = self.pusher.sample_disc(self.rng)
        eff = self.pusher.sample_effector(self.rng, obj, near=0.8)
        self.env.set_state(np.concatenate([eff, obj]))
        self._queue, self._frame, self._done = [], 0, False
        closes = self.pusher.corners and self.rng.random() < self.corner_episodes
        self._closing_frame = int(self.rng.uniform(0.4, 1.0) * self.corner_after) if closes else None
        return self.env.observe()

    def _random_effector_point(self, obj: np.ndarray) -> np.ndarray:
        for _ in range(100):
            p = self.pusher.sample_effector(self.rng, obj, near=self.effector_near)
            if self.region is None or inside_region(p, self.region, -0.25):
                return p
        return self.pusher.sample_effector(self.rng, obj, near=0.6)

    def _new_leg(self, s: np.ndarray) -> None:
        r = self.rng.random()
        self._budget, self._lead = self.leg_budget, self.rng.uniform(self.min_lead, MAX_LEAD)
        if r < self.pause_share:
            self._queue = [self._pause()]
        elif r < self.pause_share + self.effector_share:
            self._queue = [Leg("effector", self._random_effector_point(s[2:]))]
        elif (
            self._closing_frame is not None and self._frame >= self._closing_frame
        ):  # into a corner: rest, end
            target = self._closing_corner()
            via = self.pusher.corner_via(target, self.rng)
            self._queue = [Leg("disc_stop", target, slide=via is not None), self._pause(last=True)]
            if via is not None:
                self._queue.insert(0, Leg("disc_via", via))
            self._closing_frame = None
        elif self.rng.random() < PLAY_WALL_TARGETS:  # against a wall, stopping there
            slides = (
                self.wall_slides > 0 and self.rng.random() < self.wall_slides
            )  # (0: the old random stream)
            slide = self.pusher.wall_slide(self.rng) if slides else None
            if slide is None:
                self._queue = [Leg("disc_stop", self.pusher.sample_wall_disc(self.rng))]
            else:  # along a wall towards a corner, stopping short of it
                self._queue = [Leg("disc_via", slide[0]), Leg("disc_stop", slide[1], slide=True)]
            if self.rng.random() < self.rest_after_disc:
                self._queue.append(self._pause())
        else:
            target = self.pusher.sample_disc(self.rng)
            if self.open_stops > 0 and self.rng.random() < self.open_stops:  # (0: the old random stream)
                self._queue = self._open_stop(target)
                return
            self._queue = [Leg("disc", target)]
            if self.rng.random() < 0.3:  # detour through another point first
                self._queue.insert(0, Leg("disc", self.pusher.sample_disc(self.rng)))
            if self.rng.random() < self.rest_after_disc:  # a human often lets go once the disc is there
                self._queue.append(self._pause())

    def _closing_corner(self) -> np.ndarray:
        """The corner this episode heads for: at random, or (balanced) the one ended in least often so far."""
        corners = self.pusher.corners
        if not self.balanced_corners:
            return corners[self.rng.integers(len(corners))].copy()
        counts = np.array([self._corner_endings.get(tuple(c), 0) for c in corners])
        least = np.flatnonzero(counts == counts.min())
        return corners[least[self.rng.integers(len(least))]].copy()  # counted once the episode ends in it

    def _open_stop(self, target: np.ndarray) -> list[Leg]:
        """Brake the disc on a free-space ``target`` (sometimes past it first), hand beside it, rest: the
        open-space goal states and the way back to them, as the expert shows them."""
        overshoot = self.rng.uniform(*OVERSHOOT) if self.rng.random() < self.open_overshoot else 0.0
        hand = self.pusher.sample_effector(self.rng, target, near=OPEN_GOAL_HAND)
        return [Leg("disc_stop", target, overshoot=overshoot), Leg("effector", hand), self._pause()]

    def _pause(self, last: bool = False) -> Leg:
        """A rest of human-like length; the hand holds where it is when the pause starts."""
        return Leg("pause", frames=int(self.rng.integers(PLAY_REST[0], PLAY_REST[1] + 1)), last=last)

    def act(self, obs: dict) -> np.ndarray:
        s = np.asarray(obs["agent_pos"], dtype=np.float64)
        eff, obj = s[:2], s[2:]
        self._frame += 1
        moved = np.abs(s - self._last_state).max() > STALL_MOVE
        self._stalled, self._last_state = 0 if moved else self._stalled + 1, s.copy()
        if self._stalled >= STALL_FRAMES and self._queue and self._queue[0].kind != "pause":
            self._queue.pop(
                0
            )  # nothing moves: the leg cannot be done from here (e.g. no room behind the disc)
            self._stalled, self._budget = 0, self.leg_budget
        while True:
            if not self._queue:
                self._new_leg(s)
            leg = self._queue[0]
            self._budget -= 1
            if leg.kind == "pause":
                if leg.last and leg.frames <= 1:  # the last frame of the episode: hold, then done
                    self._done = True
                    corner = CORNERS[np.linalg.norm(CORNERS - obj, axis=1).argmin()]
                    if np.linalg.norm(corner - obj) < 0.05:  # a corner leg that failed is tried again later
                        self._corner_endings[tuple(corner)] = self._corner_endings.get(tuple(corner), 0) + 1
                if leg.frames <= 0 or self._budget <= 0:
                    self._queue.pop(0)
                    continue
                leg.frames -= 1
                if leg.target is None:
                    leg.target = eff.copy()
                return _clip(leg.target + self.rng.normal(0.0, REST_NOISE, 2))  # a resting hand: no leg noise
            if leg.overshoot > 0 and np.linalg.norm(obj - leg.target) < OVERSHOOT_ARM:
                past = leg.target + _unit(leg.target - obj) * leg.overshoot
                leg.overshoot = 0.0
                if self.pusher.disc_fits(past):  # never past the target into a wall (or out of the region)
                    self._queue.insert(0, Leg("disc_stop", past))
                    self._budget = self.leg_budget
                continue
            reach_tol = {"disc": 0.08, "disc_via": VIA_TOL, "disc_stop": 0.025}.get(leg.kind)
            reached = np.linalg.norm((obj if reach_tol else eff) - leg.target) < (reach_tol or 0.04)
            if reached or self._budget <= 0:
                self._queue.pop(0)
                self._budget = self.leg_budget
                continue
            if leg.kind == "effector":
                cmd = self.pusher.move_effector(eff, obj, leg.target)
            else:
                if leg.slide and leg.direction is None:  # the slide's line is fixed where it starts
                    leg.direction = slide_direction(obj, leg.target)
                # a slide into a corner needs no braking: the walls stop the disc, against both of them
                into_corner = leg.slide and np.abs(leg.target).min() >= CORNER - 1e-9
                cmd = self.pusher.push(
                    s,
                    leg.target,
                    final=leg.kind != "disc" and not into_corner,
                    lead=self._lead,
                    direction=leg.direction,
                )
            break
        return _send(eff, cmd, self.cursor_reach, self.noise, self.rng)

    @property
    def done(self) -> bool:
        return self._done


class PlayPartitioned(PlayFullSpace):
    """Play confined to one region per episode (``region`` kwarg, else random per reset): disc targets and
    disc paths stay within REGION_OVERLAP beyond the region's borders, effector-only moves stay near it."""

    def __init__(
        self,
        env,
        rng: np.random.Generator,
        region: int | None = None,
        corner_after: int = PARTITIONED_CORNER_AFTER,
        corner_episodes: float = PARTITIONED_CORNER_EPISODES,
        **kwargs,
    ):
        self.fixed_region = None if region is None else int(region)
        self.region = self.fixed_region if region is not None else int(rng.integers(len(REGION_NAMES)))
        self._pushers = {}
        super().__init__(env, rng, corner_after=corner_after, corner_episodes=corner_episodes, **kwargs)
        self._pushers[self.region] = self.pusher

    def _choose_region(self) -> None:
        if self.fixed_region is None:
            self.region = int(self.rng.integers(len(REGION_NAMES)))
        if self.region not in self._pushers:
            self._pushers[self.region] = Pusher(self.region, lookahead=self.push_lookahead)
        self.pusher = self._pushers[self.region]


class PlayHandOnly(PlayFullSpace):
    """Hand-only play: the hand wanders between random free points within ``effector_near`` of the disc (around
    it, never pushing it) and pauses. The simplest goal-reaching task: a deployment dry run trains on it in a
    minute and must then bring the hand to a goal, the disc untouched (``tests/test_sim_robot.py``)."""

    def __init__(self, env, rng: np.random.Generator, pause_share: float = 0.15, **kwargs):
        kwargs.update(effector_share=1.0 - pause_share, corner_episodes=0.0)
        super().__init__(env, rng, pause_share=pause_share, **kwargs)


# ------------------------------------------------------------------------------------------ recording

BEHAVIOURS = {
    # name: (operator class, max frames per episode, dataset task string)
    "expert": (ExpertReachGoal, 600, "push the disc to a corner of the maze"),
    "full": (PlayFullSpace, 800, "play: push the disc anywhere in the maze"),
    "partitioned": (PlayPartitioned, 630, "play: push the disc inside one region of the maze"),
    "hand": (PlayHandOnly, 600, "play: move the hand around the disc without touching it"),
}


def planar_push_features(with_images: bool = False, image_size: int = 96) -> dict:
    from lerobot_efm.dataset_writer import state_action_features

    from .env import STATE_NAMES

    return state_action_features(
        STATE_NAMES, ["cmd_x", "cmd_y"], {"top": image_size} if with_images else None
    )


def disc_coverage(states: np.ndarray) -> float:
    """Fraction of the maze cells a disc centre can occupy that the disc visited (states (T, 4))."""
    ok = free_disc_cells()
    row, col = maze_cell_of(np.asarray(states)[:, 2:4])
    seen = np.zeros((MAZE_CELLS, MAZE_CELLS), bool)
    seen[row, col] = True
    return float((seen & ok).sum() / ok.sum())


def run_episode(env, operator, max_frames: int) -> tuple[np.ndarray, np.ndarray, list | None, bool]:
    """Roll ``operator`` in ``env``: states (T, 4), actions (T, 2), images (or None), whether it ended done.

    When the operator finishes, the final state is kept as a last frame (holding the command) so the
    demonstrated goal appears in the data."""
    obs = operator.reset()
    states, actions, images = [], [], [] if "pixels" in obs else None
    for _ in range(max_frames):
        a = operator.act(obs)
        states.append(obs["agent_pos"])
        actions.append(a)
        if images is not None:
            images.append(obs["pixels"]["top"])
        obs, *_ = env.step(a)
        if operator.done:
            break
    finished = bool(operator.done)
    if finished and len(states) < max_frames:
        states.append(obs["agent_pos"])
        actions.append(actions[-1])
        if images is not None:
            images.append(obs["pixels"]["top"])
    return np.asarray(states, np.float32), np.asarray(actions, np.float32), images, finished


def evaluate_expert(max_steps: int = 600) -> dict[str, float]:
    """The scripted expert on the ten evaluation pairs under the paper's protocol: a reference row for agent
    tables. Returns success % and the mean share (%) of the goal distance closed (``reward="progress"``)."""
    from .env import EVAL_PAIRS, PlanarPushEnv

    env, successes, closed = PlanarPushEnv(task="all", reward="progress"), [], []
    for k in range(len(EVAL_PAIRS)):
        env.reset(options={"pair": k})
        expert = ExpertReachGoal(env, np.random.default_rng(k), goal=env.goal)
        obs, total, info = expert.reset(), 0.0, {"is_success": False}
        for _ in range(max_steps):
            obs, reward, terminated, _, info = env.step(expert.act(obs))
            total += reward
            if terminated:
                break
        successes.append(info["is_success"])
        closed.append(total)
    env.close()
    return {"pc_success": 100.0 * float(np.mean(successes)), "pc_closed": 100.0 * float(np.mean(closed))}


def record_planar_push_dataset(
    behaviour: str,
    root,
    num_frames: int,
    seed: int = 0,
    with_images: bool = False,
    repo_id: str | None = None,
    image_size: int = 96,
    max_episode_frames: int | None = None,
    verbose: bool = False,
    operator_options: dict | None = None,
):
    """Record episodes of ``behaviour`` (expert | full | partitioned | hand) until about ``num_frames`` frames into a
    new LeRobot v3 dataset at ``root`` (must not exist). Expert episodes that do not reach their corner are
    dropped. ``operator_options`` are keyword arguments of the operator class (e.g. ``noise``). Returns the
    dataset reopened read-only."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_efm.dataset_writer import GENERATOR_SEAL_INTERVAL_S, EpisodeWriter

    from .env import FPS, PlanarPushEnv

    if behaviour not in BEHAVIOURS:
        raise ValueError(f"Unknown behaviour {behaviour!r}; valid: {sorted(BEHAVIOURS)}")
    if Path(root).exists():
        raise FileExistsError(f"Dataset root {root} already exists; pick a new root or delete it")
    cls, max_len, task = BEHAVIOURS[behaviour]
    max_len = int(max_episode_frames or max_len)
    repo_id = repo_id or f"local/planar_push_{behaviour}"
    rng = np.random.default_rng(seed)
    env = PlanarPushEnv(
        task="pair0",
        obs_type="pixels_state" if with_images else "state",
        image_size=image_size,
        terminate_on_success=False,
    )
    env.reset(seed=seed)
    operator = cls(env, rng, **(operator_options or {}))
    writer = EpisodeWriter.open(
        root,
        repo_id,
        FPS,
        planar_push_features(with_images, image_size),
        use_videos=with_images,
        seal_interval_s=GENERATOR_SEAL_INTERVAL_S,
    )
    total, dropped, t0 = 0, 0, time.perf_counter()
    with writer, closing(env):
        while total < num_frames:
            states, actions, images, finished = run_episode(env, operator, max_len)
            if behaviour == "expert" and not finished:
                dropped += 1
                continue
            total += writer.write_episode(
                {
                    "observation.state": states[t],
                    "action": actions[t],
                    "task": task,
                    **({} if images is None else {"observation.images.top": images[t]}),
                }
                for t in range(len(states))
            )
            if verbose:
                print(
                    f"{behaviour}: {total}/{num_frames} frames, {writer.dataset.num_episodes} episodes, "
                    f"{dropped} dropped, {total / (time.perf_counter() - t0):.0f} frames/s",
                    flush=True,
                )
    return LeRobotDataset(repo_id, root=root)


@dataclass
class DemonstrationsConfig:
    """``python -m lerobot_efm.envs.planar_push.demonstrators --operator.type=planar_push_full
    --dataset.root=data/planar_push_full --num_frames=36661``: the paper-sized scripted recordings."""

    dataset: DatasetTarget = field(default_factory=DatasetTarget)
    # --operator.type=planar_push_{expert,full,partitioned,hand}, --operator.<option>=... (lerobot_efm.operators)
    operator: OperatorConfig | None = None
    num_frames: int = 0  # record episodes until about this many frames
    seed: int = 0
    images: bool = False  # also record observation.images.top (video)
    image_size: int = 96

    def __post_init__(self):
        if self.num_frames < 1:
            raise ValueError(f"--num_frames={self.num_frames}: give the number of frames to record (> 0)")
        if self.operator is not None and self.operator.env_type != "planar_push":
            raise ValueError(
                f"--operator.type={self.operator.type} records {self.operator.env_type}, not planar push; "
                f"choose one of {sorted(choice_name('planar_push', b) for b in BEHAVIOURS)}"
            )


def generate(cfg: DemonstrationsConfig):
    operator = cfg.operator or default_operator("planar_push")
    repo_id, root = cfg.dataset.resolved(f"local/planar_push_{operator.name}")
    t0 = time.perf_counter()
    ds = record_planar_push_dataset(
        operator.name,
        root,
        cfg.num_frames,
        cfg.seed,
        cfg.images,
        repo_id,
        cfg.image_size,
        verbose=True,
        operator_options=operator.options(),
    )
    states = np.stack([np.asarray(x) for x in ds.hf_dataset["observation.state"]])
    print(
        f"{root}: {ds.num_episodes} episodes, {ds.num_frames} frames in {time.perf_counter() - t0:.0f} s; "
        f"disc coverage {disc_coverage(states):.2f} of the maze cells"
    )
    return ds


def main(argv: list[str] | None = None):
    """Record a scripted planar push dataset; ``main([...])`` runs in-process and returns it."""
    from lerobot_efm.scripts import run_config_cli

    register_operators()
    return run_config_cli(DemonstrationsConfig, generate, argv, "lerobot_efm.envs.planar_push.demonstrators")


if __name__ == "__main__":
    main()
