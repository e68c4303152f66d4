"""The warehouse global simulator (GS), a PettingZoo ParallelEnv."""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils import parallel_to_aec
from pettingzoo.utils.conversions import parallel_to_aec_wrapper

from ials_zoo.core.region import INFLUENCE_KEY, RegionSpec
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.utils import check_reset_options, check_seed
from ials_zoo.warehouse import regions as R
from ials_zoo.warehouse.render import render_ansi, render_rgb

# Flat copies of the region tables: 1-d fancy indexing is cheaper than 2-d in the hot loop.
_MOVE_FLAT = R.MOVE.ravel()
_LEGAL_FLAT = R.LEGAL_ACTIONS.ravel()
_N_LEGAL_F = R.N_LEGAL_SAFE.astype(np.float64)
_NEXT_FLAT = R.NEXT_MOVE.ravel()
_INFLUENCE_FLAT = R.INFLUENCE_CLASS.ravel()
_PLAIN_INT_TYPES = frozenset([int, np.int64, np.int32])


class WarehouseEnv(ParallelEnv):
    """Warehouse commissioning (``warehouse_v0``): robots fetch items from shelves (SPEC §1).

    The floor has ``(4R+1) x (4C+1)`` cells for ``robots=(R, C)`` (25 x 25 with the default
    6 x 6 robots). Robot ``robot_{r*C+c}`` owns the 5 x 5 region with rows ``4r..4r+4`` and
    columns ``4c..4c+4``; the 12 border cells without the corners are shelf (item) cells,
    shared with the neighbouring region on that side. See :mod:`ials_zoo.warehouse.regions`
    for the layout, the item-bit order and the influence sources.

    Agents: the *learners* (``learners=None``: all robots). Every other robot is part of the
    world but driven by the scripted controller (shortest path to the oldest item of its own
    region, ties to the lowest item bit; a uniformly random legal move when the region has no
    item). With ``scripted_learners=True`` the learners stay agents (observed, rewarded,
    reported in ``infos``) but their actions are ignored and the scripted controller drives
    them -- used to score the scripted reference policy.

    Action: ``Discrete(4)``: 0 = up, 1 = down, 2 = left, 3 = right. A robot never leaves its
    region and never enters a corner; on a shelf cell only the move back inward is legal. An
    illegal move leaves the robot in place (no error). Actions must be ints (Python or numpy,
    0-d integer arrays accepted) in 0..3, one for each live agent.

    Observation: ``Box(0, 1, (37,), float32)``: a 25-bit one-hot of the robot's local
    position (row-major), then the 12 item bits of its region in the documented order.

    Reward: when the robot collects an item (moves onto, or stays on, a cell with an item),
    that item's age divided by the largest age of the items active in its region at that
    moment (before this step's collections): 1.0 for the oldest item, less for a younger one;
    0 otherwise. Ages count the observations an item has been visible in (1 for a new item).
    If two robots reach a shared item in the same step, both collect it (both are rewarded).

    Dynamics of one step: all robots move at once; robots on item cells collect them; the
    remaining items age; with ``item_lifetime=L`` an item uncollected for L steps vanishes
    (the memory variant, paper §5.4, L = 8); every empty shelf cell gets a new item with
    probability ``item_probability`` (0.02). At reset robots stand at their region's centre
    and each shelf cell holds a new item with probability ``item_probability``.

    Episode end: after ``max_cycles`` (100) steps every agent is truncated
    (``truncations`` True, ``terminations`` False) and ``agents`` becomes empty.

    Infos (for every learner, see :mod:`ials_zoo.core.region`), the same keys, shapes and
    dtypes at reset and after every step: ``"dset"`` (24 uint8: the 12 item bits and 12 "robot
    is on item cell b" bits), ``"dset_full"`` (37 uint8, the observation) and ``"influence"``
    (int64, shape (4,)): for each neighbour (right, below, left, above), which of the 3 shelf
    cells shared with it the neighbour stands on after the move (0..2), or 3 = none (at reset,
    before any move: all 3).

    State (``state()``, ``state_space``, for centralised critics): ``Box(0, 1, float32)`` of
    ``25 * n_robots + n_shelf_cells`` entries (1,152 for 6 x 6 robots): every robot's 25-bit
    local-position one-hot (robot order), then every shelf cell's item age divided by
    ``max_cycles`` (0 = no item; shelf cells in row-major floor order).

    Render modes: ``"rgb_array"`` (an image of the floor: region borders on the shelf lines,
    items shaded from yellow (new) to dark orange (old), scripted robots blue, learners
    magenta inside a red region outline), ``"ansi"`` (text) and ``"human"`` (the text view,
    printed to the terminal at every ``render()``; returns None).

    Seeding: ``reset(seed=s)`` (``s`` an int >= 0) makes the episode and the following
    unseeded resets reproducible; ``reset()`` continues the current random stream.

    Options: ``learners``, ``item_probability=0.02``, ``max_cycles=100``,
    ``item_lifetime=None``, ``robots=(6, 6)``, ``render_mode=None``,
    ``scripted_learners=False`` (see above). Any other keyword (``**unknown`` in the signature)
    is refused, naming the valid options.

    Version history: v0 -- first version (SPEC §1).
    """

    metadata = {
        "name": "warehouse_v0",
        "render_modes": ["rgb_array", "ansi", "human"],
        "render_fps": 5,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        learners=None,
        item_probability: float = R.DEFAULT_ITEM_PROBABILITY,
        max_cycles: int = R.DEFAULT_MAX_CYCLES,
        item_lifetime: int | None = None,
        robots=R.DEFAULT_ROBOTS,
        render_mode: str | None = None,
        scripted_learners: bool = False,
        **unknown,
    ):
        if unknown:
            raise BadInputType(
                f"unknown option(s) {sorted(unknown)} for {R.DOMAIN_ID}; valid options: learners, item_probability, "
                "max_cycles, item_lifetime, robots, render_mode, scripted_learners"
            )
        self.robots = R.check_robots(robots)
        self.item_probability, self.item_lifetime, self.max_cycles = R.check_options(
            item_probability, item_lifetime, max_cycles
        )
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise BadInput(
                f"unknown render_mode {render_mode!r}; expected None or one of "
                f"{self.metadata['render_modes']}"
            )
        self.render_mode = render_mode
        if not isinstance(scripted_learners, (bool, np.bool_)):
            raise BadInputType(f"scripted_learners must be a bool, got {scripted_learners!r}")
        self.scripted_learners = bool(scripted_learners)

        rows, cols = self.robots
        self.n_robots = n = rows * cols
        all_agents = R.possible_agents(self.robots)
        if learners is None:
            learner_idx = list(range(n))
        else:
            if isinstance(learners, str) or not hasattr(learners, "__iter__"):
                raise BadInputType(f"learners must be None or a list of agent ids, got {learners!r}")
            learner_idx = [R.agent_index(a, self.robots) for a in learners]
            if not learner_idx:
                raise BadInput("learners must name at least one robot (None = all robots)")
            if len(set(learner_idx)) != len(learner_idx):
                raise BadInput(f"learners has duplicates: {list(learners)!r}")
            learner_idx = sorted(learner_idx)
        self._learner_idx = np.array(learner_idx, dtype=np.int64)
        self.possible_agents = [all_agents[i] for i in learner_idx]
        self.agents = []
        self._n_learners = len(learner_idx)

        self._obs_space = spaces.Box(0.0, 1.0, (R.OBS_SIZE,), np.float32)
        self.state_space = spaces.Box(0.0, 1.0, (R.N_CELLS * n + self._n_shelf(),), np.float32)
        self._act_space = spaces.Discrete(4)
        self.observation_spaces = {a: self._obs_space for a in self.possible_agents}
        self.action_spaces = {a: spaces.Discrete(4) for a in self.possible_agents}

        self._build_geometry()
        self._rng: np.random.Generator | None = None
        self._pos = np.full(n, R.CENTRE, dtype=np.int64)
        self._ages = np.zeros(self.n_shelf_cells + 1, dtype=np.int64)
        self._cycle = 0
        self.episode_returns = np.zeros(n)
        self.items_collected = 0
        self._collected_age = 0
        self._items_waiting = 0
        self._record_metrics = False

    # ------------------------------------------------------------------ geometry

    def _n_shelf(self) -> int:
        rows, cols = self.robots
        h, w = 4 * rows + 1, 4 * cols + 1
        return h * w - ((h + 3) // 4) * ((w + 3) // 4) - ((h - 1) * 3 // 4) * ((w - 1) * 3 // 4)

    def _build_geometry(self) -> None:
        rows, cols = self.robots
        n = self.n_robots
        self.height, self.width = 4 * rows + 1, 4 * cols + 1
        ii, jj = np.mgrid[0 : self.height, 0 : self.width]
        shelf = (ii % 4 == 0) ^ (jj % 4 == 0)
        self.n_shelf_cells = int(shelf.sum())
        cell_id = np.full((self.height, self.width), -1, dtype=np.int64)
        cell_id[shelf] = np.arange(self.n_shelf_cells)
        self._shelf_rc = np.argwhere(shelf)  # (G, 2) floor coordinates of shelf cell g
        r0 = 4 * (np.arange(n) // cols)
        c0 = 4 * (np.arange(n) % cols)
        self._origin = np.stack([r0, c0], axis=1)
        item_rc = np.array(R.ITEM_CELLS)
        self._region_cells = cell_id[r0[:, None] + item_rc[:, 0], c0[:, None] + item_rc[:, 1]]
        assert (self._region_cells >= 0).all()
        nb = np.full((n, R.N_SOURCES), n, dtype=np.int64)  # n = "no neighbour" (dummy robot)
        rr, cc = np.arange(n) // cols, np.arange(n) % cols
        for s, (dr, dc) in enumerate(R.SIDE_DELTAS):
            ok = (0 <= rr + dr) & (rr + dr < rows) & (0 <= cc + dc) & (cc + dc < cols)
            nb[ok, s] = ((rr + dr) * cols + cc + dc)[ok]
        self._learner_cells = self._region_cells[self._learner_idx]
        self._learner_nb = nb[self._learner_idx]
        # _cell_of[25*n + p]: the shelf cell robot n stands on at local position p, or the
        # dummy cell G (never holds an item) when p is not a shelf cell.
        shelf_bit = np.where(R.SHELF_INDEX >= 0, R.SHELF_INDEX, R.N_ITEMS)
        padded = np.concatenate(
            [self._region_cells, np.full((n, 1), self.n_shelf_cells, dtype=np.int64)], axis=1
        )
        self._cell_of = padded[:, shelf_bit].ravel()
        self._row25 = np.arange(n) * R.N_CELLS
        self._side25 = np.arange(R.N_SOURCES) * R.N_CELLS
        self._pos_ext = np.full(n + 1, R.CENTRE, dtype=np.int64)  # last = absent neighbour

    # ------------------------------------------------------------------ API

    def observation_space(self, agent):
        try:
            return self.observation_spaces[agent]
        except KeyError:
            raise BadInput(f"unknown agent {agent!r}; agents: {self.possible_agents}") from None

    def action_space(self, agent):
        try:
            return self.action_spaces[agent]
        except KeyError:
            raise BadInput(f"unknown agent {agent!r}; agents: {self.possible_agents}") from None

    def region_spec(self, agent: str) -> RegionSpec:
        """The :class:`RegionSpec` of ``agent``'s region under this env's options."""
        return R.region_spec(
            agent,
            robots=self.robots,
            item_probability=self.item_probability,
            item_lifetime=self.item_lifetime,
            max_cycles=self.max_cycles,
        )

    @property
    def learner_indices(self) -> np.ndarray:
        """Robot index (row-major) of each agent, in ``possible_agents`` order."""
        return self._learner_idx.copy()

    def state(self) -> np.ndarray:
        """The global state (see the class docstring), float32."""
        pos = R.POS_ONEHOT[self._pos].ravel()
        ages = np.minimum(self._ages[:-1] / self.max_cycles, 1.0)
        return np.concatenate([pos, ages]).astype(np.float32)

    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode. ``seed`` makes it reproducible; ``options``: none are known (PettingZoo's API)."""
        check_reset_options(options)
        seed = check_seed(seed)
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        self._pos = np.full(self.n_robots, R.CENTRE, dtype=np.int64)
        self._ages = np.zeros(self.n_shelf_cells + 1, dtype=np.int64)
        self._ages[:-1][self._rng.random(self.n_shelf_cells) < self.item_probability] = 1
        self._cycle = 0
        self.episode_returns = np.zeros(self.n_robots)
        self.items_collected = 0
        self._collected_age = 0
        self._items_waiting = 0
        self.agents = list(self.possible_agents)
        obs, dset, full = self._learner_views()
        none = np.full(R.N_SOURCES, R.NONE, dtype=np.int64)
        infos = {
            a: {INFLUENCE_KEY: none.copy(), "dset": dset[i], "dset_full": full[i]}
            for i, a in enumerate(self.agents)
        }
        return dict(zip(self.agents, obs)), infos

    def step(self, actions: dict):
        """Advance all robots by one step; see the class docstring."""
        if not self.agents:
            raise RuntimeError("the episode is over (or reset() was never called); call reset()")
        learner_actions = self._parse_actions(actions)
        pos = self._pos
        ages = self._ages  # index G is a dummy cell that never holds an item
        region_ages = ages[self._region_cells]
        max_age = region_ages.max(axis=1)

        # Scripted controller for every robot (cheaper than selecting the scripted ones);
        # the random draws are always made so that the random stream does not depend on the
        # learners' actions.
        rand = self._rng.random(self.n_robots)
        random_act = _LEGAL_FLAT[pos * 4 + (rand * _N_LEGAL_F[pos]).astype(np.int64)]
        to_oldest = _NEXT_FLAT[pos * R.N_ITEMS + region_ages.argmax(axis=1)]
        act = np.where(max_age > 0, to_oldest, random_act)
        if learner_actions is not None:
            act[self._learner_idx] = learner_actions

        pos = _MOVE_FLAT[pos * 4 + act]
        self._pos = pos
        cell = self._cell_of[self._row25 + pos]  # the dummy cell for robots off the shelves
        reward = R.collect_reward(ages[cell], max_age)
        appear = self._rng.random(self.n_shelf_cells + 1) < self.item_probability
        appear[-1] = False
        if self._record_metrics:  # two more sums per step: only when an evaluation asks
            collected, collected_age = R.advance_items_counted(ages, cell, appear, self.item_lifetime)
            self._collected_age += collected_age
            self._items_waiting += np.count_nonzero(ages)
        else:
            collected = R.advance_items(ages, cell, appear, self.item_lifetime)
        self.items_collected += collected
        self.episode_returns += reward
        self._cycle += 1

        agents = self.agents
        obs, dset, full = self._learner_views()
        self._pos_ext[:-1] = pos
        influence = _INFLUENCE_FLAT[self._side25 + self._pos_ext[self._learner_nb]]
        rewards = dict(zip(agents, reward[self._learner_idx].tolist()))
        done = self._cycle >= self.max_cycles
        terminations = dict.fromkeys(agents, False)
        truncations = dict.fromkeys(agents, done)
        infos = {
            a: {INFLUENCE_KEY: influence[i], "dset": dset[i], "dset_full": full[i]}
            for i, a in enumerate(agents)
        }
        observations = dict(zip(agents, obs))
        if done:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _learner_views(self):
        pos = self._pos[self._learner_idx]
        items = (self._ages[self._learner_cells] > 0).view(np.uint8)
        full = np.concatenate([R.POS_ONEHOT[pos], items], axis=1)
        dset = np.concatenate([items, R.SHELF_ONEHOT[pos]], axis=1)
        return full.astype(np.float32), dset, full

    def _parse_actions(self, actions) -> np.ndarray | None:
        if not isinstance(actions, dict):
            raise BadInputType(f"actions must be a dict {{agent: action}}, got {type(actions).__name__}")
        agents = self.agents
        if self.scripted_learners:
            unknown = [a for a in actions if a not in self.action_spaces]
            if unknown:
                raise BadInput(f"actions for unknown agents {unknown}; agents: {agents}")
            return None
        try:
            values = [actions[a] for a in agents]
        except KeyError:
            values = None
        if values is None or len(actions) != len(agents):
            missing = [a for a in agents if a not in actions]
            unknown = [a for a in actions if a not in agents]
            raise BadInput(
                f"actions must have exactly one entry per live agent; missing: {missing}, "
                f"unknown or finished agents: {unknown}"
            )
        if not _PLAIN_INT_TYPES.issuperset(map(type, values)):
            # bools, 0-d arrays, floats, ...: np.asarray would silently turn True into 1.
            for a, v in zip(agents, values):
                _check_action(a, v)
        try:
            arr = np.asarray(values)
        except ValueError:
            arr = np.empty(0)
        if arr.shape != (len(agents),) or arr.dtype.kind not in "iu":
            for a, v in zip(agents, values):
                _check_action(a, v)
            raise BadInputType(f"bad actions {actions!r}; expected one int in 0..3 per agent")
        arr = arr.astype(np.int64, copy=False)
        if np.count_nonzero(arr & -4):  # any value outside 0..3 (negative ones included)
            for a, v in zip(agents, values):
                _check_action(a, v)
        return arr

    # ------------------------------------------------------------------ state access

    def get_region_state(self, agent: str) -> tuple[int, np.ndarray]:
        """``(local position, item ages (12,))`` of ``agent``'s region (a copy; age 0 = no item)."""
        i = R.agent_index(agent, self.robots)
        return int(self._pos[i]), self._ages[self._region_cells[i]].copy()

    def set_region_state(self, agent: str, position: int | None = None, item_ages=None) -> None:
        """Overwrite ``agent``'s local position and/or its region's 12 item ages (for tests
        and debugging; shared shelf cells change in the neighbours' regions too). The
        observations reflect the change from the next step on."""
        i = R.agent_index(agent, self.robots)
        if position is not None:
            if position not in range(R.N_CELLS) or position in R.CORNERS:
                raise BadInput(f"position must be a non-corner local position 0..24, got {position!r}")
            self._pos[i] = position
        if item_ages is not None:
            ages = np.asarray(item_ages)
            if ages.shape != (R.N_ITEMS,) or ages.dtype.kind not in "iu" or (ages < 0).any():
                raise BadInput(f"item_ages must be 12 non-negative ints, got {item_ages!r}")
            self._ages[self._region_cells[i]] = ages

    def robot_positions(self) -> np.ndarray:
        """Floor coordinates (row, col) of every robot, shape (n_robots, 2)."""
        return self._origin + np.stack([self._pos // R.SIZE, self._pos % R.SIZE], axis=1)

    def enable_metrics(self) -> None:
        """Record the item ages and waiting items from now on, for :meth:`episode_metrics`
        (off by default: training does not pay for them)."""
        self._record_metrics = True

    def episode_metrics(self) -> dict[str, float]:
        """The physical figures of the episode so far, over all robots: items collected per
        robot, the mean age (steps on the shelf) of the items collected, and the items waiting
        on the shelves per robot, averaged over the steps."""
        steps = max(self._cycle, 1)
        return {"items_per_robot": self.items_collected / self.n_robots,
                "age_at_collection": self._collected_age / self.items_collected if self.items_collected else 0.0,
                "items_waiting": self._items_waiting / steps / self.n_robots}

    def item_ages_floor(self) -> np.ndarray:
        """Item ages on the whole floor, shape (height, width) (0 = no item)."""
        floor = np.zeros((self.height, self.width), dtype=np.int64)
        floor[self._shelf_rc[:, 0], self._shelf_rc[:, 1]] = self._ages[:-1]
        return floor

    # ------------------------------------------------------------------ rendering

    def render(self):
        """An RGB image (``"rgb_array"``) or a text view (``"ansi"``) of the floor."""
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; returning None")
            return None

        if self.render_mode == "ansi":
            return render_ansi(self)
        if self.render_mode == "human":
            print(render_ansi(self), flush=True)
            return None
        return render_rgb(self)

    def close(self):
        pass


def _check_action(agent: str, value) -> None:
    if isinstance(value, (bool, np.bool_)):
        raise BadInputType(f"action for {agent!r} must be an int in 0..3, got bool {value!r}")
    if isinstance(value, np.ndarray):
        if value.shape != ():
            raise BadInputType(
                f"action for {agent!r} must be a scalar int in 0..3, got an array of shape {value.shape}"
            )
        value = value[()]
    if not isinstance(value, (int, np.integer)):
        raise BadInputType(
            f"action for {agent!r} must be an int in 0..3, got {type(value).__name__} {value!r}"
        )
    if not 0 <= value <= 3:
        raise BadInput(f"action for {agent!r} out of range: {value!r}; expected 0..3")


def raw_env(**options):
    """The AEC version of the GS without wrappers (PettingZoo's ``raw_env`` convention)."""
    return parallel_to_aec_wrapper(WarehouseEnv(**options))


def parallel_env(**options) -> WarehouseEnv:
    """The parallel GS (see :class:`WarehouseEnv` for the options)."""
    return WarehouseEnv(**options)


def env(**options):
    """The AEC version of the GS with PettingZoo's order-enforcing wrapper
    (``pettingzoo.utils.parallel_to_aec``)."""
    return parallel_to_aec(WarehouseEnv(**options))
