"""The warehouse local simulator (LS): one robot's 5 x 5 region, ``n_envs`` copies at once."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from ials_zoo.core.local import LocalSimulator
from ials_zoo.warehouse import regions as R

_MOVE_FLAT = R.MOVE.ravel()


class WarehouseLocalSimulator(LocalSimulator):
    """``n_envs`` copies of one warehouse region, stepped together (SPEC §1, paper §4).

    Each step, in every copy: the robot moves by its action; the influence sources ``u_t``
    (one class per side: right, below, left, above; 0..2 = the neighbour stands on that
    side's shared shelf cell k, 3 = none) place the 4 neighbours; the robot collects the item
    under it (reward = its age / the largest age in the region, as in the GS) and an item
    under a neighbour disappears; items age (and expire with ``item_lifetime``); new items
    appear on empty shelf cells with probability ``item_probability``. This is the GS's order
    of operations, using the same functions (:func:`regions.collect_reward`,
    :func:`regions.advance_items`), so a GS region stepped with its true ``u_t`` and the same
    appearance draws gives the same observations, rewards and d-sets.

    Observations are ``float32 (n_envs, 37)`` as in the GS; d-sets are uint8,
    ``{"dset": (n_envs, 24), "full": (n_envs, 37)}``. At reset every robot is at its
    region's centre and each shelf cell holds a new item with probability
    ``item_probability`` (as in the GS).
    """

    def __init__(
        self,
        agent: str = "robot_20",
        n_envs: int = 1,
        item_probability: float = R.DEFAULT_ITEM_PROBABILITY,
        max_cycles: int = R.DEFAULT_MAX_CYCLES,
        item_lifetime: int | None = None,
        robots=R.DEFAULT_ROBOTS,
    ):
        if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs must be a positive int, got {n_envs!r}")
        self.region = R.region_spec(
            agent,
            robots=robots,
            item_probability=item_probability,
            item_lifetime=item_lifetime,
            max_cycles=max_cycles,
        )
        self.agent = agent
        self.n_envs = int(n_envs)
        self.item_probability = self.region.params["item_probability"]
        self.item_lifetime = self.region.params["item_lifetime"]
        self.max_cycles = self.region.params["max_cycles"]
        self.observation_space = spaces.Box(0.0, 1.0, (R.OBS_SIZE,), np.float32)
        self.action_space = spaces.Discrete(4)
        self._rng = np.random.default_rng()
        self._arange = np.arange(self.n_envs)
        self._pos = np.full(self.n_envs, R.CENTRE, dtype=np.int64)
        self._ages = np.zeros((self.n_envs, R.N_ITEMS), dtype=np.int64)

    def reset(self, seed: int | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._pos = np.full(self.n_envs, R.CENTRE, dtype=np.int64)
        self._ages = (self._rng.random((self.n_envs, R.N_ITEMS)) < self.item_probability).astype(
            np.int64
        )
        return self._views()

    def step(self, actions, influences, new_items=None):
        """Advance every copy (see the class docstring).

        Args:
            actions: ints in 0..3, shape ``(n_envs,)``.
            influences: ints in 0..3, shape ``(n_envs, 4)``.
            new_items: optional bool ``(n_envs, 12)``: use these item-appearance draws
                instead of random ones (an item appears where True and the cell is empty);
                lets tests replay a GS region exactly.
        """
        actions = self._check_ints("actions", actions, (self.n_envs,), 4)
        influences = self._check_ints("influences", influences, (self.n_envs, R.N_SOURCES), 4)
        if new_items is None:
            appear = self._rng.random((self.n_envs, R.N_ITEMS)) < self.item_probability
        else:
            appear = np.asarray(new_items)
            if appear.shape != (self.n_envs, R.N_ITEMS) or appear.dtype != bool:
                raise ValueError(
                    f"new_items must be a bool array of shape {(self.n_envs, R.N_ITEMS)}, got "
                    f"{appear.dtype} {appear.shape}"
                )
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
                raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
        if arr.dtype.kind not in "iu":
            raise TypeError(f"{name} must be ints in 0..{n_classes - 1}, got dtype {arr.dtype}")
        arr = arr.astype(np.int64, copy=False)
        if np.count_nonzero(arr & -n_classes):  # n_classes is 4, a power of two: any value outside 0..3
            raise ValueError(
                f"{name} must be in 0..{n_classes - 1}, got values {arr.min()}..{arr.max()}"
            )
        return arr

    # ------------------------------------------------------------------ state access

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        """``(positions (n_envs,), item ages (n_envs, 12))``, copies."""
        return self._pos.copy(), self._ages.copy()

    def set_state(self, positions, item_ages) -> None:
        """Overwrite every copy's robot position and item ages (e.g. from a GS region)."""
        pos = np.asarray(positions, dtype=np.int64).reshape(self.n_envs)
        ages = np.asarray(item_ages, dtype=np.int64)
        if ages.shape != (self.n_envs, R.N_ITEMS) or (ages < 0).any():
            raise ValueError(f"item_ages must be non-negative ints of shape {(self.n_envs, R.N_ITEMS)}")
        if ((pos < 0) | (pos >= R.N_CELLS) | np.isin(pos, R.CORNERS)).any():
            raise ValueError(f"positions must be non-corner local positions 0..24, got {pos}")
        self._pos = pos.copy()
        self._ages = ages.copy()

    def observe(self):
        """``(obs, dsets)`` of the current state (as returned by ``reset``/``step``)."""
        return self._views()


def local_simulator(agent: str = "robot_20", n_envs: int = 1, **options) -> WarehouseLocalSimulator:
    """Factory used by the domain registry. Accepts the GS's options: those that shape the
    region (``robots``, ``item_probability``, ``item_lifetime``, ``max_cycles``) are used,
    the GS-only ones (``learners``, ``render_mode``, ``scripted_learners``) are ignored."""
    return WarehouseLocalSimulator(agent, n_envs=n_envs, **R.drop_gs_only_options(options))
