"""The one vocabulary for influence predictors and training simulators.

A *predictor spec* names the AIP of an IALS:

==================  ==========================================================================
``trained``          the AIP shipped with the package, else cached (else an error saying how to
                     train one: nothing is trained behind the caller's back)
``trained:gru``      the same with a given architecture (memory / no-memory AIP, paper §5.4)
``trained:mlp``
``train``            as ``trained``, but collect GS data and train the AIP when none is shipped
``train:gru|mlp``    or cached (minutes; it says so, and caches the result)
``untrained``        the domain's AIP network at a random initialisation (the paper's
                     untrained-IALS)
``uniform``          fixed per-class probabilities (``Domain.untrained_probs``, SPEC §3)
``fixed:P``          F-IALS: each source "active" with probability P, in [0, 1]
``marginal``         F-IALS with the empirical marginal of the trained AIP's data
``PATH.pt``          a predictor file (any path ending in ``.pt`` or containing a separator)
==================  ==========================================================================

A *simulator spec* (``ials-zoo train --simulator``) is ``gs`` (the global simulator) or a
predictor spec, with two historical aliases kept for the leaderboard's names: ``ials`` =
``trained`` and ``untrained-ials`` = ``untrained``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

from ials_zoo.errors import BadInput, BadInputType

PREDICTOR_SPECS = ("trained, trained:gru, trained:mlp, train, train:gru, train:mlp, untrained, uniform, fixed:P, "
                   "marginal or a .pt file")
SIMULATOR_SPECS = "gs, ials, untrained-ials, uniform, fixed:P, marginal, trained:gru|mlp or a .pt file"
SIMULATOR_ALIASES = {"ials": "trained", "untrained-ials": "untrained"}
GS = "gs"


@dataclass(frozen=True)
class PredictorSpec:
    """A parsed predictor spec.

    Attributes:
        kind: ``trained``, ``untrained``, ``uniform``, ``fixed``, ``marginal`` or ``file``.
        arch: ``gru``/``mlp`` for ``trained:ARCH``, else None.
        p: the probability of ``fixed:P``.
        path: the file of ``file``.
        train_if_missing: ``train[:ARCH]``: a ``trained`` AIP that may be trained on demand.
    """

    kind: str
    arch: str | None = None
    p: float | None = None
    path: str | None = None
    train_if_missing: bool = False

    def __str__(self) -> str:
        if self.kind == "trained":
            word = "train" if self.train_if_missing else "trained"
            return f"{word}:{self.arch}" if self.arch else word
        if self.kind == "fixed":
            return f"fixed:{self.p:g}"
        if self.kind == "file":
            return str(self.path)
        return self.kind


def is_path(text) -> bool:
    """Whether a spec names a file rather than a predictor kind."""
    if isinstance(text, os.PathLike):
        return True
    return isinstance(text, str) and (text.endswith(".pt") or os.sep in text or (os.altsep or "\0") in text)


def parse_predictor(text) -> PredictorSpec:
    """Parse a predictor spec (see the module docstring); a ValueError naming the accepted
    forms otherwise. A file spec is not opened here."""
    if is_path(text):
        return PredictorSpec("file", path=os.fspath(text))
    if not isinstance(text, str):
        raise BadInputType(f"a predictor spec must be a string or a path, got {type(text).__name__}")
    name = text.strip().lower()
    if name in ("trained", "untrained", "uniform", "marginal"):
        return PredictorSpec(name)
    if name in ("random-init", "random_init"):
        raise BadInput(f"predictor {text!r} is now called 'untrained' (a randomly initialised network)")
    if name == "train":
        return PredictorSpec("trained", train_if_missing=True)
    if name.startswith(("trained:", "train:")):
        word, arch = name.split(":", 1)
        if arch not in ("gru", "mlp"):
            raise BadInput(f"bad predictor {text!r}; expected '{word}:gru' or '{word}:mlp'")
        return PredictorSpec("trained", arch=arch, train_if_missing=word == "train")
    if name.startswith("fixed:"):
        try:
            p = float(name.split(":", 1)[1])
        except ValueError:
            p = math.nan
        if not 0.0 <= p <= 1.0:
            raise BadInput(f"bad predictor {text!r}; expected fixed:P with P a number in [0, 1]")
        return PredictorSpec("fixed", p=p)
    raise BadInput(f"unknown influence predictor {text!r}; expected {PREDICTOR_SPECS}")


def parse_simulator(text) -> PredictorSpec | None:
    """Parse a simulator spec: None for the GS, else the IALS's :class:`PredictorSpec`."""
    if isinstance(text, str) and text.strip().lower() == GS:
        return None
    if isinstance(text, str) and text.strip().lower() in SIMULATOR_ALIASES:
        text = SIMULATOR_ALIASES[text.strip().lower()]
    try:
        spec = parse_predictor(text)
    except ValueError:
        raise BadInput(f"unknown simulator {text!r}; expected {SIMULATOR_SPECS}") from None
    if spec.kind == "file" and not os.path.isfile(spec.path):
        raise BadInput(f"simulator {text!r}: predictor file not found")
    return spec


def predictor_for(simulator: str) -> str | None:
    """The ``predictor`` argument of the IALS factories for a ``--simulator`` value, or None
    for the GS (a BadInput naming the vocabulary for anything else)."""
    spec = parse_simulator(simulator)
    return None if spec is None else str(spec)


def simulator_label(text, aip_variant: str | None = None) -> str:
    """The training-simulator name a result carries: ``gs``, ``ials`` (a trained AIP, shipped
    or from a file), ``untrained-ials``, ``uniform``, ``fixed:P``, ``marginal``. A predictor
    file is named by what it holds (``aip_variant``, from its metadata)."""
    spec = parse_simulator(text)
    if spec is None:
        return GS
    if spec.kind == "file":
        return "ials" if aip_variant in (None, "trained") else ("untrained-ials" if aip_variant == "untrained" else str(aip_variant))
    if spec.kind == "trained":
        return "ials" if spec.arch is None else f"ials:{spec.arch}"
    if spec.kind == "untrained":
        return "untrained-ials"
    return str(spec)


__all__ = [
    "GS",
    "PREDICTOR_SPECS",
    "SIMULATOR_SPECS",
    "PredictorSpec",
    "parse_predictor",
    "parse_simulator",
    "predictor_for",
    "simulator_label",
]
