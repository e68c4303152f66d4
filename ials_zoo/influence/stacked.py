"""The AIPs of many agents, evaluated in one computation (the multi-agent IALS, DIALS).

:class:`StackedPredictor` holds one influence predictor per agent and answers for ``n_envs``
histories of each (rows agent-major, as in the local simulators). Agents whose predictors have
the same kind and shapes form a *group* whose weights are stacked on a leading agent axis, so
a step costs one batched matrix product per layer per group (``numpy.matmul`` over
``[G, n, D] x [G, D, H]``: each agent's slice is computed exactly as its own predictor would
compute it). Regions of one domain share a layout (sources, classes, d-set size), which is
what lets their rows share one batch; a domain whose agents use different architectures
simply has several groups.

Sampling draws, per row, one uniform number per source from that row's own stream
(:class:`ials_zoo.core.streams.CopyStreams`), so an agent's influence sources never depend on
which other agents share the batch. Replacing predictors (:meth:`StackedPredictor.replace`,
what DIALS does after retraining) restacks only the groups concerned. An autoregressive group
(:mod:`ials_zoo.influence.base`) keeps each row's last draws (``influence_lags`` of them) and
reads them at the next step.
"""

from __future__ import annotations

import numpy as np

from ials_zoo.core.streams import CopyStreams
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.influence.base import InfluencePredictor, _sigmoid, clock_value, one_hot_influences, shift_in
from ials_zoo.influence.constant import _ConstantPredictor
from ials_zoo.influence.networks import GRUPredictor, MLPPredictor

STREAM_SALT = 1  # separates the AIP's streams from the local simulator's (same seed, same agents)


def _group_key(p: InfluencePredictor) -> tuple:
    if isinstance(p, MLPPredictor):
        return ("mlp", p.hidden, p.autoregressive, p.influence_lags, p.clock_horizon)
    if isinstance(p, GRUPredictor):
        return ("gru", p.hidden, p.autoregressive, p.influence_lags, p.clock_horizon)
    if isinstance(p, _ConstantPredictor):
        return ("table",)
    raise BadInputType(f"cannot stack a {type(p).__name__}")


class _Group:
    def __init__(self, kind, members: list[int], predictors: list[InfluencePredictor]):
        self.kind, self.members = kind, np.array(members)
        ps = [predictors[i] for i in members]
        self.autoregressive = bool(ps[0].autoregressive)
        self.lags = ps[0].influence_lags
        self.clock = ps[0].clock_horizon  # 0 for a table group: constant AIPs read no clock
        self.offsets = ps[0]._offsets
        self.previous = None  # [G, n, L * sum K]: the one-hot u_{t-1} .. u_{t-L} of an autoregressive group
        if kind == "mlp":
            self.w = [np.stack([getattr(p, k) for p in ps]) for k in ("w1", "b1", "w_out", "b_out")]
        elif kind == "gru":
            # torch's GRU equations, with the weights laid out for few, contiguous products:
            # [d, h] @ W_rz (both gates at once), d @ W_in, h @ W_hn, h @ W_out
            H = self.hidden = ps[0].hidden
            st = lambda k: np.stack([getattr(p, k) for p in ps])
            w_ih, w_hh, b_ih, b_hh = st("w_ih"), st("w_hh"), st("b_ih"), st("b_hh")
            self.w_rz = np.ascontiguousarray(np.concatenate([w_ih[..., :2 * H], w_hh[..., :2 * H]], axis=1))
            self.b_rz = (b_ih[:, :2 * H] + b_hh[:, :2 * H])[:, None]
            self.w_in, self.b_in = np.ascontiguousarray(w_ih[..., 2 * H:]), b_ih[:, None, 2 * H:]
            self.w_hn, self.b_hn = np.ascontiguousarray(w_hh[..., 2 * H:]), b_hh[:, None, 2 * H:]
            self.w_out, self.b_out = st("w_out"), st("b_out")[:, None]
        else:
            self.table = np.stack([p.table for p in ps])  # [G, M, Kmax]
            cum = np.cumsum(self.table, axis=-1)
            for m, k in enumerate(ps[0].n_classes):
                cum[:, m, k - 1:] = 2.0  # never below u < 1: the last real class takes the rest
            self.cum = cum
        self.h = None

    def reset(self, n: int):
        if self.kind == "gru":
            self.h = np.zeros((len(self.members), n, self.hidden), np.float32)
        if self.autoregressive:
            self.previous = np.zeros((len(self.members), n, self.lags * int(self.offsets[-1])), np.float32)

    def remember(self, u):  # u: [G, n, M], what an autoregressive group reads at the next step
        if self.autoregressive:
            self.previous = shift_in(self.previous, one_hot_influences(u, self.offsets))

    def logits(self, d, t: int):  # d: [G, n, D] float32; t: steps since the histories started
        if self.autoregressive:
            d = np.concatenate([d, self.previous], axis=-1)
        if self.clock:
            tick = np.full(d.shape[:-1] + (1,), clock_value(t, self.clock), np.float32)
            d = np.concatenate([d, tick], axis=-1)
        if self.kind == "mlp":
            w1, b1, w_out, b_out = self.w
            h = np.matmul(d, w1)
            h += b1[:, None, :]
            np.maximum(h, 0.0, out=h)
            out = np.matmul(h, w_out)
            out += b_out[:, None, :]
            return out
        H = self.hidden
        x = np.concatenate([d, self.h], axis=-1)
        rz = np.matmul(x, self.w_rz)
        rz += self.b_rz
        _sigmoid(rz, out=rz)
        r, z = rz[..., :H], rz[..., H:]
        gn = np.matmul(self.h, self.w_hn)
        gn += self.b_hn
        gn *= r
        n = np.matmul(d, self.w_in)
        n += self.b_in
        n += gn
        np.tanh(n, out=n)
        # h' = (1 - z) * n + z * h = n + z * (h - n)
        h = self.h - n
        h *= z
        h += n
        self.h = h
        out = np.matmul(h, self.w_out)
        out += self.b_out
        return out


