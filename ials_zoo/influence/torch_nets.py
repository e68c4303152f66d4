"""The torch training networks mirrored by the numpy predictors of ``predictors.py``.

``TorchMLP``/``TorchGRU`` train one AIP (:func:`ials_zoo.influence.train.train_predictor`);
``StackedMLP``/``StackedGRU`` train many agents' AIPs at once as one batched program
(:func:`ials_zoo.influence.train.train_predictors`). Each copies its weights from and to the
numpy arrays the predictor classes read. This module imports torch; ``train.py`` imports it
lazily so that importing ``train`` stays light.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn


class TorchMLP(nn.Module):
    def __init__(self, d, hidden, n_logits):
        super().__init__()
        self.lin1 = nn.Linear(d, hidden)
        self.out = nn.Linear(hidden, n_logits)

    def forward(self, x):
        return self.out(torch.relu(self.lin1(x)))

    def load_numpy(self, a):
        with torch.no_grad():
            self.lin1.weight.copy_(torch.from_numpy(a["w1"].T.copy()))
            self.lin1.bias.copy_(torch.from_numpy(a["b1"]))
            self.out.weight.copy_(torch.from_numpy(a["w_out"].T.copy()))
            self.out.bias.copy_(torch.from_numpy(a["b_out"]))

    def to_numpy(self):
        g = lambda t: t.detach().cpu().numpy().astype(np.float32)
        return {
            "w1": g(self.lin1.weight).T.copy(),
            "b1": g(self.lin1.bias),
            "w_out": g(self.out.weight).T.copy(),
            "b_out": g(self.out.bias),
        }

class TorchGRU(nn.Module):
    def __init__(self, d, hidden, n_logits):
        super().__init__()
        self.gru = nn.GRU(d, hidden, batch_first=True)
        self.out = nn.Linear(hidden, n_logits)

    def forward(self, x):
        h, _ = self.gru(x)
        return self.out(h)

    def load_numpy(self, a):
        with torch.no_grad():
            self.gru.weight_ih_l0.copy_(torch.from_numpy(a["w_ih"].T.copy()))
            self.gru.weight_hh_l0.copy_(torch.from_numpy(a["w_hh"].T.copy()))
            self.gru.bias_ih_l0.copy_(torch.from_numpy(a["b_ih"]))
            self.gru.bias_hh_l0.copy_(torch.from_numpy(a["b_hh"]))
            self.out.weight.copy_(torch.from_numpy(a["w_out"].T.copy()))
            self.out.bias.copy_(torch.from_numpy(a["b_out"]))

    def to_numpy(self):
        g = lambda t: t.detach().cpu().numpy().astype(np.float32)
        return {
            "w_ih": g(self.gru.weight_ih_l0).T.copy(),
            "w_hh": g(self.gru.weight_hh_l0).T.copy(),
            "b_ih": g(self.gru.bias_ih_l0),
            "b_hh": g(self.gru.bias_hh_l0),
            "w_out": g(self.out.weight).T.copy(),
            "b_out": g(self.out.bias),
        }


class StackedMLP(nn.Module):
    def __init__(self, arrays: list[dict]):
        super().__init__()
        st = lambda k: nn.Parameter(torch.from_numpy(np.stack([a[k] for a in arrays]).astype(np.float32)))
        self.w1, self.b1, self.w_out, self.b_out = st("w1"), st("b1"), st("w_out"), st("b_out")

    def forward(self, x):  # x [G, B, D]
        h = torch.relu(torch.bmm(x, self.w1) + self.b1[:, None])
        return torch.bmm(h, self.w_out) + self.b_out[:, None]

    def arrays(self, g):
        return {k: getattr(self, k)[g].detach().numpy().copy() for k in ("w1", "b1", "w_out", "b_out")}

class StackedGRU(nn.Module):
    def __init__(self, arrays: list[dict]):
        super().__init__()
        st = lambda k: nn.Parameter(torch.from_numpy(np.stack([a[k] for a in arrays]).astype(np.float32)))
        for k in ("w_ih", "w_hh", "b_ih", "b_hh", "w_out", "b_out"):
            setattr(self, k, st(k))
        self.hidden = arrays[0]["w_hh"].shape[0]

    def forward(self, x):  # x [G, B, T, D]; torch.nn.GRU's equations and gate order (r, z, n)
        G, B, T, _ = x.shape
        H = self.hidden
        h = x.new_zeros(G, B, H)
        gi_all = torch.matmul(x, self.w_ih[:, None]) + self.b_ih[:, None, None]  # [G, B, T, 3H]
        outs = []
        for t in range(T):
            gi = gi_all[:, :, t]
            gh = torch.bmm(h, self.w_hh) + self.b_hh[:, None]
            r = torch.sigmoid(gi[..., :H] + gh[..., :H])
            z = torch.sigmoid(gi[..., H:2 * H] + gh[..., H:2 * H])
            n = torch.tanh(gi[..., 2 * H:] + r * gh[..., 2 * H:])
            h = (1 - z) * n + z * h
            outs.append(h)
        hs = torch.stack(outs, dim=2)  # [G, B, T, H]
        return torch.matmul(hs, self.w_out[:, None]) + self.b_out[:, None, None]

    def arrays(self, g):
        return {k: getattr(self, k)[g].detach().numpy().copy()
                for k in ("w_ih", "w_hh", "b_ih", "b_hh", "w_out", "b_out")}
