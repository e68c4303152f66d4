"""Influence predictors whose probabilities do not depend on the history: the untrained
``uniform`` AIP (SPEC §3), F-IALS ``fixed:P`` and the empirical ``marginal``."""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence.base import InfluencePredictor, count_below


class _ConstantPredictor(InfluencePredictor):
    """A predictor whose probabilities do not depend on the history."""

    def __init__(self, region, probs, dset_kind="dset", metadata=None):
        super().__init__(region, dset_kind, metadata)
        table = np.zeros((self.n_sources, self.max_classes))
        if len(probs) != self.n_sources:
            raise BadInput(f"need {self.n_sources} probability vectors, got {len(probs)}")
        for m, (p, k) in enumerate(zip(probs, self.n_classes)):
            p = np.asarray(p, dtype=np.float64)
            if p.shape != (k,) or (p < 0).any() or not np.isclose(p.sum(), 1.0, atol=1e-6):
                raise BadInput(
                    f"source {region.influence_names[m]!r}: expected {k} probabilities summing "
                    f"to 1, got {p.tolist()}"
                )
            table[m, :k] = p / p.sum()
        self.table = table
        self._batch = table[None]
        cum = np.cumsum(table, axis=1)
        for m, k in enumerate(self.n_classes):
            cum[m, k - 1 :] = 2.0  # never below r < 1: the last real class takes the rest
        self._cum = cum

    def reset(self, n=1):
        super().reset(n)
        self._batch = np.broadcast_to(self.table, (self.n, *self.table.shape))

    def probs_padded(self, dsets):
        self._check_dsets(dsets)
        return self._batch

    def sample(self, dsets, rng):
        self._check_dsets(dsets)
        return count_below(self._cum[:, :-1], rng.random((self.n, self.n_sources)))  # the last: never below

    def _arrays(self):
        return {"table": self.table}


class UniformPredictor(_ConstantPredictor):
    """The untrained AIP with fixed probabilities (SPEC §3, "untrained-IALS").

    By default uniform over each source's classes (0.25 per class for a 4-class warehouse
    source, 0.5 for a bit). ``probs`` overrides this (one vector per source), which is how a
    domain's ``Domain.untrained_probs`` is applied.
    """

    name = "uniform"

    def __init__(self, region, dset_kind="dset", probs=None, metadata=None, table=None):
        if table is not None:
            probs = [np.asarray(t)[:k] for t, k in zip(table, region.influence_classes)]
        if probs is None:
            probs = [np.full(k, 1.0 / k) for k in region.influence_classes]
        super().__init__(region, probs, dset_kind, metadata)


class FixedPredictor(_ConstantPredictor):
    """F-IALS (paper §5): every source is "active" with the fixed probability ``p``.

    Each source has a "nothing comes in" class ``null_class`` (no car enters, the neighbour
    is not on a shared cell): the domain's ``Domain.null_influence``, default 0.
    For a bit with ``null_class=0``, ``P(u=1) = p``. For a categorical source with ``K``
    classes, ``P(u=null_class) = 1 - p`` and ``p`` is spread uniformly over the other
    ``K - 1`` classes.
    """

    name = "fixed"

    def __init__(self, region, p: float = 0.1, dset_kind="dset", metadata=None, table=None, null_class=0):
        try:
            p = float(p)
        except (TypeError, ValueError):
            raise BadInputType(f"fixed influence probability must be a number in [0, 1], got {p!r}") from None
        if not 0.0 <= p <= 1.0:
            raise BadInput(f"fixed influence probability must be in [0, 1], got {p}")
        null_class = int(null_class)
        for k in region.influence_classes:
            if not 0 <= null_class < k:
                raise BadInput(f"null_class {null_class} out of range for a source with {k} classes")
        self.p = p
        self.null_class = null_class
        probs = []
        for k in region.influence_classes:
            v = np.full(k, p / (k - 1))
            v[null_class] = 1.0 - p
            probs.append(v)
        super().__init__(region, probs, dset_kind, metadata)

    def _config(self):
        return {"p": self.p, "null_class": self.null_class}

    def describe(self):
        return f"fixed:{self.p:g} ({self.region.domain}/{self.region.agent})"


class MarginalPredictor(_ConstantPredictor):
    """F-IALS with the empirical marginal ``P(u_m)`` of a data set (pooled over time)."""

    name = "marginal"

    def __init__(self, region, probs=None, dset_kind="dset", metadata=None, table=None):
        if table is not None:
            probs = [np.asarray(t)[:k] for t, k in zip(table, region.influence_classes)]
        if probs is None:
            raise BadInput("MarginalPredictor needs probs (use MarginalPredictor.fit(dataset))")
        super().__init__(region, probs, dset_kind, metadata)

    @staticmethod
    def marginal_probs(influences: np.ndarray, classes, smoothing: float = 0.5) -> list:
        """Per-source class frequencies of ``influences`` (``[..., M]``), add-``smoothing``."""
        u = np.asarray(influences).reshape(-1, len(classes))
        out = []
        for m, k in enumerate(classes):
            counts = np.bincount(u[:, m], minlength=k)[:k].astype(np.float64) + smoothing
            out.append(counts / counts.sum())
        return out

    @classmethod
    def fit(cls, dataset, dset_kind="dset", episodes=None) -> MarginalPredictor:
        u = dataset.influences if episodes is None else dataset.influences[episodes]
        probs = cls.marginal_probs(u, dataset.region.influence_classes)
        return cls(dataset.region, probs, dset_kind, metadata={"fitted_on_steps": int(u.shape[0] * u.shape[1])})


class RecordedPredictor(InfluencePredictor):
    """Not a model: the influence of one recorded GS episode, replayed step by step (the same
    ``u_t`` for every history, whatever the d-sets). It tests the local simulator alone: fed
    the GS's own sources under a joint policy, does it give the GS's rewards? Past the
    recording's end it repeats the last step."""

    name = "recorded"

    def __init__(self, region, influences, dset_kind="dset", metadata=None):
        super().__init__(region, dset_kind, metadata)
        u = np.asarray(influences, dtype=np.int64)
        if u.ndim != 2 or u.shape[1] != self.n_sources or len(u) == 0:
            raise BadInput(f"recorded influences must have shape [steps >= 1, {self.n_sources}], got {u.shape}")
        if (u < 0).any() or (u >= self.n_classes[None, :]).any():
            raise BadInput("recorded influences hold a class outside a source's classes")
        self.influences = u

    def probs_padded(self, dsets):
        u = self._next(dsets)
        return np.broadcast_to(np.eye(self.max_classes)[u], (self.n, self.n_sources, self.max_classes))

    def sample(self, dsets, rng):
        return np.broadcast_to(self._next(dsets), (self.n, self.n_sources)).copy()

    def _next(self, dsets) -> np.ndarray:
        self._check_dsets(dsets)
        u = self.influences[min(self._t, len(self.influences) - 1)]
        self._t += 1
        return u
