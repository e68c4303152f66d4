"""Approximate influence predictors (AIPs, paper §4.2): ``P(u_t | d_0 .. d_t)``.

This module gathers the public names of

* :mod:`ials_zoo.influence.base` -- the :class:`InfluencePredictor` interface and sampling;
* :mod:`ials_zoo.influence.networks` -- :class:`MLPPredictor`, :class:`GRUPredictor` (numpy
  inference, torch's initialisation);
* :mod:`ials_zoo.influence.constant` -- :class:`UniformPredictor`, :class:`FixedPredictor`
  (F-IALS), :class:`MarginalPredictor`;
* :mod:`ials_zoo.influence.metrics` -- cross-entropies;
* :mod:`ials_zoo.influence.files` -- predictor files (weights + JSON, no pickle).
"""

from ials_zoo.influence.base import InfluencePredictor
from ials_zoo.influence.constant import FixedPredictor, MarginalPredictor, UniformPredictor
from ials_zoo.influence.files import FORMAT, FORMAT_VERSION, load_predictor, save_predictor
from ials_zoo.influence.metrics import cross_entropy_per_source, evaluate_cross_entropy
from ials_zoo.influence.networks import (
    ARCHS,
    GRUPredictor,
    MLPPredictor,
    init_arrays,
    untrained_predictor,
)

__all__ = [
    "ARCHS",
    "FORMAT",
    "FORMAT_VERSION",
    "FixedPredictor",
    "GRUPredictor",
    "InfluencePredictor",
    "MLPPredictor",
    "MarginalPredictor",
    "UniformPredictor",
    "cross_entropy_per_source",
    "evaluate_cross_entropy",
    "init_arrays",
    "load_predictor",
    "untrained_predictor",
    "save_predictor",
]
