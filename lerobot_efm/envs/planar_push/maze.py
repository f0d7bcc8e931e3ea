"""Geometry of the planar push maze: walls, clearances, the three regions and grid shortest paths.

The arena is [-1, 1]^2 split in a 9 x 9 grid of cells of 2/9 (as the reference's "circle_maze_medium").
The disc (radius 0.2, diameter 0.4 = 1.8 cells) cannot pass one-cell corridors, so our maze keeps every
passage at least 4 cells (0.89) wide: one divider of wall cells (row 4, columns 4..8) leaves a C-shaped
free space -- a bottom band, a top band and a left passage joining them. Moving the disc from the right of
one band to the right of the other needs a detour around the divider, and a 0.89-wide passage leaves room
for the effector (diameter 0.15) to get around a disc in its middle (0.245 on each side).

Regions (used by the partitioned play data; dashed lines in the paper's figure): ``bottom`` (x > -1/3,
y < 0), ``left`` (x <= -1/3) and ``top`` (x > -1/3, y >= 0). Going from ``bottom`` to ``top`` crosses all three.

Shortest paths are BFS distances on a 45 x 45 grid (5 x 5 nodes per maze cell, spacing 2/45), computed by a
vectorised wavefront (8-connected, diagonal steps cost sqrt(2) approximately through two passes).
"""

from __future__ import annotations

from functools import cache

import numpy as np

ARENA = 1.0
MAZE_CELLS = 9
CELL = 2.0 * ARENA / MAZE_CELLS
# Row 0 is the top (y = +1), column 0 the left (x = -1); '#' = wall cell.
LAYOUT = (
    ".........",
    ".........",
    ".........",
    ".........",
    "....#####",
    ".........",
    ".........",
    ".........",
    ".........",
)
OBJECT_RADIUS = 0.2
EFFECTOR_RADIUS = 0.075
REGION_NAMES = ("bottom", "left", "top")
REGION_X_SPLIT = -1.0 / 3.0  # left region: x <= this
GRID_N = 45  # planning grid nodes per axis
GRID_H = 2.0 * ARENA / GRID_N
GRID_COORDS = -ARENA + (np.arange(GRID_N) + 0.5) * GRID_H
OBJECT_CLEARANCE = 0.03  # planned disc centres keep this much space to walls beyond the radius
# A disc pushed into a corner comes to rest against both walls (isotropic ground friction: a slide along a wall
# ends touching it); corner goals and targets sit this far off them.
CORNER = ARENA - OBJECT_RADIUS - 0.005
EFFECTOR_CLEARANCE = 0.02


def wall_cells() -> np.ndarray:
    """(9, 9) bool, [row, col] with row 0 at the top."""
    grid = np.array([[c == "#" for c in row] for row in LAYOUT])
    if grid.shape != (MAZE_CELLS, MAZE_CELLS):
        raise ValueError(f"LAYOUT must be {MAZE_CELLS}x{MAZE_CELLS}, got {grid.shape}")
    return grid


def wall_boxes() -> np.ndarray:
    """Axis-aligned wall boxes (cx, cy, half_x, half_y), one per horizontal run of wall cells."""
    boxes = []
    for r, row in enumerate(wall_cells()):
        c = 0
        while c < MAZE_CELLS:
            if not row[c]:
                c += 1
                continue
            start = c
            while c < MAZE_CELLS and row[c]:
                c += 1
            x0, x1 = -ARENA + start * CELL, -ARENA + c * CELL
            y1 = ARENA - r * CELL
            boxes.append(((x0 + x1) / 2, y1 - CELL / 2, (x1 - x0) / 2, CELL / 2))
    return np.array(boxes, dtype=np.float64).reshape(-1, 4)


_BOXES = wall_boxes()


def wall_distance(points) -> np.ndarray:
    """Distance from each point (..., 2) to the nearest wall surface or arena border (negative inside)."""
    p = np.asarray(points, dtype=np.float64)
    d = ARENA - np.abs(p).max(axis=-1)  # border
    for cx, cy, hx, hy in _BOXES:
        q = np.abs(p - np.array([cx, cy])) - np.array([hx, hy])
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        inside = np.minimum(q.max(axis=-1), 0.0)
        d = np.minimum(d, outside + inside)
    return d


def region_of(xy) -> np.ndarray | int:
    """Region index (0 bottom, 1 left, 2 top) of points (..., 2); an int for a single point."""
    p = np.asarray(xy, dtype=np.float64)
    r = np.where(p[..., 0] <= REGION_X_SPLIT, 1, np.where(p[..., 1] < 0.0, 0, 2))
    return int(r) if r.ndim == 0 else r


def maze_cell_of(xy) -> tuple[np.ndarray, np.ndarray]:
    """(row, col) of the 9 x 9 maze cell containing each point (row 0 at the top)."""
    p = np.clip(np.asarray(xy, dtype=np.float64), -ARENA, ARENA - 1e-9)
    col = ((p[..., 0] + ARENA) / CELL).astype(int)
    row = ((ARENA - 1e-9 - p[..., 1]) / CELL).astype(int)
    return np.clip(row, 0, MAZE_CELLS - 1), col


def free_disc_cells() -> np.ndarray:
    """(9, 9) bool: maze cells whose centre is a valid disc position (used for coverage statistics)."""
    c = -ARENA + (np.arange(MAZE_CELLS) + 0.5) * CELL
    xs, ys = np.meshgrid(c, c[::-1])
    return wall_distance(np.stack([xs, ys], -1)) >= OBJECT_RADIUS