class StackedPredictor:
    """One influence predictor per agent, ``n_envs`` histories each (module docstring).

    Args:
        predictors: one per agent, in row order (agent-major).
        n_envs: histories (copies) per agent.
    """

    def __init__(self, predictors, n_envs: int = 1):
        self.predictors = list(predictors)
        if not self.predictors:
            raise BadInput("a stacked predictor needs at least one predictor")
        first = self.predictors[0]
        for p in self.predictors:
            if not isinstance(p, InfluencePredictor):
                raise BadInputType(f"expected InfluencePredictors, got {type(p).__name__}")
            if (p.region.influence_classes, p.dset_size, p.dset_kind) != (
                    first.region.influence_classes, first.dset_size, first.dset_kind):
                raise BadInput(f"the predictors of {first.region.agent} and {p.region.agent} read or predict "
                                 "different layouts; the regions of a batch must share one")
        self.agents = [p.region.agent for p in self.predictors]
        if len(set(self.agents)) != len(self.agents):
            raise BadInput(f"one predictor per agent, got {self.agents}")
        self.dset_kind = first.dset_kind
        self.n_sources, self.max_classes = first.n_sources, first.max_classes
        self._layout = first
        self.n_envs = int(n_envs)
        self.streams = CopyStreams(self.agents, self.n_envs, self.n_sources, salt=STREAM_SALT)
        self._build()
        self.reset()

    def _build(self):
        keys: dict = {}
        for i, p in enumerate(self.predictors):
            keys.setdefault(_group_key(p), []).append(i)
        self.groups = [_Group(k[0], members, self.predictors) for k, members in keys.items()]

    @property
    def rows(self) -> int:
        return len(self.agents) * self.n_envs

    def seed(self, seed: int | None) -> None:
        """Seed every row's sampling stream (from ``seed`` and the agents' names)."""
        self.streams.seed(seed)

    def reset(self) -> None:
        """Start new histories (zero recurrent states and the clock) in every row."""
        self.t = 0  # steps since the histories started (they all start together)
        for g in self.groups:
            g.reset(self.n_envs)

    def replace(self, predictors: dict) -> None:
        """Swap in new predictors ``{agent: predictor}`` (their recurrent state starts at zero
        at the next :meth:`reset`)."""
        for agent, p in predictors.items():
            i = self.agents.index(agent)
            if p.region.agent != agent or p.region.influence_classes != self._layout.region.influence_classes:
                raise BadInput(f"a predictor for {p.region.agent} cannot replace {agent}'s")
            self.predictors[i] = p
        running = [(g.members, g.h, g.previous) for g in self.groups]
        self._build()
        for g in self.groups:  # keep running histories where the group's shape allows
            g.reset(self.n_envs)
            for members, h, previous in running:
                if not np.array_equal(members, g.members):
                    continue
                if h is not None and g.h is not None and h.shape == g.h.shape:
                    g.h = h
                if previous is not None and g.previous is not None and previous.shape == g.previous.shape:
                    g.previous = previous

    def probs_padded(self, dsets: np.ndarray) -> np.ndarray:
        """Feed ``d_t`` of every row (``[rows, D]``), advance the recurrent states, return the
        class probabilities ``[rows, M, Kmax]``."""
        d = np.asarray(dsets)
        if d.shape != (self.rows, self._layout.dset_size):
            raise BadInput(f"expected d-sets of shape {(self.rows, self._layout.dset_size)}, got {d.shape}")
        out = np.empty((self.rows, self.n_sources, self.max_classes))
        view = out.reshape(len(self.agents), self.n_envs, self.n_sources, self.max_classes)
        dg = d.reshape(len(self.agents), self.n_envs, -1)
        for g in self.groups:
            if g.kind == "table":
                view[g.members] = g.table[:, None]
                continue
            logits = g.logits(dg[g.members].astype(np.float32), self.t)
            probs = self._layout._logits_to_padded(logits.reshape(-1, logits.shape[-1]))
            view[g.members] = probs.reshape(len(g.members), self.n_envs, self.n_sources, self.max_classes)
        self.t += 1
        return out

    def observe(self, influences: np.ndarray) -> None:
        """The influence ``u_t`` of every row (int ``[rows, M]``) that autoregressive AIPs read
        at the next step (teacher forcing; :meth:`sample` does this with its own draws)."""
        u = np.asarray(influences)
        if u.shape != (self.rows, self.n_sources):
            raise BadInput(f"expected influences of shape {(self.rows, self.n_sources)}, got {u.shape}")
        ug = u.reshape(len(self.agents), self.n_envs, self.n_sources)
        for g in self.groups:
            g.remember(ug[g.members])

    def sample(self, dsets: np.ndarray) -> np.ndarray:
        """Feed ``d_t`` of every row, advance, draw ``u_t`` (int64 ``[rows, M]``) from each row's
        own stream: the number of classes whose cumulative probability is below the row's
        uniform number (inverse CDF on the unnormalised ``exp`` of the logits, as the
        single-agent predictors sample)."""
        d = np.asarray(dsets)
        if d.shape != (self.rows, self._layout.dset_size):
            raise BadInput(f"expected d-sets of shape {(self.rows, self._layout.dset_size)}, got {d.shape}")
        A, n, M = len(self.agents), self.n_envs, self.n_sources
        r = self.streams.next().reshape(A, n, M, 1)
        out = np.empty((A, n, M), np.int64)
        dg = d.reshape(A, n, -1)
        layout = self._layout
        for g in self.groups:
            if g.kind == "table":
                out[g.members] = (g.cum[:, None] < r[g.members]).sum(axis=-1)
                continue
            logits = g.logits(dg[g.members].astype(np.float32), self.t)  # [G, n, sum K]
            if layout._same_k:
                z = logits.reshape(len(g.members), n, M, layout.max_classes)
                z -= z.max(axis=-1, keepdims=True)
            else:
                z = logits[..., layout._gather]
                z[..., layout._pad_mask] = -np.inf
                z -= z.max(axis=-1, keepdims=True)
            np.exp(z, out=z)
            np.cumsum(z, axis=-1, out=z)
            rr = r[g.members] * z[..., -1:]
            out[g.members] = (z < rr).sum(axis=-1)
            g.remember(out[g.members])
        self.t += 1
        return out.reshape(self.rows, M)


__all__ = ["StackedPredictor"]
