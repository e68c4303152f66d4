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

For comparing algorithms over seeds the way the field reports (Agarwal et al., 2021, "Deep RL
at the edge of the statistical precipice"): the **interquartile mean** (IQM, the mean of the
middle 50% of the scores, ``scipy.stats.trim_mean(x, 0.25)``) with a **stratified bootstrap**
interval (``scipy.stats.bootstrap`` over one sample per task: each task's seeds are resampled
within the task), and the **probability of improvement** P(X > Y) + P(X = Y) / 2 of one
algorithm's seeds over another's (the Mann-Whitney U statistic over ``n m``, scipy), with a
stratified bootstrap interval too.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from ials_zoo.errors import BadInput

CI_LEVEL = 0.95
BOOTSTRAP_RESAMPLES = 9999
BOOTSTRAP_SEED = 0
EPISODES_METHOD = "bootstrap-bca"
SEEDS_METHOD = "student-t"


def _values(values) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 1 or x.size == 0:
        raise BadInput(f"need a non-empty 1-D sequence of values, got shape {x.shape}")
    if not np.isfinite(x).all():
        raise BadInput("values must be finite numbers")
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


def iqm(values: Sequence[float]) -> float:
    """The interquartile mean (scipy's 25% trimmed mean)."""
    from scipy import stats

    return float(stats.trim_mean(_values(values), 0.25))


def iqm_interval(per_task: Sequence[Sequence[float]], level: float = CI_LEVEL) -> tuple[float, float, float]:
    """``(iqm, low, high)`` of the scores of every task and seed, with a stratified percentile
    bootstrap interval (each task's scores resampled within the task; one task: a plain one)."""

    from scipy import stats

    samples = [_values(x) for x in per_task]
    if not samples:
        raise BadInput("need the scores of at least one task")
    point = iqm(np.concatenate(samples))
    if all(x.size == 1 or np.all(x == x[0]) for x in samples):
        return point, point, point

    def statistic(*xs, axis=-1):
        return stats.trim_mean(np.concatenate(xs, axis=axis), 0.25, axis=axis)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = stats.bootstrap(samples, statistic, n_resamples=BOOTSTRAP_RESAMPLES, confidence_level=level,
                              method="percentile", vectorized=True, random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return point, min(float(res.confidence_interval.low), point), max(float(res.confidence_interval.high), point)


def probability_of_improvement(x: Sequence[float], y: Sequence[float], level: float = CI_LEVEL
                               ) -> tuple[float, float, float]:
    """``(p, low, high)``: P(X > Y) + P(X = Y) / 2 for a score X of ``x``'s runs and Y of ``y``'s
    (the Mann-Whitney U statistic of ``x`` over ``len(x) * len(y)``), with a percentile
    bootstrap interval that resamples each algorithm's runs."""

    from scipy import stats

    a, b = _values(x), _values(y)

    def statistic(a, b, axis=-1):
        greater = (a[..., :, None] > b[..., None, :]).mean(axis=(-2, -1))
        equal = (a[..., :, None] == b[..., None, :]).mean(axis=(-2, -1))
        return greater + 0.5 * equal

    point = float(stats.mannwhitneyu(a, b).statistic) / (a.size * b.size)
    if a.size == 1 and b.size == 1:
        return point, point, point
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = stats.bootstrap((a, b), statistic, n_resamples=BOOTSTRAP_RESAMPLES, confidence_level=level,
                              method="percentile", vectorized=True, random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return point, min(float(res.confidence_interval.low), point), max(float(res.confidence_interval.high), point)


def interval(values: Sequence[float], method: str, level: float = CI_LEVEL) -> tuple[float, float, float]:
    """``(mean, low, high)`` with ``method`` :data:`EPISODES_METHOD` or :data:`SEEDS_METHOD`."""
    if method == EPISODES_METHOD:
        return bootstrap_interval(values, level)
    if method == SEEDS_METHOD:
        return t_interval(values, level)
    raise BadInput(f"unknown interval method {method!r}; expected {EPISODES_METHOD!r} or {SEEDS_METHOD!r}")


__all__ = [
    "BOOTSTRAP_RESAMPLES",
    "BOOTSTRAP_SEED",
    "CI_LEVEL",
    "EPISODES_METHOD",
    "SEEDS_METHOD",
    "bootstrap_interval",
    "interval",
    "iqm",
    "iqm_interval",
    "probability_of_improvement",
    "t_interval",
]
