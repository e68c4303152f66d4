"""Confidence intervals of mean returns (scipy), one definition for the whole zoo.

* Over the **episodes** of one evaluation: a bias-corrected and accelerated (BCa) bootstrap
  interval (``scipy.stats.bootstrap``, :data:`BOOTSTRAP_RESAMPLES` resamples from a generator
  seeded with :data:`BOOTSTRAP_SEED`, so the interval is a deterministic function of the
  returns). Unlike the Student-t interval it stays inside the range the returns can take: a
  policy whose episodic returns are all >= 0 never gets a lower bound below 0.
* Over **training seeds** (3-10 values): the Student-t interval
  ``mean +- t(0.975, n-1) s / sqrt(n)`` (``scipy.stats.t``). A bootstrap of 3 values has only
  10 distinct resamples and badly understates the uncertainty; the t interval does not.

A sample whose values are all equal gets the interval ``[v, v]``; a single value too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

CI_LEVEL = 0.95
BOOTSTRAP_RESAMPLES = 9999
BOOTSTRAP_SEED = 0
EPISODES_METHOD = "bootstrap-bca"
SEEDS_METHOD = "student-t"


def _values(values) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size == 0:
        raise ValueError(f"need a non-empty 1-D sequence of values, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise ValueError("values must be finite numbers")
    return x


def t_interval(values: Sequence[float], level: float = CI_LEVEL) -> tuple[float, float, float]:
    """``(mean, low, high)``: the Student-t interval of the mean."""
    from scipy import stats

    x = _values(values)
    mean = float(x.mean())
    if x.size == 1 or np.all(x == x[0]):
        return mean, mean, mean
    half = float(stats.t.ppf(0.5 + level / 2.0, x.size - 1)) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean, mean - half, mean + half


def bootstrap_interval(values: Sequence[float], level: float = CI_LEVEL) -> tuple[float, float, float]:
    """``(mean, low, high)``: the BCa bootstrap interval of the mean (module docstring)."""
    import warnings

    from scipy import stats

    x = _values(values)
    mean = float(x.mean())
    if x.size == 1 or np.all(x == x[0]):
        return mean, mean, mean
    with warnings.catch_warnings():
        # BCa warns (and returns NaN) on degenerate resamples; the fallback below handles it.
        warnings.simplefilter("ignore")
        res = stats.bootstrap((x,), np.mean, n_resamples=BOOTSTRAP_RESAMPLES, confidence_level=level,
                              method="BCa", random_state=np.random.default_rng(BOOTSTRAP_SEED))
    low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    if not (math.isfinite(low) and math.isfinite(high)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = stats.bootstrap((x,), np.mean, n_resamples=BOOTSTRAP_RESAMPLES, confidence_level=level,
                                  method="percentile", random_state=np.random.default_rng(BOOTSTRAP_SEED))
        low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return mean, min(low, mean), max(high, mean)


def interval(values: Sequence[float], method: str, level: float = CI_LEVEL) -> tuple[float, float, float]:
    """``(mean, low, high)`` with ``method`` :data:`EPISODES_METHOD` or :data:`SEEDS_METHOD`."""
    if method == EPISODES_METHOD:
        return bootstrap_interval(values, level)
    if method == SEEDS_METHOD:
        return t_interval(values, level)
    raise ValueError(f"unknown interval method {method!r}; expected {EPISODES_METHOD!r} or {SEEDS_METHOD!r}")


__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "BOOTSTRAP_SEED",
    "CI_LEVEL",
    "EPISODES_METHOD",
    "SEEDS_METHOD",
    "bootstrap_interval",
    "interval",
    "t_interval",
]
