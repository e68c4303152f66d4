"""Influence predictors, data collection (Algorithm 1) and IALS environments (Algorithm 2).

* :mod:`ials_zoo.influence.dataset` -- :func:`collect` ``(d_t, u_t)`` data from a GS,
  :class:`InfluenceDataset` (``.npz`` files);
* :mod:`ials_zoo.influence.base` -- the :class:`InfluencePredictor` interface and sampling;
  :mod:`~ials_zoo.influence.networks` (GRU, MLP, untrained; numpy inference),
  :mod:`~ials_zoo.influence.constant` (uniform, fixed, marginal),
  :mod:`~ials_zoo.influence.files` (predictor files: weights + JSON),
  :mod:`~ials_zoo.influence.metrics` (cross-entropies);
* :mod:`ials_zoo.influence.train` -- :func:`train_predictor` (torch);
* :mod:`ials_zoo.influence.ials` -- :class:`IALSEnv`, :class:`IALSVecEnv`, :func:`make_ials`,
  :func:`make_ials_vec_env`.

Heavy imports (torch, stable-baselines3) happen only where needed.
"""

from ials_zoo.influence.base import InfluencePredictor
from ials_zoo.influence.constant import FixedPredictor, MarginalPredictor, UniformPredictor
from ials_zoo.influence.dataset import InfluenceDataset, collect
from ials_zoo.influence.files import load_predictor, save_predictor
from ials_zoo.influence.metrics import evaluate_cross_entropy
from ials_zoo.influence.networks import GRUPredictor, MLPPredictor, untrained_predictor
from ials_zoo.influence.train import train_predictor


def __getattr__(name):
    if name in ("IALSEnv", "IALSVecEnv", "make_ials", "make_ials_vec_env"):
        from ials_zoo.influence import ials  # lazy: SB3/torch

        return getattr(ials, name)
    raise AttributeError(f"module 'ials_zoo.influence' has no attribute {name!r}")


__all__ = [
    "FixedPredictor",
    "GRUPredictor",
    "IALSEnv",
    "IALSVecEnv",
    "InfluenceDataset",
    "InfluencePredictor",
    "MLPPredictor",
    "MarginalPredictor",
    "UniformPredictor",
    "collect",
    "evaluate_cross_entropy",
    "load_predictor",
    "make_ials",
    "make_ials_vec_env",
    "untrained_predictor",
    "save_predictor",
    "train_predictor",
]
