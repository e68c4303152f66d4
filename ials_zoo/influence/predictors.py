"""Approximate influence predictors (AIPs, paper §4.2): ``P(u_t | d_0 .. d_t)``.

Every predictor implements :class:`InfluencePredictor`, the interface the IALS uses:

* ``reset(n)`` -- start ``n`` parallel histories (zero recurrent state);
* ``probs(dsets)`` -- feed the current d-sets ``d_t`` of shape ``[n, D]`` (advancing the
  recurrent state, if any) and return one ``[n, K_m]`` probability array per source;
* ``sample(dsets, rng)`` -- the same, then draw ``u_t`` (int64, ``[n, M]``).

The sources are independent given the history (one softmax head per source, paper §4.2).

Implementations:

* :class:`MLPPredictor` -- one hidden layer (ReLU), input the current d-set only (no memory,
  the traffic AIP of the paper; "NM" variant).
* :class:`GRUPredictor` -- a GRU over the d-set history, hidden state reset at episode start
  (the warehouse AIP of the paper; "M" variant).
* :class:`UniformPredictor` -- fixed class probabilities, by default uniform over classes
  (SPEC §3: 0.25 per class in the warehouse); a domain may set other probabilities in
  ``Domain.extra["untrained_probs"]``.
* :class:`FixedPredictor` -- F-IALS: ``P(u != 0) = p`` per source (see its docstring).
* :class:`MarginalPredictor` -- F-IALS with the empirical marginal ``P(u)`` of a data set.

Inference is plain numpy (weights copied out of torch after training): a torch call at batch
1 costs more than a whole local-simulator step. Torch is only needed to *train* (``train.py``)
and to read/write predictor files. A single history (``reset(1)``, the :class:`IALSEnv` case)
takes a dedicated path in :class:`GRUPredictor`/:class:`MLPPredictor` sampling: the same float
operations in the same order as the batched code (bitwise the same draws), on preallocated
buffers, with the GRU's input projection memoised per d-set.

Files (:func:`save_predictor` / :func:`load_predictor`): one ``torch.save`` of a plain dict
(readable with ``weights_only=True``)::

    {"format": "ials_zoo.influence_predictor", "format_version": 1,
     "class": "GRUPredictor", "metadata_json": "<json>", "arrays": {name: tensor}}

``metadata_json`` holds the domain id (versioned, e.g. ``warehouse_v0``), agent, region spec,
d-set kind, architecture and hyper-parameters, data-set size, train/test cross-entropies,
package version and creation time.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ials_zoo.core.region import RegionSpec, check_dset_kind

FORMAT = "ials_zoo.influence_predictor"
FORMAT_VERSION = 1


_max_reduce = np.maximum.reduce
_add_accumulate = np.add.accumulate
_add_reduce = np.add.reduce
_HALF32 = np.array(0.5, dtype=np.float32)
_ONE32 = np.array(1.0, dtype=np.float32)


def _sigmoid(x, out=None):
    # 0.5 * (1 + tanh(x / 2)) never overflows, unlike 1 / (1 + exp(-x)).
    out = np.multiply(x, 0.5, out=out)
    np.tanh(out, out=out)
    out += 1.0
    out *= 0.5
    return out


class InfluencePredictor:
    """Interface of every influence predictor (see the module docstring).

    Attributes:
        region: the region this predictor is for (domain, agent, sources, d-set layout).
        dset_kind: which d-set it reads, ``"dset"`` or ``"full"``.
        metadata: free-form provenance (hyper-parameters, cross-entropies, ...), saved with it.
    """

    name = "base"

    def __init__(self, region: RegionSpec, dset_kind: str = "dset", metadata: dict | None = None):
        if not isinstance(region, RegionSpec):
            raise TypeError(f"region must be a RegionSpec, got {type(region).__name__}")
        self.region = region
        self.dset_kind = check_dset_kind(dset_kind)
        self.metadata = dict(metadata or {})
        classes = np.asarray(region.influence_classes, dtype=np.int64)
        if classes.size == 0:
            raise ValueError(f"region of {region.agent!r} has no influence sources")
        if (classes < 2).any():
            raise ValueError(f"every influence source needs >= 2 classes, got {tuple(classes)}")
        self.n_sources = int(classes.size)
        self.n_classes = classes
        self.max_classes = int(classes.max())
        self.dset_size = region.dset_size(dset_kind)
        # Layout of the concatenated logits [sum K_m] inside a padded [M, Kmax] array.
        self._offsets = np.concatenate([[0], np.cumsum(classes)])
        flat = np.full((self.n_sources, self.max_classes), -1, dtype=np.int64)
        for m, k in enumerate(classes):
            flat[m, :k] = np.arange(self._offsets[m], self._offsets[m] + k)
        self._gather = np.where(flat >= 0, flat, 0)
        self._pad_mask = flat < 0
        self._kmax_minus1 = (classes - 1)[None, :]
        self._same_k = bool((classes == classes[0]).all())
        self._sample_bufs = None
        self.n = 0

    # Scratch state of the n=1 fast paths: buffers holding views of each other, which a copy
    # or pickle would turn into unrelated arrays, and memo tables. Rebuilt on demand.
    _SCRATCH = {"_sample_bufs": None, "_bufs1": None, "_h_spare": None, "_gi_cache": {}}

    def __getstate__(self):
        state = dict(self.__dict__)
        for k, v in self._SCRATCH.items():
            if k in state:
                state[k] = type(v)() if isinstance(v, dict) else v
        return state

    # -- interface -------------------------------------------------------------------------
    def reset(self, n: int = 1) -> None:
        """Start ``n`` new parallel histories (zero the recurrent state, if any)."""
        n = int(n)
        if n < 1:
            raise ValueError(f"n must be >= 1, got {n}")
        self.n = n

    def probs_padded(self, dsets: np.ndarray) -> np.ndarray:
        """Class probabilities ``[n, M, Kmax]`` (0 beyond a source's own classes)."""
        raise NotImplementedError

    def probs(self, dsets: np.ndarray) -> list[np.ndarray]:
        """Feed ``d_t`` (``[n, D]``), advance the state, return one ``[n, K_m]`` array per source."""
        p = self.probs_padded(dsets)
        return [p[:, m, :k] for m, k in enumerate(self.n_classes)]

    def sample(self, dsets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Feed ``d_t`` (``[n, D]``), advance the state, draw ``u_t`` (int64, ``[n, M]``)."""
        p = self.probs_padded(dsets)
        cum = np.cumsum(p, axis=-1)
        r = rng.random((p.shape[0], self.n_sources, 1))
        u = (cum < r).sum(axis=-1)
        # cum[-1] may round to just below r; clamp to the last real class.
        return np.minimum(u, self._kmax_minus1).astype(np.int64, copy=False)

    # -- helpers ---------------------------------------------------------------------------
    def _check_dsets(self, dsets) -> np.ndarray:
        d = np.asarray(dsets)
        if d.ndim != 2 or d.shape[1] != self.dset_size:
            raise ValueError(
                f"{type(self).__name__} for {self.region.agent!r} expects d-sets of shape "
                f"[n, {self.dset_size}] ({self.dset_kind!r}), got {d.shape}"
            )
        if self.n == 0:
            raise RuntimeError(f"{type(self).__name__}: call reset(n) before probs()/sample()")
        if d.shape[0] != self.n:
            raise ValueError(f"reset({self.n}) was called but got {d.shape[0]} d-sets")
        return d

    def _sample_logits(self, logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Draw ``u`` from the per-source softmax of ``logits`` ``[n, sum K]``.

        Inverse-CDF sampling on the *unnormalised* cumulative ``exp``: ``u`` is the number of
        classes whose cumulative mass is below ``r * total``, ``r ~ U[0, 1)``. Padded
        classes add no mass, and ``r * total < total``, so ``u`` is always a real class.
        (Fewer numpy calls than normalising first: this is the IALS's hot path.)
        """
        n = logits.shape[0]
        if self._same_k:
            z = logits.reshape(n, self.n_sources, self.max_classes)
            z = z - z.max(axis=-1, keepdims=True)
        else:
            z = logits[:, self._gather]
            z[:, self._pad_mask] = -np.inf
            z -= z.max(axis=-1, keepdims=True)
        np.exp(z, out=z)
        np.cumsum(z, axis=-1, out=z)
        r = rng.random((n, self.n_sources, 1), dtype=z.dtype)
        r *= z[:, :, -1:]
        return (z < r).sum(axis=-1)

    def _sample_logits1(self, logits: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """:meth:`_sample_logits` for one history (``n=1``) with equal class counts: the same
        float operations in the same order (bitwise the same draws), on preallocated buffers
        and without numpy's Python-level wrappers (``max``, ``cumsum``, ``sum``)."""
        bufs = self._sample_bufs
        if bufs is None or bufs[0].dtype != logits.dtype:
            # 2-D [M, K] buffers: cheaper for numpy to iterate than [1, M, K] with broadcasting.
            shape = (self.n_sources, self.max_classes)
            z = np.empty(shape, logits.dtype)
            bufs = self._sample_bufs = (z, np.empty((self.n_sources, 1), logits.dtype),
                                        np.empty(shape, bool), z[:, -1:])
        z, m, less, total = bufs
        x = logits.reshape(z.shape)
        _max_reduce(x, 1, None, m, True)
        np.subtract(x, m, z)
        np.exp(z, z)
        _add_accumulate(z, 1, None, z)
        r = rng.random((self.n_sources, 1), dtype=z.dtype)  # same draws as shape (1, M, 1)
        np.multiply(r, total, r)
        np.less(z, r, less)
        return _add_reduce(less, 1, np.int64).reshape(1, self.n_sources)

    def _logits_to_padded(self, logits: np.ndarray) -> np.ndarray:
        z = logits[:, self._gather]
        z[:, self._pad_mask] = -np.inf
        z -= z.max(axis=-1, keepdims=True)
        np.exp(z, out=z)
        z /= z.sum(axis=-1, keepdims=True)
        return z

    def _arrays(self) -> dict[str, np.ndarray]:
        """The numeric state to save (weights, probabilities)."""
        return {}

    def _config(self) -> dict:
        """Constructor keyword arguments (JSON) other than region/dset_kind/metadata/arrays."""
        return {}

    def describe(self) -> str:
        return f"{self.name} ({self.dset_kind!r} d-set, {self.region.domain}/{self.region.agent})"

    def __repr__(self):
        return f"<{type(self).__name__} {self.describe()}>"


class _ConstantPredictor(InfluencePredictor):
    """A predictor whose probabilities do not depend on the history."""

    def __init__(self, region, probs, dset_kind="dset", metadata=None):
        super().__init__(region, dset_kind, metadata)
        table = np.zeros((self.n_sources, self.max_classes))
        if len(probs) != self.n_sources:
            raise ValueError(f"need {self.n_sources} probability vectors, got {len(probs)}")
        for m, (p, k) in enumerate(zip(probs, self.n_classes)):
            p = np.asarray(p, dtype=np.float64)
            if p.shape != (k,) or (p < 0).any() or not np.isclose(p.sum(), 1.0, atol=1e-6):
                raise ValueError(
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
        r = rng.random((self.n, self.n_sources, 1))
        return (self._cum < r).sum(axis=-1)

    def _arrays(self):
        return {"table": self.table}


class UniformPredictor(_ConstantPredictor):
    """The untrained AIP with fixed probabilities (SPEC §3, "untrained-IALS").

    By default uniform over each source's classes (0.25 per class for a 4-class warehouse
    source, 0.5 for a bit). ``probs`` overrides this (one vector per source), which is how a
    domain's ``Domain.extra["untrained_probs"]`` is applied.
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
    is not on a shared cell): the domain's ``Domain.extra["null_influence"]``, default 0.
    For a bit with ``null_class=0``, ``P(u=1) = p``. For a categorical source with ``K``
    classes, ``P(u=null_class) = 1 - p`` and ``p`` is spread uniformly over the other
    ``K - 1`` classes.
    """

    name = "fixed"

    def __init__(self, region, p: float = 0.1, dset_kind="dset", metadata=None, table=None, null_class=0):
        try:
            p = float(p)
        except (TypeError, ValueError):
            raise TypeError(f"fixed influence probability must be a number in [0, 1], got {p!r}") from None
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"fixed influence probability must be in [0, 1], got {p}")
        null_class = int(null_class)
        for k in region.influence_classes:
            if not 0 <= null_class < k:
                raise ValueError(f"null_class {null_class} out of range for a source with {k} classes")
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
            raise ValueError("MarginalPredictor needs probs (use MarginalPredictor.fit(dataset))")
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
    def fit(cls, dataset, dset_kind="dset", episodes=None) -> "MarginalPredictor":
        u = dataset.influences if episodes is None else dataset.influences[episodes]
        probs = cls.marginal_probs(u, dataset.region.influence_classes)
        return cls(dataset.region, probs, dset_kind, metadata={"fitted_on_steps": int(u.shape[0] * u.shape[1])})


class MLPPredictor(InfluencePredictor):
    """Feed-forward AIP without memory: ``d_t -> ReLU(W1 d_t + b1) -> one softmax per source``.

    The traffic AIP of the paper (hidden 64, input the current d-set). Weights are numpy
    arrays: ``w1 [D, H]``, ``b1 [H]``, ``w_out [H, sum K]``, ``b_out [sum K]``.
    """

    name = "mlp"
    arch = "mlp"

    def __init__(self, region, dset_kind="dset", hidden=64, arrays=None, seed=0, metadata=None):
        super().__init__(region, dset_kind, metadata)
        self.hidden = int(hidden)
        if arrays is None:
            arrays = init_arrays("mlp", self.dset_size, self.hidden, int(self._offsets[-1]), seed)
        self.set_arrays(arrays)

    def set_arrays(self, arrays):
        a = {k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()}
        shapes = {
            "w1": (self.dset_size, self.hidden),
            "b1": (self.hidden,),
            "w_out": (self.hidden, int(self._offsets[-1])),
            "b_out": (int(self._offsets[-1]),),
        }
        _check_shapes(a, shapes, "MLPPredictor")
        self.w1, self.b1, self.w_out, self.b_out = (np.ascontiguousarray(a[k]) for k in shapes)

    def _logits(self, dsets):
        d = self._check_dsets(dsets)
        h = d.astype(np.float32) @ self.w1
        h += self.b1
        np.maximum(h, 0.0, out=h)
        logits = h @ self.w_out
        logits += self.b_out
        return logits

    def probs_padded(self, dsets):
        return self._logits_to_padded(self._logits(dsets))

    def sample(self, dsets, rng):
        logits = self._logits(dsets)
        if self.n == 1 and self._same_k:
            return self._sample_logits1(logits, rng)
        return self._sample_logits(logits, rng)

    def _arrays(self):
        return {"w1": self.w1, "b1": self.b1, "w_out": self.w_out, "b_out": self.b_out}

    def _config(self):
        return {"hidden": self.hidden}


class GRUPredictor(InfluencePredictor):
    """Recurrent AIP: a GRU over ``d_0 .. d_t`` then one softmax head per source.

    The warehouse AIP of the paper (hidden 64, hidden state zeroed at episode start, i.e. by
    ``reset``). Same equations and gate order (r, z, n) as ``torch.nn.GRU``; weights are numpy
    arrays ``w_ih [D, 3H]``, ``w_hh [H, 3H]``, ``b_ih [3H]``, ``b_hh [3H]`` (torch's
    transposed), ``w_out [H, sum K]``, ``b_out [sum K]``.
    """

    name = "gru"
    arch = "gru"

    def __init__(self, region, dset_kind="dset", hidden=64, arrays=None, seed=0, metadata=None):
        super().__init__(region, dset_kind, metadata)
        self.hidden = int(hidden)
        if arrays is None:
            arrays = init_arrays("gru", self.dset_size, self.hidden, int(self._offsets[-1]), seed)
        self.set_arrays(arrays)
        self.h = np.zeros((0, self.hidden), dtype=np.float32)

    def set_arrays(self, arrays):
        a = {k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()}
        H, K = self.hidden, int(self._offsets[-1])
        shapes = {
            "w_ih": (self.dset_size, 3 * H),
            "w_hh": (H, 3 * H),
            "b_ih": (3 * H,),
            "b_hh": (3 * H,),
            "w_out": (H, K),
            "b_out": (K,),
        }
        _check_shapes(a, shapes, "GRUPredictor")
        self.w_ih, self.w_hh, self.b_ih, self.b_hh, self.w_out, self.b_out = (
            np.ascontiguousarray(a[k]) for k in shapes
        )
        self._gi_cache = {}
        self._bufs1 = None

    def reset(self, n=1):
        super().reset(n)
        self.h = np.zeros((self.n, self.hidden), dtype=np.float32)

    def probs_padded(self, dsets):
        return self._logits_to_padded(self._logits(dsets))

    def sample(self, dsets, rng):
        if self.n == 1:
            logits = self._logits1(self._check_dsets(dsets))
            if self._same_k:
                return self._sample_logits1(logits, rng)
            return self._sample_logits(logits, rng)
        return self._sample_logits(self._logits(dsets), rng)

    # The d-set projection d @ w_ih + b_ih of at most this many distinct d-sets is memoised
    # for single-history sampling (binary d-sets repeat a lot; 8192 x 3H floats = 6 MB).
    _GI_CACHE_SIZE = 8192

    def _logits1(self, d):
        """:meth:`_logits` for one history: the same float operations in the same order
        (bitwise the same logits), with ``d @ w_ih + b_ih`` memoised per d-set and the
        intermediate arrays preallocated. Returns a buffer reused by the next call."""
        key = d.tobytes()
        gi = self._gi_cache.get(key)
        if gi is None:
            H = self.hidden
            g = d.astype(np.float32) @ self.w_ih
            g += self.b_ih
            g.flags.writeable = False
            if len(self._gi_cache) >= self._GI_CACHE_SIZE:
                self._gi_cache.clear()
            gi = self._gi_cache[key] = (g[:, : 2 * H], g[:, 2 * H :])
        gi_rz, gi_n = gi
        if self._bufs1 is None:
            self._make_bufs1()
        gh, gh_rz, gh_n, rz, r, z, n, logits = self._bufs1
        add, mul = np.add, np.multiply
        h_old, h = self.h, self._h_spare
        np.dot(h_old, self.w_hh, gh)
        add(gh, self.b_hh, gh)
        add(gi_rz, gh_rz, rz)
        # _sigmoid(rz, out=rz), with 0-d float32 constants (a Python float operand costs a
        # scalar conversion per call; the values are exact in float32, so same results).
        mul(rz, _HALF32, rz)
        np.tanh(rz, rz)
        add(rz, _ONE32, rz)
        mul(rz, _HALF32, rz)
        mul(r, gh_n, n)
        add(n, gi_n, n)
        np.tanh(n, n)
        # h' = (1 - z) * n + z * h = n + z * (h - n)
        np.subtract(h_old, n, h)
        mul(h, z, h)
        add(h, n, h)
        self.h, self._h_spare = h, h_old
        np.dot(h, self.w_out, logits)
        add(logits, self.b_out, logits)
        return logits

    def _make_bufs1(self):
        H = self.hidden
        gh = np.empty((1, 3 * H), np.float32)
        rz = np.empty((1, 2 * H), np.float32)
        # Buffers and their fixed views (slicing costs as much as a small ufunc call).
        self._bufs1 = (
            gh, gh[:, : 2 * H], gh[:, 2 * H :], rz, rz[:, :H], rz[:, H:],
            np.empty((1, H), np.float32),  # n
            np.empty((1, int(self._offsets[-1])), np.float32),  # logits
        )
        self._h_spare = np.empty((1, H), np.float32)  # swapped with h every step

    def _logits(self, dsets):
        d = self._check_dsets(dsets)
        H = self.hidden
        gi = d.astype(np.float32) @ self.w_ih
        gi += self.b_ih
        gh = self.h @ self.w_hh
        gh += self.b_hh
        rz = gi[:, : 2 * H]
        rz += gh[:, : 2 * H]
        _sigmoid(rz, out=rz)
        r, z = rz[:, :H], rz[:, H:]
        n = gi[:, 2 * H :]
        n += r * gh[:, 2 * H :]
        np.tanh(n, out=n)
        # h' = (1 - z) * n + z * h = n + z * (h - n)
        h = self.h - n
        h *= z
        h += n
        self.h = h
        logits = h @ self.w_out
        logits += self.b_out
        return logits

    def _arrays(self):
        return {
            "w_ih": self.w_ih,
            "w_hh": self.w_hh,
            "b_ih": self.b_ih,
            "b_hh": self.b_hh,
            "w_out": self.w_out,
            "b_out": self.b_out,
        }

    def _config(self):
        return {"hidden": self.hidden}


ARCHS = {"mlp": MLPPredictor, "gru": GRUPredictor}
_CLASSES = {
    cls.__name__: cls
    for cls in (MLPPredictor, GRUPredictor, UniformPredictor, FixedPredictor, MarginalPredictor)
}


def _check_shapes(arrays, shapes, who):
    missing = set(shapes) - set(arrays)
    if missing:
        raise ValueError(f"{who}: missing weight arrays {sorted(missing)}")
    for k, s in shapes.items():
        if arrays[k].shape != s:
            raise ValueError(f"{who}: weight {k!r} has shape {arrays[k].shape}, expected {s}")
        if not np.isfinite(arrays[k]).all():
            raise ValueError(f"{who}: weight {k!r} is not finite")


def init_arrays(arch: str, d: int, hidden: int, n_logits: int, seed: int = 0) -> dict:
    """Random initial weights with torch's default distributions (``nn.GRU``/``nn.Linear``).

    A GRU's weights and biases are ``U(-1/sqrt(H), 1/sqrt(H))``; a linear layer's are
    ``U(-1/sqrt(fan_in), 1/sqrt(fan_in))``. Training starts from exactly these, so the
    "random-init" predictor of a seed is the trained one's starting point.
    """
    rng = np.random.default_rng(seed)

    def u(bound, shape):
        return rng.uniform(-bound, bound, size=shape).astype(np.float32)

    if arch == "mlp":
        return {
            "w1": u(1 / np.sqrt(d), (d, hidden)),
            "b1": u(1 / np.sqrt(d), (hidden,)),
            "w_out": u(1 / np.sqrt(hidden), (hidden, n_logits)),
            "b_out": u(1 / np.sqrt(hidden), (n_logits,)),
        }
    if arch == "gru":
        b = 1 / np.sqrt(hidden)
        return {
            "w_ih": u(b, (d, 3 * hidden)),
            "w_hh": u(b, (hidden, 3 * hidden)),
            "b_ih": u(b, (3 * hidden,)),
            "b_hh": u(b, (3 * hidden,)),
            "w_out": u(b, (hidden, n_logits)),
            "b_out": u(b, (n_logits,)),
        }
    raise ValueError(f"unknown AIP architecture {arch!r}; expected one of {sorted(ARCHS)}")


def random_init_predictor(region, arch="gru", dset_kind="dset", hidden=64, seed=0):
    """A randomly initialised (untrained) network AIP: SPEC §3's other "untrained" variant."""
    if arch not in ARCHS:
        raise ValueError(f"unknown AIP architecture {arch!r}; expected one of {sorted(ARCHS)}")
    pred = ARCHS[arch](region, dset_kind=dset_kind, hidden=hidden, seed=seed)
    pred.metadata.update({"variant": "random-init", "seed": int(seed)})
    return pred


def evaluate_cross_entropy(predictor: InfluencePredictor, dataset, episodes=None) -> float:
    """Mean cross-entropy (nats) of ``predictor`` on ``dataset``.

    ``CE = (1/M) sum_m mean_{episode, t} [-ln p_m(u_{t,m} | d_0..d_t)]``: the per-step
    negative log-likelihood of each source, averaged over steps and episodes, then over the
    ``M`` sources (so a uniform guess over 4 classes scores ln 4 = 1.386 whatever ``M``).
    The recurrent state is reset at the start of every episode. ``episodes`` selects a
    subset (index array); default all.
    """
    return float(np.mean(cross_entropy_per_source(predictor, dataset, episodes)))


def cross_entropy_per_source(predictor, dataset, episodes=None) -> np.ndarray:
    """Per-source mean cross-entropy (nats), shape ``[M]``; see :func:`evaluate_cross_entropy`."""
    if predictor.region.influence_classes != dataset.region.influence_classes:
        raise ValueError(
            f"predictor sources {predictor.region.influence_classes} do not match the data "
            f"set's {dataset.region.influence_classes}"
        )
    d = dataset.dsets[predictor.dset_kind]
    u = dataset.influences
    if episodes is not None:
        d, u = d[episodes], u[episodes]
    E, T, M = u.shape
    if E == 0:
        raise ValueError("cannot evaluate the cross-entropy on an empty data set")
    nll = np.zeros(M)
    rows = np.arange(E)[:, None]
    cols = np.arange(M)[None, :]
    predictor.reset(E)
    for t in range(T):
        p = predictor.probs_padded(d[:, t])
        pu = p[rows, cols, u[:, t]]
        nll -= np.log(np.maximum(pu, 1e-12)).sum(axis=0)
    return nll / (E * T)


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def _package_version() -> str:
    from ials_zoo import __version__

    return __version__


def save_predictor(predictor: InfluencePredictor, path) -> Path:
    """Save ``predictor`` to one file (atomic), see the module docstring for the format."""
    import torch

    from ials_zoo.utils import atomic_path

    if not isinstance(predictor, InfluencePredictor):
        raise TypeError(f"expected an InfluencePredictor, got {type(predictor).__name__}")
    cls_name = type(predictor).__name__
    if cls_name not in _CLASSES:
        raise TypeError(f"cannot save predictor class {cls_name}")
    meta = dict(predictor.metadata)
    meta.setdefault("created", time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    meta["package_version"] = meta.get("package_version") or _package_version()
    meta.update(
        {
            "env_id": predictor.region.domain,
            "agent": predictor.region.agent,
            "region": predictor.region.to_dict(),
            "dset_kind": predictor.dset_kind,
            "predictor": predictor.name,
            "config": predictor._config(),
        }
    )
    payload = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "class": cls_name,
        "metadata_json": json.dumps(meta, sort_keys=True, default=_json_default),
        "arrays": {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in predictor._arrays().items()},
    }
    path = Path(path)
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
        _readable(tmp)
    return path


def _readable(path) -> None:
    """Give a file the usual ``0666 & ~umask`` mode (temporary files are created 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def load_predictor(path, env_id: str | None = None, agent: str | None = None) -> InfluencePredictor:
    """Load a predictor saved by :func:`save_predictor`.

    ``env_id``/``agent``, when given, must match the ones it was trained for (a clear
    ``ValueError`` naming both otherwise). A file that is not a predictor file (corrupt,
    truncated, something else) raises ``ValueError("not an ials_zoo influence predictor: ...")``.
    """
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"influence predictor file not found: {path}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds for a corrupt/foreign file
        raise ValueError(f"not an ials_zoo influence predictor: {path} ({type(exc).__name__}: {exc})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ValueError(f"not an ials_zoo influence predictor: {path} (no {FORMAT!r} header)")
    if payload.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{path}: influence predictor format version {payload.get('format_version')!r}, this "
            f"ials_zoo reads version {FORMAT_VERSION}"
        )
    try:
        meta = json.loads(payload["metadata_json"])
        cls = _CLASSES[payload["class"]]
        region = RegionSpec.from_dict(meta["region"])
        arrays = {k: v.numpy() for k, v in payload["arrays"].items()}
        kwargs = dict(meta.get("config", {}))
        if cls in ARCHS.values():
            pred = cls(region, dset_kind=meta["dset_kind"], arrays=arrays, metadata=meta, **kwargs)
        else:
            pred = cls(region, dset_kind=meta["dset_kind"], metadata=meta, table=arrays["table"], **kwargs)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"not an ials_zoo influence predictor: {path} (bad content: {exc})") from None
    if env_id is not None and region.domain != env_id:
        raise ValueError(
            f"{path} is an influence predictor for domain {region.domain!r}, not {env_id!r}"
        )
    if agent is not None and region.agent != agent:
        raise ValueError(
            f"{path} is an influence predictor for agent {region.agent!r} of {region.domain}, "
            f"not for agent {agent!r}"
        )
    return pred


def predictor_info(path) -> dict:
    """The metadata of a predictor file (see :func:`load_predictor`)."""
    return dict(load_predictor(path).metadata)


__all__ = [
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
    "random_init_predictor",
    "save_predictor",
]
