"""Layout of the warehouse floor and of one robot's region (SPEC §1).

Floor and regions
-----------------
With ``robots=(R, C)`` the floor has ``(4R+1) x (4C+1)`` cells (25 x 25 for the default 6 x 6
robots). Robot ``(r, c)`` -- agent ``robot_{r*C + c}``, row-major -- owns the 5 x 5 region with
rows ``4r..4r+4`` and columns ``4c..4c+4``; neighbouring regions share their border row/column.

Inside a region cells are addressed by a *local position* ``p = 5*i + j`` (row ``i``, column
``j``, both 0..4, row-major). The 4 corners are walls. The other 12 border cells are shelf
(item) cells; the 9 inner cells are free floor.

Item bits (the fixed order used by observations, d-sets and the local simulator)
-----------------------------------------------------------------------------
The 12 shelf cells are grouped by side, in the influence-source order (right, below, left,
above); within a side they go top to bottom (vertical sides) or left to right (horizontal
sides)::

    bit  0- 2: right side  (1,4) (2,4) (3,4)
    bit  3- 5: below side  (4,1) (4,2) (4,3)
    bit  6- 8: left side   (1,0) (2,0) (3,0)
    bit  9-11: above side  (0,1) (0,2) (0,3)

So bit ``3*s + k`` is the ``k``-th cell of side ``s``. A shared side is seen by both regions
with the same ``k`` (the right side of one region is the left side of the next, both counted
top to bottom).

Influence sources
-----------------
One categorical variable per side ``s`` in (right, below, left, above) with 4 classes: class
``k`` in 0..2 means "the neighbour on that side stands, after its move, on my shelf cell
``3*s + k``" (its own cell ``3*opposite(s) + k``); class ``3`` (:data:`NONE`) means it stands
anywhere else. Regions on the outer rows/columns keep all 4 sources (same spec for every
region); a missing neighbour is always ``NONE``.

Movement
--------
Actions: 0 = up, 1 = down, 2 = left, 3 = right. From an inner cell all 4 moves are legal (an
inner cell never touches a corner). On a shelf cell only the move back inward is legal. An
illegal move leaves the robot where it is. Several robots may stand on the same shared cell.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ials_zoo.core.region import RegionSpec
from ials_zoo.errors import BadInput, BadInputType

DOMAIN_ID = "warehouse_v0"
SIZE = 5  # region side length
N_CELLS = SIZE * SIZE
N_ITEMS = 12
N_SOURCES = 4
NONE = 3  # influence class "the neighbour is not on a shared shelf cell of this side"
CENTRE = 2 * SIZE + 2  # local position of the region centre, where robots start
OBS_SIZE = N_CELLS + N_ITEMS  # 37

SIDE_NAMES = ("right", "below", "left", "above")
ACTION_DELTAS = ((-1, 0), (1, 0), (0, -1), (0, 1))
SIDE_DELTAS = ((0, 1), (1, 0), (0, -1), (-1, 0))  # offset (dr, dc) of the neighbour robot

DEFAULT_ROBOTS = (6, 6)
DEFAULT_ITEM_PROBABILITY = 0.02
DEFAULT_MAX_CYCLES = 100


def opposite(side: int) -> int:
    """The side of the neighbour's region that is shared with ``side`` of this one."""
    return (side + 2) % 4


def _item_cells() -> tuple[tuple[int, int], ...]:
    cells = []
    for side in range(4):
        for k in range(3):
            if side == 0:
                cells.append((k + 1, SIZE - 1))
            elif side == 1:
                cells.append((SIZE - 1, k + 1))
            elif side == 2:
                cells.append((k + 1, 0))
            else:
                cells.append((0, k + 1))
    return tuple(cells)


ITEM_CELLS = _item_cells()
"""Local (row, col) of item bit ``b``, in the documented bit order."""

ITEM_POS = np.array([i * SIZE + j for i, j in ITEM_CELLS], dtype=np.int64)
"""Local position of item bit ``b``."""

CORNERS = np.array([0, SIZE - 1, (SIZE - 1) * SIZE, N_CELLS - 1], dtype=np.int64)

SHELF_INDEX = np.full(N_CELLS, -1, dtype=np.int64)
"""Item bit of each local position, -1 for inner cells and corners."""
SHELF_INDEX[ITEM_POS] = np.arange(N_ITEMS)

POS_ONEHOT = np.eye(N_CELLS, dtype=np.uint8)
"""Row ``p``: the 25-bit one-hot of local position ``p`` (first part of the observation)."""

SHELF_ONEHOT = np.zeros((N_CELLS, N_ITEMS), dtype=np.uint8)
"""Row ``p``: the 12 "robot is on item cell b" bits of the d-set for a robot at ``p``."""
SHELF_ONEHOT[ITEM_POS, np.arange(N_ITEMS)] = 1


