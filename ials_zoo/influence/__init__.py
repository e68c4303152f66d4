"""Influence predictors, data collection (Algorithm 1) and IALS environments (Algorithm 2).

* :mod:`ials_zoo.influence.dataset` -- :func:`collect` ``(d_t, u_t)`` data from a GS,
  :class:`InfluenceDataset` (``.npz`` files);
* :mod:`ials_zoo.influence.predictors` -- the :class:`InfluencePredictor` interface and its
  implementations (GRU, MLP, untrained, fixed, marginal), numpy inference, predictor files;
* :mod:`ials_zoo.influence.train` -- :func:`train_predictor` (torch);
* :mod:`ials_zoo.influence.ials` -- :class:`IALSEnv`, :class:`IALSVecEnv`, :func:`make_ials`,
  :func:`make_ials_vec_env`.

Heavy imports (torch, stable-baselines3) happen only where needed.
"""

from ials_zoo.influence.dataset import InfluenceDataset, collect
from ials_zoo.influence.predictors import (
    FixedPredictor,
    GRUPredictor,
    InfluencePredictor,
    MarginalPredictor,
    MLPPredictor,
    UniformPredictor,
    evaluate_cross_entropy,
    load_predictor,
    save_predictor,
    untrained_predictor,
)


def __getattr__(name):
    # Lazy: ials.py imports gymnasium/SB3, train.py imports torch.
    if name in ("IALSEnv", "IALSVecEnv", "make_ials", "make_ials_vec_env"):
        from ials_zoo.influence import ials

        return getattr(ials, name)
    if name == "train_predictor":
        from ials_zoo.influence.train import train_predictor

        return train_predictor
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
