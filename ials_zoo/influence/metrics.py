"""How well an influence predictor fits data: cross-entropy (nats) per source and mean."""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.influence.base import InfluencePredictor


def evaluate_cross_entropy(predictor: InfluencePredictor, dataset, episodes=None) -> float:
    """Mean cross-entropy (nats) of ``predictor`` on ``dataset``.

    ``CE = (1/M) sum_m mean_{episode, t} [-ln p_m(u_{t,m} | d_0..d_t)]`` (and ``u_0..u_{t-1}``
    for an autoregressive predictor, given the recorded ones: teacher forcing): the per-step
    negative log-likelihood of each source, averaged over steps and episodes, then over the
    ``M`` sources (so a uniform guess over 4 classes scores ln 4 = 1.386 whatever ``M``).
    The recurrent state is reset at the start of every episode. ``episodes`` selects a
    subset (index array); default all.
    """
    return float(np.mean(cross_entropy_per_source(predictor, dataset, episodes)))


def cross_entropy_per_source(predictor, dataset, episodes=None) -> np.ndarray:
    """Per-source mean cross-entropy (nats), shape ``[M]``; see :func:`evaluate_cross_entropy`."""
    if predictor.region.influence_classes != dataset.region.influence_classes:
        raise BadInput(
            f"predictor sources {predictor.region.influence_classes} do not match the data "
            f"set's {dataset.region.influence_classes}"
        )
    d = dataset.dsets[predictor.dset_kind]
    u = dataset.influences
    if episodes is not None:
        d, u = d[episodes], u[episodes]
    E, T, M = u.shape
    if E == 0:
        raise BadInput("cannot evaluate the cross-entropy on an empty data set")
    nll = np.zeros(M)
    rows = np.arange(E)[:, None]
    cols = np.arange(M)[None, :]
    predictor.reset(E)
    for t in range(T):
        p = predictor.probs_padded(d[:, t])
        predictor.observe(u[:, t])  # teacher forcing: an autoregressive AIP reads the recorded u_t next
        pu = p[rows, cols, u[:, t]]
        nll -= np.log(np.maximum(pu, 1e-12)).sum(axis=0)
    return nll / (E * T)


__all__ = ["cross_entropy_per_source", "evaluate_cross_entropy"]
