"""The influence-predictor interface (paper §4.2): ``P(u_t | d_0 .. d_t)``, or, for an
*autoregressive* predictor, ``P(u_t | d_0 .. d_t, u_0 .. u_{t-1})``.

Every predictor implements :class:`InfluencePredictor`, the interface the IALS uses:

* ``reset(n)`` -- start ``n`` parallel histories (zero recurrent state);
* ``probs(dsets)`` -- feed the current d-sets ``d_t`` of shape ``[n, D]`` (advancing the
  recurrent state, if any) and return one ``[n, K_m]`` probability array per source;
* ``sample(dsets, rng)`` -- the same, then draw ``u_t`` (int64, ``[n, M]``).

The sources are independent given the history (one softmax head per source, paper §4.2).

An autoregressive predictor (``autoregressive=True``, :mod:`ials_zoo.influence.networks`) also
reads the influence of the previous ``influence_lags`` steps (1 by default), one-hot per source,
beside ``d_t``, the latest first: what it sampled itself (``sample`` remembers its draws) or,
under teacher forcing, the recorded ``u_{t-1} .. u_{t-L}`` (:meth:`InfluencePredictor.observe`,
what the cross-entropy on data does; zeros before the episode's start). A predictor that
forgets its own samples turns one neighbour that lingers into a string of fresh arrivals (the
warehouse, ``ials-zoo fidelity``); conditioning on ``u_{<t}`` is how it remembers. The sources
of a region are still factored into independent heads given that input: each head sees every
source's previous class, so a neighbour moving from one shared cell to the next is visible to
both cells' heads. More than one lag is for arrivals whose timing carries over a few steps: the
cars a neighbouring light releases in a platoon enter a traffic lane 2-3 steps apart, which
``u_{t-1}`` alone does not show (``docs/fidelity.md``).
Sampling from logits is shared here (:meth:`InfluencePredictor._sample_logits`, and a
single-history path, :meth:`InfluencePredictor._sample_logits1`, bitwise the same draws).
"""

from __future__ import annotations

import numpy as np

from ials_zoo.core.region import RegionSpec, check_dset_kind
from ials_zoo.errors import BadInput, BadInputType

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


