"""Numpy-only drawing of the grid: roads, light states and cars into an RGB array."""

from __future__ import annotations

import numpy as np

from ials_zoo.traffic.network import EDGE_LENGTH

SCALE = 0.5  # pixels per metre
_ROAD, _BG, _CAR = (90, 90, 90), (235, 235, 225), (30, 60, 200)
_LEARNER = (200, 0, 200)
_COLOR = {"G": (0, 170, 0), "g": (0, 170, 0), "y": (230, 190, 0), "r": (200, 0, 0)}
LEGEND = (("road", _ROAD), ("car", _CAR), ("green", _COLOR["G"]), ("yellow", _COLOR["y"]),
          ("red", _COLOR["r"]), ("learner", _LEARNER))
"""The colours of :func:`render_grid`, for legends."""


def render_grid(grid, data: dict, learners=()) -> np.ndarray:
    """Draw the grid from ``data = {"xy": [V, 2] vehicle positions, "tls": {id: state}}``.

    Roads are grey lines, each intersection shows two marks (north of it: the north-south
    light, east of it: the east-west light) coloured by the first link of that approach, a
    magenta frame marks the ``learners`` (intersection indices), and each vehicle is a blue
    3 x 3 dot. Returns ``uint8 [H, W, 3]``.
    """
    rows, cols = grid
    width_m, height_m = (cols + 1) * EDGE_LENGTH, (rows + 1) * EDGE_LENGTH
    w, h = int(width_m * SCALE) + 1, int(height_m * SCALE) + 1
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _BG

    def px(x, y):
        return int(round(x * SCALE)), int(round((height_m - y) * SCALE))

    for r in range(rows):
        _, py = px(0, height_m - (r + 1) * EDGE_LENGTH)
        img[max(py - 1, 0) : py + 2, :] = _ROAD
    for c in range(cols):
        pxx, _ = px((c + 1) * EDGE_LENGTH, 0)
        img[:, max(pxx - 1, 0) : pxx + 2] = _ROAD
    learners = set(int(i) for i in learners)
    if len(learners) < rows * cols:  # framing every intersection would say nothing
        for i in learners:
            r, c = divmod(i, cols)
            x, y = px((c + 1) * EDGE_LENGTH, height_m - (r + 1) * EDGE_LENGTH)
            half = 12
            for dy in (-half, half):
                img[max(y + dy - 1, 0) : y + dy + 1, max(x - half, 0) : x + half + 1] = _LEARNER
            for dx in (-half, half):
                img[max(y - half, 0) : y + half + 1, max(x + dx - 1, 0) : x + dx + 1] = _LEARNER
    for r in range(rows):
        for c in range(cols):
            state = data["tls"].get(f"tls_{r * cols + c}")
            if not state:
                continue
            x, y = px((c + 1) * EDGE_LENGTH, height_m - (r + 1) * EDGE_LENGTH)
            # link order is clockwise from the north approach, 3 links per approach
            ns, ew = state[0], state[len(state) // 4]
            img[max(y - 7, 0) : y - 3, x - 2 : x + 3] = _COLOR.get(ns, _ROAD)
            img[y - 2 : y + 3, x + 4 : x + 8] = _COLOR.get(ew, _ROAD)
    for x, y in np.asarray(data["xy"]).reshape(-1, 2):
        cx, cy = px(x, y)
        img[max(cy - 1, 0) : cy + 2, max(cx - 1, 0) : cx + 2] = _CAR
    return img