def _is_wall(i: int, j: int) -> bool:
    return i in (0, SIZE - 1) and j in (0, SIZE - 1)


def _build_moves() -> tuple[np.ndarray, np.ndarray]:
    move = np.zeros((N_CELLS, 4), dtype=np.int64)
    legal = np.zeros((N_CELLS, 4), dtype=bool)
    for p in range(N_CELLS):
        i, j = divmod(p, SIZE)
        on_shelf = SHELF_INDEX[p] >= 0
        for a, (di, dj) in enumerate(ACTION_DELTAS):
            ni, nj = i + di, j + dj
            ok = 0 <= ni < SIZE and 0 <= nj < SIZE and not _is_wall(ni, nj) and not _is_wall(i, j)
            if ok and on_shelf:
                # Only the inward move: it is the one that reaches an inner cell.
                ok = 1 <= ni <= SIZE - 2 and 1 <= nj <= SIZE - 2
            legal[p, a] = ok
            move[p, a] = ni * SIZE + nj if ok else p
    return move, legal


MOVE, LEGAL = _build_moves()
"""``MOVE[p, a]``: local position after action ``a`` from ``p`` (illegal -> ``p``);
``LEGAL[p, a]``: whether that move is legal."""

N_LEGAL = LEGAL.sum(axis=1)
LEGAL_ACTIONS = np.zeros((N_CELLS, 4), dtype=np.int64)
"""Row ``p`` starts with the legal actions of ``p`` in action order (for random moves)."""
for _p in range(N_CELLS):
    _acts = np.flatnonzero(LEGAL[_p])
    LEGAL_ACTIONS[_p, : len(_acts)] = _acts
N_LEGAL_SAFE = np.maximum(N_LEGAL, 1)  # corners (never occupied) have no legal move