def count_below(cum: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Inverse-CDF sampling's classes: per entry of ``r`` (``[..., M]``), how many of its
    cumulative masses ``cum`` (``[..., M, K]``, broadcast) lie below it, int64. A loop over the
    few classes is about 4x faster than one ``[..., M, K]`` comparison summed over its last axis,
    and draws the same classes."""
    out = np.zeros(np.broadcast_shapes(r.shape, cum.shape[:-1]), np.int64)
    for k in range(cum.shape[-1]):
        out += cum[..., k] < r
    return out


class InfluencePredictor:
    """Interface of every influence predictor (see the module docstring).

    Attributes:
        region: the region this predictor is for (domain, agent, sources, d-set layout).
        dset_kind: which d-set it reads, ``"dset"`` or ``"full"``.
        metadata: free-form provenance (hyper-parameters, cross-entropies, ...), saved with it.
        source: the file it was loaded from, None when it was made in this process (not saved:
            it says where this object came from, so a run can tell a shipped AIP from one it
            trained).
    """

    name = "base"
    autoregressive = False
    influence_lags = 0  # past steps of its own influence an autoregressive predictor reads
    clock_horizon = 0  # > 0: the predictor also reads min(t, clock_horizon) / clock_horizon
    source = None

    def __init__(self, region: RegionSpec, dset_kind: str = "dset", metadata: dict | None = None):
        if not isinstance(region, RegionSpec):
            raise BadInputType(f"region must be a RegionSpec, got {type(region).__name__}")
        self.region = region
        self.dset_kind = check_dset_kind(dset_kind)
        self.metadata = dict(metadata or {})
        classes = np.asarray(region.influence_classes, dtype=np.int64)
        if classes.size == 0:
            raise BadInput(f"region of {region.agent!r} has no influence sources")
        if (classes < 2).any():
            raise BadInput(f"every influence source needs >= 2 classes, got {tuple(classes)}")
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
        self.input_size = (self.dset_size + self.influence_lags * int(self._offsets[-1])
                           + (1 if self.clock_horizon else 0))
        self._t = 0  # steps since reset(): every history of a predictor starts together
        self._previous = np.zeros((0, self.influence_lags * int(self._offsets[-1])), np.float32)

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
            raise BadInput(f"n must be >= 1, got {n}")
        self.n = n
        self._t = 0
        if self.autoregressive:
            self._previous = np.zeros((n, self.influence_lags * int(self._offsets[-1])), np.float32)

    def observe(self, influences: np.ndarray) -> None:
        """Tell an autoregressive predictor the influence ``u_t`` (int ``[n, M]``) that the next
        step conditions on (teacher forcing); ``sample`` does this with its own draw. A
        predictor without that input ignores it."""
        if not self.autoregressive:
            return
        u = np.asarray(influences)
        if u.shape != (self.n, self.n_sources):
            raise BadInput(f"expected influences of shape {(self.n, self.n_sources)}, got {u.shape}")
        self._previous = shift_in(self._previous, one_hot_influences(u, self._offsets))

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
        u = count_below(cum, rng.random((p.shape[0], self.n_sources)))
        # cum[-1] may round to just below r; clamp to the last real class.
        u = np.minimum(u, self._kmax_minus1).astype(np.int64, copy=False)
        self.observe(u)
        return u

    # -- helpers ---------------------------------------------------------------------------
    def _check_dsets(self, dsets) -> np.ndarray:
        d = np.asarray(dsets)
        if d.ndim != 2 or d.shape[1] != self.dset_size:
            raise BadInput(
                f"{type(self).__name__} for {self.region.agent!r} expects d-sets of shape "
                f"[n, {self.dset_size}] ({self.dset_kind!r}), got {d.shape}"
            )
        if self.n == 0:
            raise RuntimeError(f"{type(self).__name__}: call reset(n) before probs()/sample()")
        if d.shape[0] != self.n:
            raise BadInput(f"reset({self.n}) was called but got {d.shape[0]} d-sets")
        return d

    def _input(self, d: np.ndarray) -> np.ndarray:
        """The network's input: ``d_t``, for an autoregressive predictor the one-hot
        ``u_{t-1} .. u_{t-L}`` beside it, and for one with a clock ``min(t, H) / H`` (float32);
        a call is a step (the clock advances)."""
        if not (self.autoregressive or self.clock_horizon):
            return d
        parts = [d.astype(np.float32, copy=False)]
        if self.autoregressive:
            parts.append(self._previous)
        if self.clock_horizon:
            parts.append(np.full((d.shape[0], 1), clock_value(self._t, self.clock_horizon), np.float32))
            self._t += 1
        return np.concatenate(parts, axis=1)

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
        r = rng.random((n, self.n_sources), dtype=z.dtype)
        r *= z[:, :, -1]
        return count_below(z, r)

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


def one_hot_influences(u: np.ndarray, offsets) -> np.ndarray:
    """``u`` (int ``[..., M]``) as the concatenated one-hot ``[..., sum K_m]`` (float32):
    source ``m``'s class ``k`` at column ``offsets[m] + k``."""
    u = np.asarray(u)
    out = np.zeros(u.shape[:-1] + (int(offsets[-1]),), np.float32)
    cols = u + np.asarray(offsets[:-1], np.int64)
    np.put_along_axis(out, cols, 1.0, axis=-1)
    return out


def shift_in(previous: np.ndarray, latest: np.ndarray) -> np.ndarray:
    """The autoregressive input one step on: ``latest`` (``[..., sum K]``) in front of
    ``previous`` (``[..., L * sum K]``, the latest lag first), the oldest lag dropped."""
    width = latest.shape[-1]
    if previous.shape[-1] == width:
        return latest
    return np.concatenate([latest, previous[..., :-width]], axis=-1)


def previous_influences(u: np.ndarray, offsets, lags: int = 1) -> np.ndarray:
    """The autoregressive input of recorded episodes ``u`` (``[E, T, M]``): at step ``t`` the
    one-hot ``u_{t-1} .. u_{t-lags}`` side by side, the latest first, zeros before the episode's
    start (teacher forcing), ``[E, T, lags * sum K]``."""
    onehot = one_hot_influences(u, offsets)
    T, width = onehot.shape[1], onehot.shape[2]
    out = np.zeros(onehot.shape[:2] + (lags * width,), np.float32)
    for k in range(1, min(lags, T - 1) + 1):
        out[:, k:, (k - 1) * width:k * width] = onehot[:, :-k]
    return out


MAX_INFLUENCE_LAGS = 64
"""The most past draws an autoregressive AIP reads (the networks' input grows with each: our
domains use 1-3; 100,000 would ask for tens of GiB)."""


def check_influence_lags(lags) -> int:
    """``lags`` as an int in [1, :data:`MAX_INFLUENCE_LAGS`], else :class:`BadInput` naming it."""
    if isinstance(lags, bool) or not isinstance(lags, (int, np.integer)) or not 1 <= lags <= MAX_INFLUENCE_LAGS:
        raise BadInput(f"influence_lags must be an int in [1, {MAX_INFLUENCE_LAGS}], got {lags!r}")
    return int(lags)


def check_clock_horizon(horizon) -> int:
    """``horizon`` as an int >= 0 (0: no clock), else :class:`BadInput` naming it."""
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 0:
        raise BadInput(f"clock_horizon must be an int >= 0 (0: no clock), got {horizon!r}")
    return int(horizon)


def clock_value(t, horizon: int):
    """The clock input at step ``t`` (int or int array) of an episode: ``min(t, horizon) / horizon``."""
    return np.minimum(t, horizon) / horizon


def resolve_influence_lags(autoregressive: bool, lags) -> int:
    """The past draws an AIP reads: ``lags`` (None: 1) for an autoregressive AIP, 0 for a
    memoryless one, which must not be given any (None or 0), else :class:`BadInput`."""
    if autoregressive:
        return 1 if lags is None else check_influence_lags(lags)
    if lags is None or (not isinstance(lags, bool) and isinstance(lags, (int, np.integer)) and lags == 0):
        return 0
    raise BadInput(f"influence_lags={lags!r} needs an autoregressive AIP (autoregressive=True)")


def _check_shapes(arrays, shapes, who):
    missing = set(shapes) - set(arrays)
    if missing:
        raise BadInput(f"{who}: missing weight arrays {sorted(missing)}")
    for k, s in shapes.items():
        if arrays[k].shape != s:
            raise BadInput(f"{who}: weight {k!r} has shape {arrays[k].shape}, expected {s}")
        if not np.isfinite(arrays[k]).all():
            raise BadInput(f"{who}: weight {k!r} is not finite")
