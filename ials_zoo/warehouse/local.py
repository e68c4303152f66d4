"""The warehouse local simulator (LS): robots' 5 x 5 regions, many copies in one numpy program."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ials_zoo.core.local import LocalSimulator, agent_list, check_n_envs
from ials_zoo.core.streams import BLOCK, CopyStreams
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.warehouse import regions as R

_MOVE_FLAT = R.MOVE.ravel()
_MOVE_L = R.MOVE_LIST
_SHELF_L = R.SHELF_INDEX_LIST
_INFL_BITS = R.INFLUENCE_BITS
_BITS = R.BIT_INDICES
_ITEM_U8 = R.ITEM_BITS_U8
_POW2 = 1 << np.arange(R.N_ITEMS, dtype=np.int64)
_ALL_ITEMS = (1 << R.N_ITEMS) - 1
_DRAW_STEPS = BLOCK  # appearance draws fetched per rng call by the single-copy path (as CopyStreams)

# (position, item bitmask) -> read-only (obs float32 (37,), {"dset": (1, 24), "full": (1, 37)}).
# Filled on demand by the single-copy path; emptied when it reaches _VIEW_CACHE_SIZE entries
# (~1 kB each) so that long runs visiting many item patterns stay bounded in memory.
_VIEW_CACHE: dict = {}
_VIEW_CACHE_SIZE = 16384


def _single_views(key: int):
    views = _VIEW_CACHE.get(key)
    if views is None:
        pos, items = divmod(key, 1 << R.N_ITEMS)
        bits = _ITEM_U8[items]
        full = np.concatenate([R.POS_ONEHOT[pos], bits])[None]
        dset = np.concatenate([bits, R.SHELF_ONEHOT[pos]])[None]
        obs = full[0].astype(np.float32)
        for a in (full, dset, obs):
            a.flags.writeable = False
        if len(_VIEW_CACHE) >= _VIEW_CACHE_SIZE:
            _VIEW_CACHE.clear()
        views = _VIEW_CACHE[key] = (obs, {"dset": dset, "full": full})
    return views


class WarehouseLocalSimulator(LocalSimulator):
    """``n_envs`` copies of the region of each of ``agents``, stepped together in one numpy
    program (SPEC §1, paper §4). Every region has the same layout and rules, so the rows differ
    only by their state (and, through the AIP, by what their neighbours do).

    Each step, in every copy: the robot moves by its action; the influence sources ``u_t``
    (one class per side: right, below, left, above; 0..2 = the neighbour stands on that
    side's shared shelf cell k, 3 = none) place the 4 neighbours; the robot collects the item
    under it (reward = its age / the largest age in the region, as in the GS) and an item
    under a neighbour disappears; items age (and expire with ``item_lifetime``); new items
    appear on empty shelf cells with probability ``item_probability``. This is the GS's order
    of operations, using the same functions (:func:`regions.collect_reward`,
    :func:`regions.advance_items`), so a GS region stepped with its true ``u_t`` and the same
    appearance draws gives the same observations, rewards and d-sets.

    Observations are ``float32 (n_copies, 37)`` as in the GS; d-sets are uint8,
    ``{"dset": (n_copies, 24), "full": (n_copies, 37)}``. At reset every robot is at its
    region's centre and each shelf cell holds a new item with probability
    ``item_probability`` (as in the GS).

    With a single copy the state is kept in plain Python ints (position, item bitmask, list of
    ages) and stepped without numpy (:meth:`step_single`, used by :class:`IALSEnv`): numpy's
    per-call overhead on 12-element arrays dominates a single copy's step. It draws the same
    random numbers in the same order (fetched ``64`` steps at a time) and gives the same
    results as the array path.

    Randomness (the item appearances) comes from one stream per (agent, copy)
    (:class:`ials_zoo.core.streams.CopyStreams`): a copy of ``robot_20`` behaves the same in a
    batch of every robot's regions as alone.
    """

    def __init__(
        self,
        agents="robot_20",
        n_envs: int = 1,
        item_probability: float = R.DEFAULT_ITEM_PROBABILITY,
        max_cycles: int = R.DEFAULT_MAX_CYCLES,
        item_lifetime: int | None = None,
        robots=R.DEFAULT_ROBOTS,
    ):
        self.n_envs = check_n_envs(n_envs)
        self.agents = agent_list(agents)
        self.regions = tuple(
            R.region_spec(a, robots=robots, item_probability=item_probability,
                          item_lifetime=item_lifetime, max_cycles=max_cycles)
            for a in self.agents
        )
        params = self.regions[0].params
        self.item_probability = params["item_probability"]
        self.item_lifetime = params["item_lifetime"]
        self.max_cycles = params["max_cycles"]
        self.observation_space = spaces.Box(0.0, 1.0, (R.OBS_SIZE,), np.float32)
        self.action_space = spaces.Discrete(4)
        # item-appearance draws: one stream per (agent, copy) (ials_zoo.core.streams)
        self._streams = CopyStreams(self.agents, self.n_envs, R.N_ITEMS)
        n = self.n_copies
        self._pos = np.full(n, R.CENTRE, dtype=np.int64)
        self._ages = np.zeros((n, R.N_ITEMS), dtype=np.int64)
        # Single-copy state (used iff self._scalar): position, item bitmask, 12 ages.
        self._scalar = n == 1
        self._p = R.CENTRE
        self._items = 0
        self._age = [0] * R.N_ITEMS
        self._draws: list[int] = []  # pending appearance bitmasks, next one last

    @property
    def agent(self) -> str:
        """The agent of a single-agent local simulator."""
        return self.region.agent

    def reset(self, seed: int | None = None):
        if seed is not None:
            self._streams.seed(seed)
            self._draws = []
        if self._scalar:
            self._set_single(R.CENTRE, self._next_draw())
            return self.observe()
        self._pos = np.full(self.n_copies, R.CENTRE, dtype=np.int64)
        self._ages = (self._streams.next() < self.item_probability).astype(np.int64)
        return self._views()

    # ------------------------------------------------------------------ single copy

    @property
    def supports_step_single(self) -> bool:
        """Whether :meth:`step_single` / :meth:`observe_single` may be used (one copy)."""
        return self._scalar

    def _next_draw(self) -> int:
        """The next ``rng.random(12) < item_probability`` draw as a bitmask.

        Draws ``_DRAW_STEPS`` steps' numbers per rng call: the same doubles, in the same
        order, as one ``rng.random((1, 12))`` per step.
        """
        draws = self._draws
        if not draws:
            hits = self._streams.generator(0).random((_DRAW_STEPS, R.N_ITEMS)) < self.item_probability
            draws.extend((hits @ _POW2)[::-1].tolist())
        return draws.pop()

    def _set_single(self, pos: int, items: int, ages=None) -> None:
        self._p = pos
        self._items = items
        self._age = [(items >> b) & 1 for b in range(R.N_ITEMS)] if ages is None else ages

    def step_single(self, action: int, u0: int, u1: int, u2: int, u3: int) -> float:
        """Advance the single copy by one step; returns the reward.

        The fast form of ``step([action], [[u0, u1, u2, u3]])``: Python ints in 0..3 (not
        checked here: callers check them), the observation and d-sets of the new state
        come from :meth:`observe`.
        """
        age = self._age
        max_age = max(age)
        p = _MOVE_L[self._p * 4 + action]
        self._p = p
        b = _SHELF_L[p]
        occupied = _INFL_BITS[u0 * 64 + u1 * 16 + u2 * 4 + u3]
        if b >= 0:
            # regions.collect_reward: own age / max(largest age before collection, 1).
            reward = age[b] / (max_age if max_age > 1 else 1)
            occupied |= 1 << b
        else:
            reward = 0.0
        self._advance_single(occupied, self._next_draw())
        return reward

    def _advance_single(self, occupied: int, appear: int) -> None:
        """:func:`regions.advance_items` on the bitmask state."""
        age = self._age
        items = self._items
        gone = items & occupied
        if gone:
            for i in _BITS[gone]:
                age[i] = 0
            items ^= gone
        lifetime = self.item_lifetime
        for i in _BITS[items]:
            a = age[i] + 1
            if lifetime is not None and a > lifetime:
                age[i] = 0
                items ^= 1 << i
            else:
                age[i] = a
        new = appear & ~items
        if new:
            for i in _BITS[new]:
                age[i] = 1
            items |= new
        self._items = items

    def observe_single(self):
        """``(obs (37,), {"dset": (1, 24), "full": (1, 37)})`` of the single copy: shared
        read-only arrays (copy the observation before handing it out)."""
        return _single_views(self._p << R.N_ITEMS | self._items)

    def step(self, actions, influences, new_items=None):
        """Advance every copy (see the class docstring).

        Args:
            actions: ints in 0..3, shape ``(n_copies,)``.
            influences: ints in 0..3, shape ``(n_copies, 4)``.
            new_items: optional bool ``(n_copies, 12)``: use these item-appearance draws
                instead of random ones (an item appears where True and the cell is empty);
                lets tests replay a GS region exactly.
        """
        n = self.n_copies
        actions = self._check_ints("actions", actions, (n,), 4)
        influences = self._check_ints("influences", influences, (n, R.N_SOURCES), 4)
        if new_items is not None:
            appear = np.asarray(new_items)
            if appear.shape != (n, R.N_ITEMS) or appear.dtype != bool:
                raise BadInput(
                    f"new_items must be a bool array of shape {(n, R.N_ITEMS)}, got "
                    f"{appear.dtype} {appear.shape}"
                )
        if self._scalar:
            return self._step_single_arrays(int(actions[0]), influences[0], new_items)
        if new_items is None:
            appear = self._streams.next() < self.item_probability
        ages = self._ages
        max_age = ages.max(axis=1)
        pos = _MOVE_FLAT[self._pos * 4 + actions]
        self._pos = pos
        own = R.SHELF_ONEHOT[pos].view(bool)
        reward = R.collect_reward((ages * own).sum(axis=1), max_age)
        occupied = own | R.INFLUENCE_MASK[influences @ R.INFLUENCE_CODE]
        R.advance_items(ages, occupied, appear, self.item_lifetime)
        obs, dsets = self._views()
        return obs, reward, dsets

    def _step_single_arrays(self, action, u, new_items):
        if new_items is None:
            reward = self.step_single(action, *u.tolist())
        else:
            # step_single with the given appearance draws instead of the rng's.
            draws = self._draws
            self._draws = [int(np.asarray(new_items)[0] @ _POW2)]
            try:
                reward = self.step_single(action, *u.tolist())
            finally:
                self._draws = draws
        obs, dsets = self.observe()
        return obs, np.array([reward]), dsets

    def _views(self):
        items = (self._ages > 0).view(np.uint8)
        full = np.concatenate([R.POS_ONEHOT[self._pos], items], axis=1)
        dset = np.concatenate([items, R.SHELF_ONEHOT[self._pos]], axis=1)
        return full.astype(np.float32), {"dset": dset, "full": full}

    @staticmethod
    def _check_ints(name, value, shape, n_classes) -> np.ndarray:
        arr = np.asarray(value)
        if arr.shape != shape:
            if len(shape) == 1 and arr.shape == shape + (1,):
                arr = arr.reshape(shape)  # (n, 1) actions, as some vectorised policies give
            else:
                raise BadInput(f"{name} must have shape {shape}, got {arr.shape}")
        if arr.dtype.kind not in "iu":
            raise BadInputType(f"{name} must be ints in 0..{n_classes - 1}, got dtype {arr.dtype}")
        arr = arr.astype(np.int64, copy=False)
        if np.count_nonzero(arr & -n_classes):  # n_classes is 4, a power of two: any value outside 0..3
            raise BadInput(
                f"{name} must be in 0..{n_classes - 1}, got values {arr.min()}..{arr.max()}"
            )
        return arr

    # ------------------------------------------------------------------ state access

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        """``(positions (n_copies,), item ages (n_copies, 12))``, copies."""
        if self._scalar:
            return np.array([self._p], dtype=np.int64), np.array([self._age], dtype=np.int64)
        return self._pos.copy(), self._ages.copy()

    def set_state(self, positions, item_ages) -> None:
        """Overwrite every copy's robot position and item ages (e.g. from a GS region)."""
        n = self.n_copies
        pos = np.asarray(positions, dtype=np.int64).reshape(n)
        ages = np.asarray(item_ages, dtype=np.int64)
        if ages.shape != (n, R.N_ITEMS) or (ages < 0).any():
            raise BadInput(f"item_ages must be non-negative ints of shape {(n, R.N_ITEMS)}")
        if ((pos < 0) | (pos >= R.N_CELLS) | np.isin(pos, R.CORNERS)).any():
            raise BadInput(f"positions must be non-corner local positions 0..24, got {pos}")
        if self._scalar:
            age = [int(a) for a in ages[0]]
            self._set_single(int(pos[0]), int((ages[0] > 0) @ _POW2), age)
            return
        self._pos = pos.copy()
        self._ages = ages.copy()

    def observe(self):
        """``(obs, dsets)`` of the current state (as returned by ``reset``/``step``)."""
        if self._scalar:
            obs, dsets = self.observe_single()
            return obs[None].copy(), {k: v.copy() for k, v in dsets.items()}
        return self._views()


def local_simulator(agents="robot_20", n_envs: int = 1, **options) -> WarehouseLocalSimulator:
    """Factory used by the domain registry. Accepts the GS's options: those that shape the
    region (``robots``, ``item_probability``, ``item_lifetime``, ``max_cycles``) are used,
    the GS-only ones (``learners``, ``render_mode``, ``scripted_learners``) are ignored."""
    return WarehouseLocalSimulator(agents, n_envs=n_envs, **R.drop_gs_only_options(options))