@cache
def _grid_points() -> np.ndarray:
    xs, ys = np.meshgrid(GRID_COORDS, GRID_COORDS, indexing="ij")  # [i, j] -> (x_i, y_j)
    return np.stack([xs, ys], -1)


@cache
def _grid_wall_distance() -> np.ndarray:
    return wall_distance(_grid_points())


def inside_region(xy, region: int, margin: float = 0.0) -> np.ndarray:
    """Whether points (..., 2) lie in ``region`` at least ``margin`` away from its (virtual) borders."""
    p = np.asarray(xy, dtype=np.float64)
    x, y = p[..., 0], p[..., 1]
    if region == 1:
        return x <= REGION_X_SPLIT - margin
    if region not in (0, 2):
        raise ValueError(f"region must be 0 (bottom), 1 (left) or 2 (top), got {region!r}")
    return (x > REGION_X_SPLIT + margin) & ((y < -margin) if region == 0 else (y >= margin))


def free_mask(radius: float, region: int | None = None, margin: float = 0.0) -> np.ndarray:
    """(N, N) bool [i, j] (x index, y index): nodes where a circle of ``radius`` fits (and lies in ``region``,
    ``margin`` inside its borders)."""
    free = _grid_wall_distance() >= radius
    if region is not None:
        free &= inside_region(_grid_points(), region, margin)
    return free


def grid_index(xy) -> tuple[int, int]:
    ij = np.clip(((np.asarray(xy, dtype=np.float64) + ARENA) / GRID_H).astype(int), 0, GRID_N - 1)
    return int(ij[0]), int(ij[1])


def grid_point(i: int, j: int) -> np.ndarray:
    return np.array([GRID_COORDS[i], GRID_COORDS[j]])


def nearest_free(free: np.ndarray, xy) -> tuple[int, int]:
    """Index of the free node nearest to ``xy`` (a point just outside the free set snaps back in)."""
    if not free.any():
        raise ValueError("empty free mask: nothing is reachable")
    pts = _grid_points()
    d = np.linalg.norm(pts - np.asarray(xy, dtype=np.float64), axis=-1)
    d[~free] = np.inf
    i, j = np.unravel_index(int(np.argmin(d)), d.shape)
    return int(i), int(j)


_STEPS = [(di, dj, float(np.hypot(di, dj))) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]


def distance_field(free: np.ndarray, goal_xy) -> np.ndarray:
    """Grid path length (in world units) from every free node to the node nearest ``goal_xy``; inf elsewhere.

    Bellman-Ford sweeps over the 8 neighbour shifts, vectorised, until nothing changes (a few dozen sweeps).
    """
    dist = np.full(free.shape, np.inf)
    dist[nearest_free(free, goal_xy)] = 0.0
    n = free.shape[0]
    while True:
        new = dist.copy()
        for di, dj, c in _STEPS:
            src = dist[max(di, 0) : n + min(di, 0), max(dj, 0) : n + min(dj, 0)]
            dst = new[max(-di, 0) : n + min(-di, 0), max(-dj, 0) : n + min(-dj, 0)]
            np.minimum(dst, src + c * GRID_H, out=dst)
        new[~free] = np.inf
        if np.array_equal(new, dist):
            return dist
        dist = new


def segment_clear(a, b, radius: float, avoid=None, avoid_radius: float = 0.0) -> bool:
    """Whether a circle of ``radius`` swept from a to b stays off the walls (and off the disc ``avoid``)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    n = max(2, int(np.ceil(np.linalg.norm(b - a) / 0.02)) + 1)
    pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    if np.any(wall_distance(pts) < radius):
        return False
    if avoid is not None and np.any(np.linalg.norm(pts - np.asarray(avoid), axis=-1) < avoid_radius):
        return False
    return True


def grid_path(dist: np.ndarray, start_xy, free: np.ndarray) -> np.ndarray:
    """Node positions (K, 2) of the steepest-descent path from ``start_xy`` to the goal of ``dist``."""
    i, j = nearest_free(free, start_xy)
    if not np.isfinite(dist[i, j]):
        raise ValueError(f"no path from {np.asarray(start_xy).tolist()}: goal unreachable in this free mask")
    path = [(i, j)]
    n = dist.shape[0]
    while dist[i, j] > 0:
        best = min(
            (
                (dist[i + di, j + dj], i + di, j + dj)
                for di, dj, _ in _STEPS
                if 0 <= i + di < n and 0 <= j + dj < n
            ),
            key=lambda t: t[0],
        )
        i, j = best[1], best[2]
        path.append((i, j))
    return np.array([grid_point(a, b) for a, b in path])


def lookahead(
    path: np.ndarray, start_xy, radius: float, max_dist: float, avoid=None, avoid_radius: float = 0.0
) -> np.ndarray:
    """Farthest path node within ``max_dist`` (along the path) reachable from ``start_xy`` in a straight line."""
    best = path[min(1, len(path) - 1)]
    seg = np.linalg.norm(np.diff(path, axis=0), axis=-1)
    along = np.concatenate([[0.0], np.cumsum(seg)])
    for k in range(1, len(path)):
        if along[k] > max_dist:
            break
        if segment_clear(start_xy, path[k], radius, avoid, avoid_radius):
            best = path[k]
    return best