def _build_distances() -> np.ndarray:
    dist = np.full((N_CELLS, N_CELLS), np.iinfo(np.int64).max // 2, dtype=np.int64)
    for src in range(N_CELLS):
        if src in CORNERS:
            continue
        dist[src, src] = 0
        queue = deque([src])
        while queue:
            p = queue.popleft()
            for a in range(4):
                if LEGAL[p, a]:
                    q = MOVE[p, a]
                    if dist[src, q] > dist[src, p] + 1:
                        dist[src, q] = dist[src, p] + 1
                        queue.append(q)
    return dist


DIST = _build_distances()
"""``DIST[p, q]``: number of moves from local position ``p`` to ``q`` (large if unreachable)."""


def _build_next_moves() -> np.ndarray:
    nxt = np.zeros((N_CELLS, N_ITEMS), dtype=np.int64)
    for p in range(N_CELLS):
        for b in range(N_ITEMS):
            target = ITEM_POS[b]
            if p == target:
                # Standing on the target (an item appeared under the robot): an illegal move
                # keeps it there, which collects the item at the next step.
                illegal = np.flatnonzero(~LEGAL[p])
                nxt[p, b] = illegal[0] if len(illegal) else 0
                continue
            best, best_d = 0, None
            for a in range(4):  # ties broken in action order up, down, left, right
                if LEGAL[p, a]:
                    d = DIST[MOVE[p, a], target]
                    if best_d is None or d < best_d:
                        best, best_d = a, d
            nxt[p, b] = best
    return nxt


NEXT_MOVE = _build_next_moves()
"""``NEXT_MOVE[p, b]``: first action of a shortest path from ``p`` to item cell ``b``."""


def _build_influence_class() -> np.ndarray:
    table = np.full((N_SOURCES, N_CELLS), NONE, dtype=np.int64)
    for side in range(N_SOURCES):
        for k in range(3):
            table[side, ITEM_POS[3 * opposite(side) + k]] = k
    return table


INFLUENCE_CLASS = _build_influence_class()
"""``INFLUENCE_CLASS[s, p]``: the class of source ``s`` when the neighbour on side ``s`` stands
at *its own* local position ``p``."""

INFLUENCE_CODE = 4 ** np.arange(N_SOURCES - 1, -1, -1, dtype=np.int64)
"""Weights that turn a u vector (4 classes in 0..3) into one code in 0..255."""


def _build_influence_mask() -> np.ndarray:
    # Bit 3*s + k is occupied iff u[s] == k.
    codes = np.arange(N_SOURCES**N_SOURCES)
    u = (codes[:, None] // INFLUENCE_CODE[None, :]) % N_SOURCES
    return np.eye(N_SOURCES, dtype=bool)[u][:, :, :3].reshape(len(codes), N_ITEMS)


INFLUENCE_MASK = _build_influence_mask()
"""``INFLUENCE_MASK[code]``: the 12 cells occupied by neighbours for the u with that code."""


# ----------------------------------------------------------------------------- names, spec


def robot_name(index: int) -> str:
    return f"robot_{index}"


def check_robots(robots) -> tuple[int, int]:
    """Validate the ``robots=(rows, cols)`` option."""
    try:
        rows, cols = robots
    except (TypeError, ValueError):
        raise BadInput(f"robots must be a pair (rows, cols), got {robots!r}") from None
    for v in (rows, cols):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise BadInput(f"robots must be two positive ints (rows, cols), got {robots!r}")
    return int(rows), int(cols)


def check_options(
    item_probability=DEFAULT_ITEM_PROBABILITY, item_lifetime=None, max_cycles=DEFAULT_MAX_CYCLES
) -> tuple[float, int | None, int]:
    """Validate the item/episode options shared by the GS and the LS."""
    if isinstance(item_probability, bool) or not isinstance(
        item_probability, (int, float, np.integer, np.floating)
    ):
        raise BadInputType(f"item_probability must be a number in [0, 1], got {item_probability!r}")
    if not 0.0 <= float(item_probability) <= 1.0:
        raise BadInput(f"item_probability must be in [0, 1], got {item_probability!r}")
    if item_lifetime is not None:
        if isinstance(item_lifetime, bool) or not isinstance(item_lifetime, (int, np.integer)):
            raise BadInputType(f"item_lifetime must be None or a positive int, got {item_lifetime!r}")
        if item_lifetime < 1:
            raise BadInput(f"item_lifetime must be None or >= 1, got {item_lifetime!r}")
        item_lifetime = int(item_lifetime)
    if isinstance(max_cycles, bool) or not isinstance(max_cycles, (int, np.integer)):
        raise BadInputType(f"max_cycles must be a positive int, got {max_cycles!r}")
    if max_cycles < 1:
        raise BadInput(f"max_cycles must be >= 1, got {max_cycles!r}")
    return float(item_probability), item_lifetime, int(max_cycles)


GS_ONLY_OPTIONS = ("learners", "render_mode", "scripted_learners")
"""GS options that do not change a region; the region-level factories accept and ignore
them so that generic code can pass the GS's options unchanged."""


def drop_gs_only_options(options: dict) -> dict:
    """``options`` without :data:`GS_ONLY_OPTIONS` (anything else is passed on and checked)."""
    return {k: v for k, v in options.items() if k not in GS_ONLY_OPTIONS}


def possible_agents(robots=DEFAULT_ROBOTS, **options) -> list[str]:
    """All robot ids ``robot_0 .. robot_{R*C-1}``, row-major (other GS options are checked
    and otherwise ignored)."""
    check_options(**drop_gs_only_options(options))
    rows, cols = check_robots(robots)
    return [robot_name(i) for i in range(rows * cols)]


def agent_index(agent: str, robots=DEFAULT_ROBOTS) -> int:
    """Index of ``agent`` (``"robot_<i>"``); ValueError naming the valid ids otherwise."""
    rows, cols = check_robots(robots)
    n = rows * cols
    if isinstance(agent, str) and agent.startswith("robot_"):
        tail = agent[len("robot_"):]
        if tail.isdigit() and str(int(tail)) == tail and int(tail) < n:
            return int(tail)
    raise BadInput(
        f"unknown agent {agent!r}; warehouse_v0 with robots={rows, cols} has robot_0..robot_{n - 1}"
    )


ITEM_NAMES = tuple(
    f"item_{SIDE_NAMES[b // 3]}_{b % 3}" for b in range(N_ITEMS)
)
ON_ITEM_NAMES = tuple(f"on_{name}" for name in ITEM_NAMES)
POSITION_NAMES = tuple(f"pos_{i}_{j}" for i in range(SIZE) for j in range(SIZE))


def region_spec(
    agent: str = "robot_20",
    robots=DEFAULT_ROBOTS,
    item_probability=DEFAULT_ITEM_PROBABILITY,
    item_lifetime=None,
    max_cycles=DEFAULT_MAX_CYCLES,
    **gs_only,
) -> RegionSpec:
    """The :class:`RegionSpec` of ``agent``'s region (identical layout for every region).

    d-set ``"dset"`` (24 bits): the 12 item bits, then 12 bits "the robot stands on item cell
    b". d-set ``"full"`` (37 bits): the observation (25-bit one-hot position + 12 item bits).
    The GS-only options (``learners``, ``render_mode``, ``scripted_learners``) are ignored;
    any other unknown option is a TypeError.
    """
    unknown = sorted(set(gs_only) - set(GS_ONLY_OPTIONS))
    if unknown:
        raise BadInputType(f"unknown option(s) {unknown} for {DOMAIN_ID} region_spec")
    robots = check_robots(robots)
    agent_index(agent, robots)
    item_probability, item_lifetime, max_cycles = check_options(
        item_probability, item_lifetime, max_cycles
    )
    return RegionSpec(
        domain=DOMAIN_ID,
        agent=agent,
        influence_names=SIDE_NAMES,
        influence_classes=(4, 4, 4, 4),
        dset_names={"dset": ITEM_NAMES + ON_ITEM_NAMES, "full": POSITION_NAMES + ITEM_NAMES},
        params={
            "robots": list(robots),
            "item_probability": item_probability,
            "item_lifetime": item_lifetime,
            "max_cycles": max_cycles,
        },
    )


# ----------------------------------------------------------------------------- item process
# The GS (global array of shelf cells) and the LS (n_envs x 12 region cells) both advance
# their items with these two functions, so the two simulators share one definition of the
# order of operations:
#   1. robots move (the learner by its action, the others by their controllers / u_t);
#   2. every robot now on an item cell collects it: its reward is the item's age divided by
#      the largest age of the items active in its region before any collection of this step
#      (collecting the oldest pays 1.0); if two robots reach the same shared item together,
#      both are credited (each with its own region's normalisation);
#   3. collected items disappear; the remaining ones age by one step; with item_lifetime=L
#      an item older than L disappears (it was visible in exactly L observations);
#   4. every empty shelf cell gets a new item (age 1) with probability item_probability.
# An item's age is the number of observations it has been visible in, so an item that
# appeared at the end of step t has age 1 when collected in step t+1.


def collect_reward(own_age: np.ndarray, max_age: np.ndarray) -> np.ndarray:
    """Reward of robots standing on cells with item ages ``own_age`` (0 = no item), in
    regions whose oldest item (before this step's collections) has age ``max_age``."""
    # own_age == 0 (no item) gives 0; max(., 1) only guards regions without items.
    return own_age / np.maximum(max_age, 1)


def advance_items(ages: np.ndarray, occupied, appear: np.ndarray, item_lifetime) -> int:
    """Steps 3-4 above, in place on the int array ``ages``.

    Args:
        occupied: the cells with a robot after the move: a bool mask like ``ages`` or an
            index array into it.
        appear: bool mask like ``ages``: the cells whose appearance draw fired.
        item_lifetime: None, or the number of steps after which an item vanishes.

    Returns:
        the number of items collected (removed by a robot).
    """
    before = np.count_nonzero(ages)
    ages[occupied] = 0
    collected = before - np.count_nonzero(ages)
    _age_and_appear(ages, appear, item_lifetime)
    return collected


def advance_items_counted(ages: np.ndarray, occupied, appear: np.ndarray, item_lifetime) -> tuple[int, int]:
    """:func:`advance_items`, also returning the summed ages of the items collected."""
    before, age_before = np.count_nonzero(ages), int(ages.sum())
    ages[occupied] = 0
    collected = before - np.count_nonzero(ages)
    collected_age = age_before - int(ages.sum())
    _age_and_appear(ages, appear, item_lifetime)
    return collected, collected_age


def _age_and_appear(ages: np.ndarray, appear: np.ndarray, item_lifetime) -> None:
    ages += ages > 0
    if item_lifetime is not None:
        ages[ages > item_lifetime] = 0
    ages += appear & (ages == 0)


# ----------------------------------------------------------------------------- scalar tables
# Plain-Python versions of the tables above for the single-copy (n_envs=1) local simulator,
# where numpy's per-call overhead on 12-element arrays costs more than the work itself. An
# item set is then an int bitmask: bit b set <=> item cell b holds an item.

MOVE_LIST = MOVE.ravel().tolist()
"""``MOVE_LIST[4 * p + a]`` == ``MOVE[p, a]`` as a Python int."""
SHELF_INDEX_LIST = SHELF_INDEX.tolist()
"""``SHELF_INDEX_LIST[p]`` == ``SHELF_INDEX[p]`` as a Python int (-1: not an item cell)."""
INFLUENCE_BITS = [int(m) for m in INFLUENCE_MASK @ (1 << np.arange(N_ITEMS))]
"""``INFLUENCE_BITS[code]``: :data:`INFLUENCE_MASK` ``[code]`` as an item bitmask."""
BIT_INDICES = tuple(tuple(b for b in range(N_ITEMS) if m >> b & 1) for m in range(1 << N_ITEMS))
"""``BIT_INDICES[mask]``: the item bits set in ``mask``, ascending."""
ITEM_BITS_U8 = ((np.arange(1 << N_ITEMS)[:, None] >> np.arange(N_ITEMS)) & 1).astype(np.uint8)
"""``ITEM_BITS_U8[mask]``: the 12 item bits of ``mask`` (observation/d-set order)."""
