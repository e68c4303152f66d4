"""Neural influence predictors with numpy inference: :class:`MLPPredictor` (no memory, the
traffic AIP) and :class:`GRUPredictor` (memory, the warehouse AIP). Either can be
*autoregressive* (``autoregressive=True``): its input is ``d_t`` and the one-hot ``u_{t-1}``,
or ``u_{t-1} .. u_{t-L}`` with ``influence_lags=L`` (:mod:`ials_zoo.influence.base`), so an MLP
then models ``P(u_t | d_t, u_{t-L} .. u_{t-1})`` and a GRU ``P(u_t | d_<=t, u_<t)``.

Inference is plain numpy (weights copied out of torch after training): a torch call at batch
1 costs more than a whole local-simulator step. A single history (``reset(1)``, the
:class:`~ials_zoo.influence.ials.IALSEnv` case) takes a dedicated path: the same float
operations in the same order as the batched code (bitwise the same draws), on preallocated
buffers, with the GRU's input projection memoised per d-set.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.influence.base import (
    _HALF32,
    _ONE32,
    InfluencePredictor,
    _check_shapes,
    _sigmoid,
    check_clock_horizon,
    resolve_influence_lags,
)


def _config(p) -> dict:
    """The constructor keywords saved with a network AIP (one lag, the first autoregressive
    AIPs' only kind, is left implicit so that their files stay as they were)."""
    out = {"hidden": p.hidden}
    if p.autoregressive:
        out["autoregressive"] = True
        if p.influence_lags != 1:
            out["influence_lags"] = p.influence_lags
    if p.clock_horizon:
        out["clock_horizon"] = p.clock_horizon
    return out


class MLPPredictor(InfluencePredictor):
    """Feed-forward AIP without memory: ``d_t -> ReLU(W1 d_t + b1) -> one softmax per source``.

    The traffic AIP of the paper (hidden 64, input the current d-set). Weights are numpy
    arrays: ``w1 [D, H]``, ``b1 [H]``, ``w_out [H, sum K]``, ``b_out [sum K]``.
    """

    name = "mlp"
    arch = "mlp"

    def __init__(self, region, dset_kind="dset", hidden=64, arrays=None, seed=0, metadata=None,
                 autoregressive=False, influence_lags=None, clock_horizon=0):
        self.autoregressive = bool(autoregressive)
        self.influence_lags = resolve_influence_lags(self.autoregressive, influence_lags)
        self.clock_horizon = check_clock_horizon(clock_horizon)
        super().__init__(region, dset_kind, metadata)
        self.hidden = int(hidden)
        if arrays is None:
            arrays = init_arrays("mlp", self.input_size, self.hidden, int(self._offsets[-1]), seed)
        self.set_arrays(arrays)

    def set_arrays(self, arrays):
        a = {k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()}
        shapes = {
            "w1": (self.input_size, self.hidden),
            "b1": (self.hidden,),
            "w_out": (self.hidden, int(self._offsets[-1])),
            "b_out": (int(self._offsets[-1]),),
        }
        _check_shapes(a, shapes, "MLPPredictor")
        self.w1, self.b1, self.w_out, self.b_out = (np.ascontiguousarray(a[k]) for k in shapes)

    def _logits(self, dsets):
        d = self._input(self._check_dsets(dsets))
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
            u = self._sample_logits1(logits, rng)
        else:
            u = self._sample_logits(logits, rng)
        if self.autoregressive:
            self.observe(u)
        return u

    def _arrays(self):
        return {"w1": self.w1, "b1": self.b1, "w_out": self.w_out, "b_out": self.b_out}

    def _config(self):
        return _config(self)


class GRUPredictor(InfluencePredictor):
    """Recurrent AIP: a GRU over ``d_0 .. d_t`` then one softmax head per source.

    The warehouse AIP of the paper (hidden 64, hidden state zeroed at episode start, i.e. by
    ``reset``). Same equations and gate order (r, z, n) as ``torch.nn.GRU``; weights are numpy
    arrays ``w_ih [D, 3H]``, ``w_hh [H, 3H]``, ``b_ih [3H]``, ``b_hh [3H]`` (torch's
    transposed), ``w_out [H, sum K]``, ``b_out [sum K]``.
    """

    name = "gru"
    arch = "gru"

    def __init__(self, region, dset_kind="dset", hidden=64, arrays=None, seed=0, metadata=None,
                 autoregressive=False, influence_lags=None, clock_horizon=0):
        self.autoregressive = bool(autoregressive)
        self.influence_lags = resolve_influence_lags(self.autoregressive, influence_lags)
        self.clock_horizon = check_clock_horizon(clock_horizon)
        super().__init__(region, dset_kind, metadata)
        self.hidden = int(hidden)
        if arrays is None:
            arrays = init_arrays("gru", self.input_size, self.hidden, int(self._offsets[-1]), seed)
        self.set_arrays(arrays)
        self.h = np.zeros((0, self.hidden), dtype=np.float32)

    def set_arrays(self, arrays):
        a = {k: np.asarray(v, dtype=np.float32) for k, v in arrays.items()}
        H, K = self.hidden, int(self._offsets[-1])
        shapes = {
            "w_ih": (self.input_size, 3 * H),
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
            d = self._check_dsets(dsets)
            logits = self._logits1(self._input(d))
            u = self._sample_logits1(logits, rng) if self._same_k else self._sample_logits(logits, rng)
        else:
            u = self._sample_logits(self._logits(dsets), rng)
        if self.autoregressive:
            self.observe(u)
        return u

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
        d = self._input(self._check_dsets(dsets))
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
        return _config(self)


ARCHS = {"mlp": MLPPredictor, "gru": GRUPredictor}


def init_arrays(arch: str, d: int, hidden: int, n_logits: int, seed: int = 0) -> dict:
    """Random initial weights with torch's default distributions (``nn.GRU``/``nn.Linear``).

    A GRU's weights and biases are ``U(-1/sqrt(H), 1/sqrt(H))``; a linear layer's are
    ``U(-1/sqrt(fan_in), 1/sqrt(fan_in))``. Training starts from exactly these, so the
    untrained predictor of a seed is the trained one's starting point.
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
    raise BadInput(f"unknown AIP architecture {arch!r}; expected one of {sorted(ARCHS)}")


def untrained_predictor(region, arch="gru", dset_kind="dset", hidden=64, seed=0, autoregressive=False,
                        influence_lags=None, clock_horizon=0):
    """A randomly initialised network AIP: the paper's untrained-IALS (SPEC §3)."""
    if arch not in ARCHS:
        raise BadInput(f"unknown AIP architecture {arch!r}; expected one of {sorted(ARCHS)}")
    pred = ARCHS[arch](region, dset_kind=dset_kind, hidden=hidden, seed=seed, autoregressive=autoregressive,
                       influence_lags=influence_lags, clock_horizon=clock_horizon)
    pred.metadata.update({"variant": "untrained", "seed": int(seed)})
    return pred
