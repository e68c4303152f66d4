"""Pictures of the warehouse floor: an RGB image and a text view."""

from __future__ import annotations

import numpy as np

CELL_PX = 12
_FLOOR = np.array([245, 245, 245], np.uint8)
_SHELF = np.array([205, 190, 160], np.uint8)
_WALL = np.array([90, 90, 90], np.uint8)
_ITEM_NEW = np.array([255, 235, 90], np.float64)
_ITEM_OLD = np.array([190, 80, 0], np.float64)
_ROBOT = np.array([40, 90, 220], np.uint8)
_LEARNER = np.array([200, 0, 200], np.uint8)
_OUTLINE = np.array([220, 0, 0], np.uint8)
_AGE_SCALE = 30  # an item this old (or older) gets the darkest shade
LEGEND = tuple((name, tuple(int(c) for c in colour)) for name, colour in (
    ("shelf", _SHELF), ("new item", _ITEM_NEW), ("old item", _ITEM_OLD), ("robot", _ROBOT),
    ("learner", _LEARNER), ("learner's region", _OUTLINE)))
"""The colours of :func:`render_rgb`, for legends."""


def render_rgb(env, cell_px: int = CELL_PX) -> np.ndarray:
    """``(height*cell_px, width*cell_px, 3)`` uint8 image of ``env``'s floor."""
    h, w = env.height, env.width
    ii, jj = np.mgrid[0:h, 0:w]
    row_line, col_line = ii % 4 == 0, jj % 4 == 0
    cells = np.empty((h, w, 3), np.uint8)
    cells[:] = _FLOOR
    cells[row_line ^ col_line] = _SHELF
    cells[row_line & col_line] = _WALL
    ages = env.item_ages_floor()
    has = ages > 0
    frac = np.clip((ages[has] - 1) / (_AGE_SCALE - 1), 0.0, 1.0)[:, None]
    cells[has] = ((1 - frac) * _ITEM_NEW + frac * _ITEM_OLD).astype(np.uint8)
    img = np.repeat(np.repeat(cells, cell_px, axis=0), cell_px, axis=1)

    # Region borders run along the middle of the shared shelf rows/columns.
    mid = cell_px // 2
    img[mid::4 * cell_px, :] = (img[mid::4 * cell_px, :] * 0.5).astype(np.uint8)
    img[:, mid::4 * cell_px] = (img[:, mid::4 * cell_px] * 0.5).astype(np.uint8)

    learners = set(env.learner_indices.tolist())
    pad = max(cell_px // 5, 1)
    for n, (r, c) in enumerate(env.robot_positions()):
        colour = _LEARNER if n in learners else _ROBOT
        img[r * cell_px + pad : (r + 1) * cell_px - pad, c * cell_px + pad : (c + 1) * cell_px - pad] = colour
    if len(learners) < env.n_robots:  # outlining every region would say nothing
        for n in learners:
            r0, c0 = (env._origin[n] * cell_px).tolist()
            r1, c1 = r0 + 5 * cell_px - 1, c0 + 5 * cell_px - 1
            img[r0 : r0 + 2, c0 : c1 + 1] = _OUTLINE
            img[r1 - 1 : r1 + 1, c0 : c1 + 1] = _OUTLINE
            img[r0 : r1 + 1, c0 : c0 + 2] = _OUTLINE
            img[r0 : r1 + 1, c1 - 1 : c1 + 1] = _OUTLINE
    return img


def render_ansi(env) -> str:
    """Text view: ``#`` wall, ``-``/``|`` empty shelf, ``1``-``9`` item age (``+`` older),
    ``R`` scripted robot, ``L`` learner, ``.`` floor."""
    h, w = env.height, env.width
    ii, jj = np.mgrid[0:h, 0:w]
    grid = np.full((h, w), ".", dtype="<U1")
    grid[(ii % 4 == 0) & (jj % 4 != 0)] = "-"
    grid[(ii % 4 != 0) & (jj % 4 == 0)] = "|"
    grid[(ii % 4 == 0) & (jj % 4 == 0)] = "#"
    ages = env.item_ages_floor()
    for age in range(1, 10):
        grid[ages == age] = str(age)
    grid[ages > 9] = "+"
    pos = env.robot_positions()
    grid[pos[:, 0], pos[:, 1]] = "R"
    learners = env.learner_indices
    grid[pos[learners, 0], pos[learners, 1]] = "L"
    header = f"warehouse_v0 step {env._cycle}/{env.max_cycles}, items collected {env.items_collected}"
    return header + "\n" + "\n".join("".join(row) for row in grid) + "\n"
