"""Observations and rewards of ``sumo_net_v0``: small pluggable functions, RESCO's by default.

Each takes one light's measures (``[lanes, 5]``: approach, total wait, queue, speed sum, max
wait; :data:`ials_zoo.sumo_net.core.MEASURES`) and its current phase index, and returns the
agent's observation (float32, flat) or reward (float). Read from RESCO's ``states.py`` and
``rewards.py``.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput

N_FEATURES = 5


def _lanes_table(measures: np.ndarray, phase: int, divisors: np.ndarray | None) -> np.ndarray:
    n = len(measures)
    out = np.empty((n, N_FEATURES), np.float32)
    out[:, 0] = 0.0
    if 0 <= phase < n:
        out[phase, 0] = 1.0
    out[:, 1:] = measures[:, :4]
    if divisors is not None:
        out[:, 1:] /= divisors  # in float32, as the observation always was (bit for bit)
    return out.reshape(-1)


def drq(measures: np.ndarray, phase: int) -> np.ndarray:
    """RESCO's ``drq``: per lane ``[lane index == phase index, approach, total wait, queue,
    speed sum]`` (the first entry is RESCO's: a lane marker, not a one-hot of the phase)."""
    return _lanes_table(measures, phase, None)


_DRQ_DIVISORS = np.array([28.0, 28.0, 28.0, 20.0 * 28.0], np.float32)


def drq_norm(measures: np.ndarray, phase: int) -> np.ndarray:
    """RESCO's ``drq_norm`` (IDQN, IPPO): ``drq`` with counts and waits over 28, speeds over 20 * 28."""
    return _lanes_table(measures, phase, _DRQ_DIVISORS)


def wait_norm(measures: np.ndarray, phase: int) -> float:
    """RESCO's ``wait_norm`` (IDQN, IPPO): ``clip(-total wait / 224, -4, 4)``."""
    return min(4.0, max(-4.0, -float(measures[:, 1].sum()) / 224.0))  # np.clip costs 10x on a scalar


def wait_scaled(measures: np.ndarray, phase: int) -> float:
    """``wait_norm`` without its clip: ``-total wait / 224``. Past 896 s of waiting the clip
    makes every action look alike to a learner; this keeps telling a long queue from a longer
    one (a reward to learn from: ``train idqn --train-reward wait_scaled``)."""
    return -float(measures[:, 1].sum()) / 224.0


def wait(measures: np.ndarray, phase: int) -> float:
    """RESCO's ``wait``: minus the total wait of the light's detected vehicles (s)."""
    return float(-measures[:, 1].sum())


def queue(measures: np.ndarray, phase: int) -> float:
    """Minus the light's queue (vehicles that stopped within detection)."""
    return float(-measures[:, 2].sum())


def lanes_tables(measures: np.ndarray, phases: np.ndarray, starts: np.ndarray,
                 divisors: np.ndarray | None) -> np.ndarray:
    """Every light's lanes table at once, ``[all lanes, 5]`` float32 (light ``k``'s lanes are
    rows ``starts[k]:starts[k + 1]``): bit for bit the per-light tables stacked, one numpy pass
    instead of one per light (a tenth of a small map's Python per decision)."""
    out = np.empty((len(measures), N_FEATURES), np.float32)
    out[:, 0] = 0.0
    counts = np.diff(starts)
    marked = (phases >= 0) & (phases < counts)
    out[starts[:-1][marked] + phases[marked], 0] = 1.0
    out[:, 1:] = measures[:, :4]
    if divisors is not None:
        out[:, 1:] /= divisors
    return out


OBSERVATIONS = {"drq_norm": drq_norm, "drq": drq}
BATCHED_OBSERVATIONS = {drq_norm: _DRQ_DIVISORS, drq: None}
"""The observations :func:`lanes_tables` computes for every light at once, with their divisors."""
REWARDS = {"wait_norm": wait_norm, "wait_scaled": wait_scaled, "wait": wait, "queue": queue}


def _greens_table(scores: np.ndarray, phase: int) -> np.ndarray:
    n = len(scores)
    out = np.zeros(2 * n, np.float32)
    out[:n] = scores
    if 0 <= phase < n:
        out[n + phase] = 1.0
    return out


def mplight(pressures: np.ndarray, phase: int) -> np.ndarray:
    """MPLight's observation (RESCO's ``states.mplight`` on our greens): the light's greens'
    pressures (:class:`ials_zoo.sumo_net.pressure.Pressures`), then a one-hot of its current
    green (all zero during a yellow)."""
    return _greens_table(pressures, phase)


def wave(waves: np.ndarray, phase: int) -> np.ndarray:
    """What greedy (RESCO's MAXWAVE) reads, for a learner: each green's vehicles within 50 m of
    the light on the lanes it lets go, over 28 (:class:`ials_zoo.sumo_net.waves.Waves`), then a
    one-hot of its current green. Greedy's choice is the first half's argmax; the one-hot tells
    a learner what a change costs (a yellow)."""
    return _greens_table(np.asarray(waves) / 28.0, phase)


def drq_wave(measures: np.ndarray, waves: np.ndarray, phase: int) -> np.ndarray:
    """RESCO's ``drq_norm`` lanes table, then :func:`wave`'s table: what RESCO's learners read and
    what greedy reads, side by side."""
    return np.concatenate([drq_norm(measures, phase), wave(waves, phase)])


NETWORK_OBSERVATIONS = {"mplight": mplight, "wave": wave, "drq_wave": drq_wave}
"""Observations of the GS only, not a region: a light's greens' pressures (they read other
lights' downstream queues) or waves (a count a region does not make)."""
GREEN_OBSERVATIONS = (mplight, wave)
"""Observations of two entries per green: its score, then the one-hot of the current green."""
WAVE_OBSERVATIONS = (wave, drq_wave)
"""Observations that read every green's wave."""
NETWORK_REWARDS = ("pressure",)
"""RESCO's ``pressure`` (MPLight): minus the light's pressure; the GS only, not a region."""


def observation_fn(name: str, network_wide: bool = False):
    known = {**OBSERVATIONS, **(NETWORK_OBSERVATIONS if network_wide else {})}
    if name not in known:
        raise BadInput(f"unknown observation {name!r}; expected one of {', '.join(known)}"
                       + ("" if network_wide else " (mplight, wave and drq_wave: the GS only)"))
    return known[name]


def reward_fn(name: str, network_wide: bool = False):
    if network_wide and name in NETWORK_REWARDS:
        return None  # the env computes it for every light at once
    if name not in REWARDS:
        known = [*REWARDS, *(NETWORK_REWARDS if network_wide else ())]
        raise BadInput(f"unknown reward {name!r}; expected one of {', '.join(known)}"
                       + ("" if network_wide else " (pressure reads other lights: the GS only)"))
    return REWARDS[name]


__all__ = ["BATCHED_OBSERVATIONS", "GREEN_OBSERVATIONS", "N_FEATURES", "WAVE_OBSERVATIONS", "drq_wave", "NETWORK_OBSERVATIONS", "NETWORK_REWARDS", "OBSERVATIONS", "REWARDS",
           "drq", "drq_norm", "lanes_tables", "mplight", "observation_fn", "reward_fn", "wait", "wait_norm", "wave"]
