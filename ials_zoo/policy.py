"""Policies as weights plus plain JSON: what the evaluator and the leaderboard load.

A policy file holds one or more agents' independent categorical MLP policies (the actor of
PPO): per agent, layers ``x -> act(W1 x + b1) -> ... -> W_out h + b_out`` (logits), the input
being the agent's last ``frame_stack`` observations concatenated (newest last, zeros before an
episode's first, as SB3's ``VecFrameStack``). It is a safetensors file -- tensors and a JSON
header, nothing else: loading it can never run code (no pickle). Weights of several agents are
stacked on a leading agent axis::

    tensors:  layer<i>.weight [A, in, out] float32, layer<i>.bias [A, out] float32
    metadata: {"ials_zoo.policy": "<json>"} with format, format_version, agents, obs_size,
              n_actions, hidden, activation, frame_stack, shared, env_id, and free provenance
              (algorithm, training record, learning curve, package version, ...).

A *recurrent* policy reads its frames through a GRU first (SPEC §6's warehouse policy,
"recurrent over the last 8 observations"): the GRU runs over the ``frame_stack`` observations,
oldest first, from a zero state, and the layers read its last state. Its tensors are
``gru.weight_ih [A, obs, 3H]``, ``gru.weight_hh [A, H, 3H]``, ``gru.bias_ih [A, 3H]`` and
``gru.bias_hh [A, 3H]`` (torch's gate order r, z, n) and the header's ``recurrent_hidden`` is H.

A *shared* policy (parameter sharing) stores one set of weights (``A = 1``) used by every
listed agent.

Inference (:meth:`PolicyNetwork.act`) is numpy in float64 -- deterministic to ~1e-15 on any
machine, so a score can be re-measured exactly: a stochastic policy draws one uniform number
per agent and step from the generator it is given and takes the inverse CDF of its softmax;
a deterministic one takes the most likely action.

:func:`policy_from_sb3_zip` reads an SB3 PPO ``.zip`` *safely*: the weights from its
``policy.pth`` with ``torch.load(weights_only=True)`` and its JSON ``data``, ignoring every
``:serialized:`` (pickled) field -- so today's model zips can be scored without trusting them.
"""

from __future__ import annotations

import io
import json
import os
import re
import zipfile
from pathlib import Path

import numpy as np

from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.utils import atomic_path, loads_untrusted_json

FORMAT = "ials_zoo.policy"
FORMAT_VERSION = 1
MASKED_FORMAT_VERSION = 2  # a policy with per-agent action counts (older readers must refuse it)
HEADER_KEY = "ials_zoo.policy"
SUFFIX = ".safetensors"
ACTIVATIONS = ("tanh", "relu")
MAX_FILE_BYTES = 256 * 2**20
MAX_FRAME_STACK = 64
"""The most frames a policy stacks (a training run and a policy's metadata alike)."""
MAX_ZIP_MEMBER_BYTES = 256 * 2**20


class PolicyFileError(BadInput):
    """A policy file is malformed, foreign, or does not fit what it is used for."""


def _activation(name: str):
    if name == "tanh":
        return np.tanh
    if name == "relu":
        return lambda x: np.maximum(x, 0.0)
    raise PolicyFileError(f"unknown activation {name!r}; expected one of {ACTIVATIONS}")


class PolicyNetwork:
    """Independent MLP policies of ``agents`` (one set of weights each, stacked).

    Args:
        agents: the agents, in weight order.
        obs_size: one observation's length; the input is ``obs_size * frame_stack``.
        n_actions: ``Discrete`` action count.
        layers: ``[(W [A, in, out], b [A, out]), ...]`` from input to logits.
        activation: ``"tanh"`` (SB3's default) or ``"relu"``, after every hidden layer.
        frame_stack: observations the policy reads.
        metadata: JSON-able provenance (env_id, algorithm, training record, ...).
        shared: one set of weights (leading axis 1) for every agent.
        recurrent: ``(W_ih, W_hh, b_ih, b_hh)`` of a GRU that reads the frames before the
            layers (module docstring), or None.
        action_counts: per agent, how many of the ``n_actions`` it has (agents with their own
            action spaces: the others get probability 0), or None (all ``n_actions``). Such a
            policy reads observations zero-padded to ``obs_size``.
    """

    def __init__(self, agents, obs_size: int, n_actions: int, layers, activation: str = "tanh",
                 frame_stack: int = 1, metadata: dict | None = None, shared: bool = False, recurrent=None,
                 action_counts=None):
        self.agents = tuple(agents)
        if not self.agents or len(set(self.agents)) != len(self.agents):
            raise PolicyFileError(f"a policy needs distinct agents, got {list(self.agents)}")
        for name, value in (("obs_size", obs_size), ("n_actions", n_actions), ("frame_stack", frame_stack)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise PolicyFileError(f"{name} must be an integer, got {value!r}")
        self.obs_size, self.n_actions = int(obs_size), int(n_actions)
        self.frame_stack = int(frame_stack)
        if self.obs_size < 1 or self.n_actions < 2 or self.frame_stack < 1:
            raise PolicyFileError("obs_size, frame_stack must be >= 1 and n_actions >= 2")
        self.activation = activation
        self._act = _activation(activation)
        # the header's own keys are the network's; provenance never overrides them
        self.metadata = {k: v for k, v in dict(metadata or {}).items() if k not in _RESERVED}
        self.shared = bool(shared) and len(self.agents) > 1
        self.layers = []
        width = self.obs_size * self.frame_stack
        A = 1 if self.shared else len(self.agents)
        self.recurrent = None if recurrent is None else self._check_gru(recurrent, A)
        if self.recurrent is not None:
            width = self.recurrent_hidden
        for i, (w, b) in enumerate(layers):
            for part, x in (("weight", w), ("bias", b)):
                if np.asarray(x).dtype.kind != "f":
                    raise PolicyFileError(f"layer {i}: {part} must be floating point, got {np.asarray(x).dtype}")
            w, b = np.asarray(w, dtype=np.float32), np.asarray(b, dtype=np.float32)
            if w.ndim != 3 or w.shape[:2] != (A, width) or b.shape != (A, w.shape[2]):
                raise PolicyFileError(f"layer {i}: weight {w.shape} / bias {b.shape} do not fit "
                                      f"{A} agents with inputs of {width}")
            if not (np.isfinite(w).all() and np.isfinite(b).all()):
                raise PolicyFileError(f"layer {i} has non-finite weights")
            self.layers.append((w, b))
            width = w.shape[2]
        if not self.layers or width != self.n_actions:
            raise PolicyFileError(f"the last layer has {width} outputs, not n_actions={self.n_actions}")
        self.action_counts = self._check_counts(action_counts)
        # float64 copies for inference (see the module docstring)
        self._layers64 = [(w.astype(np.float64), b.astype(np.float64)[:, None, :]) for w, b in self.layers]
        self._gru64 = None if self.recurrent is None else [t.astype(np.float64) for t in self.recurrent]

    def _check_counts(self, counts):
        if counts is None:
            return None
        if not isinstance(counts, (list, tuple)) or len(counts) != len(self.agents) or any(
                isinstance(c, bool) or not isinstance(c, (int, np.integer)) or not 1 <= c <= self.n_actions
                for c in counts):
            raise PolicyFileError(f"action_counts must give each of the {len(self.agents)} agents an integer "
                                  f"in [1, {self.n_actions}], got {counts!r}")
        return tuple(int(c) for c in counts)

    def _check_gru(self, parts, A: int) -> tuple:
        if len(parts) != 4:
            raise PolicyFileError("a recurrent policy's GRU is (weight_ih, weight_hh, bias_ih, bias_hh)")
        arrays = []
        for name, x in zip(GRU_TENSORS, parts):
            if np.asarray(x).dtype.kind != "f":
                raise PolicyFileError(f"gru.{name} must be floating point, got {np.asarray(x).dtype}")
            x = np.asarray(x, dtype=np.float32)
            if not np.isfinite(x).all():
                raise PolicyFileError(f"gru.{name} has non-finite weights")
            arrays.append(x)
        w_ih, w_hh, b_ih, b_hh = arrays
        H3 = w_hh.shape[-1] if w_hh.ndim == 3 else -1
        if (H3 < 3 or H3 % 3 or w_ih.shape != (A, self.obs_size, H3) or w_hh.shape != (A, H3 // 3, H3)
                or b_ih.shape != (A, H3) or b_hh.shape != (A, H3)):
            raise PolicyFileError(f"the GRU's shapes {[x.shape for x in arrays]} do not fit {A} agents with "
                                  f"observations of {self.obs_size}")
        return tuple(arrays)

    @property
    def recurrent_hidden(self) -> int:
        """The GRU's units (0: no GRU)."""
        return 0 if self.recurrent is None else self.recurrent[1].shape[1]

    @property
    def hidden(self) -> list[int]:
        return [w.shape[2] for w, _ in self.layers[:-1]]

    @property
    def input_size(self) -> int:
        return self.obs_size * self.frame_stack

    def index(self, agent: str) -> int:
        try:
            return self.agents.index(agent)
        except ValueError:
            raise PolicyFileError(f"the policy has no weights for agent {agent!r}; it is for "
                                  f"{', '.join(self.agents)}") from None

    def subset(self, agents) -> PolicyNetwork:
        """The policies of ``agents`` only (in that order)."""
        idx = [self.index(a) for a in agents]
        counts = None if self.action_counts is None else [self.action_counts[i] for i in idx]
        if self.shared:
            return PolicyNetwork(agents, self.obs_size, self.n_actions, self.layers, self.activation,
                                 self.frame_stack, self.metadata, shared=True, recurrent=self.recurrent,
                                 action_counts=counts)
        gru = None if self.recurrent is None else [t[idx] for t in self.recurrent]
        return PolicyNetwork(agents, self.obs_size, self.n_actions,
                             [(w[idx], b[idx]) for w, b in self.layers], self.activation,
                             self.frame_stack, self.metadata, recurrent=gru, action_counts=counts)

    def logits(self, x) -> np.ndarray:
        """``x [A, n, input]`` (or ``[A, input]``) -> logits ``[A, n, n_actions]`` (float64)."""
        h = np.asarray(x, dtype=np.float64)
        squeeze = h.ndim == 2
        if squeeze:
            h = h[:, None, :]
        if h.shape[0] != len(self.agents) or h.shape[-1] != self.input_size:
            raise BadInput(f"policy input must be [{len(self.agents)}, n, {self.input_size}], got {h.shape}")
        if self._gru64 is not None:
            h = self._gru_state(h)
        last = len(self._layers64) - 1
        for i, (w, b) in enumerate(self._layers64):
            h = np.matmul(h, w) + b
            if i < last:
                h = self._act(h)
        return h[:, 0] if squeeze else h

    def _gru_state(self, x: np.ndarray) -> np.ndarray:
        """The GRU's last state after reading the frames of ``x [A, n, input]``, oldest first."""
        w_ih, w_hh, b_ih, b_hh = self._gru64
        H = w_hh.shape[1]
        frames = x.reshape(x.shape[0], x.shape[1], self.frame_stack, self.obs_size)
        h = np.zeros((x.shape[0], x.shape[1], H))
        for t in range(self.frame_stack):
            gi = np.matmul(frames[:, :, t], w_ih) + b_ih[:, None]
            gh = np.matmul(h, w_hh) + b_hh[:, None]
            r = 1.0 / (1.0 + np.exp(-(gi[..., :H] + gh[..., :H])))
            z = 1.0 / (1.0 + np.exp(-(gi[..., H:2 * H] + gh[..., H:2 * H])))
            n = np.tanh(gi[..., 2 * H:] + r * gh[..., 2 * H:])
            h = (1.0 - z) * n + z * h
        return h

    def probs(self, x) -> np.ndarray:
        z = self.logits(x)
        if self.action_counts is not None:  # an agent's missing actions get probability 0
            missing = np.arange(self.n_actions) >= np.asarray(self.action_counts)[:, None]
            z = np.where(missing[:, None, :] if z.ndim == 3 else missing, -np.inf, z)
        z = z - z.max(axis=-1, keepdims=True)
        np.exp(z, out=z)
        return z / z.sum(axis=-1, keepdims=True)

    def act(self, x, rng: np.random.Generator | None = None, deterministic: bool = False) -> np.ndarray:
        """One action per agent (and row) for inputs ``x`` (``[A, input]`` or ``[A, n, input]``):
        the most likely one, or one draw from ``rng`` per agent and row (module docstring)."""
        p = self.probs(x)
        if deterministic:
            return p.argmax(axis=-1)
        if rng is None:
            raise BadInput("a stochastic policy needs a random generator")
        cum = np.cumsum(p, axis=-1)
        u = rng.random(p.shape[:-1] + (1,))
        last = self.n_actions - 1 if self.action_counts is None else np.asarray(self.action_counts) - 1
        if np.ndim(last) and p.ndim == 3:
            last = last[:, None]
        return np.minimum((cum < u).sum(axis=-1), last)

    def header(self) -> dict:
        counts = {} if self.action_counts is None else {"action_counts": list(self.action_counts)}
        version = FORMAT_VERSION if self.action_counts is None else MASKED_FORMAT_VERSION
        return {"format": FORMAT, "format_version": version, "agents": list(self.agents), **counts,
                "obs_size": self.obs_size, "n_actions": self.n_actions, "hidden": self.hidden,
                "activation": self.activation, "frame_stack": self.frame_stack, "shared": self.shared,
                **({"recurrent_hidden": self.recurrent_hidden} if self.recurrent is not None else {}), **self.metadata}

    def tensors(self) -> dict[str, np.ndarray]:
        out = {}
        if self.recurrent is not None:
            out.update({f"gru.{name}": np.ascontiguousarray(t) for name, t in zip(GRU_TENSORS, self.recurrent)})
        for i, (w, b) in enumerate(self.layers):
            out[f"layer{i}.weight"] = np.ascontiguousarray(w)
            out[f"layer{i}.bias"] = np.ascontiguousarray(b)
        return out

    def __repr__(self):
        gru = f" GRU {self.recurrent_hidden} ->" if self.recurrent is not None else ""
        return (f"<PolicyNetwork {len(self.agents)} agent(s), {self.input_size} ->{gru} {self.hidden} -> "
                f"{self.n_actions} ({self.activation})>")


_RESERVED = ("format", "format_version", "agents", "obs_size", "n_actions", "hidden", "activation", "frame_stack",
             "shared", "recurrent_hidden", "action_counts")
GRU_TENSORS = ("weight_ih", "weight_hh", "bias_ih", "bias_hh")


def save_policy(net: PolicyNetwork, path) -> Path:
    """Write ``net`` to ``path`` (a ``.safetensors`` file), atomically."""
    from safetensors.numpy import save

    path = Path(path)
    header = json.dumps(net.header(), sort_keys=True, default=_json_default, allow_nan=False)
    data = save(net.tensors(), metadata={HEADER_KEY: header})
    with atomic_path(path, suffix=SUFFIX) as tmp:
        tmp.write_bytes(data)
    return path


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise BadInputType(f"not JSON serialisable: {type(o).__name__}")


def load_policy_file(path) -> PolicyNetwork:
    """Read a policy file (:func:`save_policy`); a :class:`PolicyFileError` naming the file
    for anything that is not one."""
    from safetensors import safe_open

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"policy file not found: {path}")
    if path.stat().st_size > MAX_FILE_BYTES:
        raise PolicyFileError(f"{path}: {path.stat().st_size} bytes is more than a policy file may hold")
    try:
        with safe_open(str(path), framework="np") as f:
            meta = f.metadata() or {}
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except Exception as exc:  # safetensors raises its own error types for foreign files
        raise PolicyFileError(f"not an ials_zoo policy file: {path} ({type(exc).__name__}: {exc})") from None
    return _from_parts(meta, tensors, str(path))


def _from_parts(meta: dict, tensors: dict, where: str) -> PolicyNetwork:
    try:
        header = loads_untrusted_json(meta[HEADER_KEY])
    except (KeyError, TypeError, ValueError) as exc:
        raise PolicyFileError(f"not an ials_zoo policy file: {where} (no readable {HEADER_KEY!r} header: {exc})") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise PolicyFileError(f"not an ials_zoo policy file: {where}")
    version = header.get("format_version")
    if version not in (FORMAT_VERSION, MASKED_FORMAT_VERSION) or (version == MASKED_FORMAT_VERSION) != (
            "action_counts" in header):
        raise PolicyFileError(f"{where}: policy format version {version!r}; this ials_zoo reads version "
                              f"{FORMAT_VERSION}, and {MASKED_FORMAT_VERSION} with action_counts")
    n = len(header.get("hidden", [])) + 1
    recurrent = header.get("recurrent_hidden", 0)
    try:
        layers = [(tensors[f"layer{i}.weight"], tensors[f"layer{i}.bias"]) for i in range(n)]
        gru = [tensors[f"gru.{name}"] for name in GRU_TENSORS] if recurrent else None
        expected = {f"layer{i}.{p}" for i in range(n) for p in ("weight", "bias")}
        expected |= {f"gru.{name}" for name in GRU_TENSORS} if recurrent else set()
        extra = set(tensors) - expected
        if extra:
            raise PolicyFileError(f"{where}: unexpected tensors {sorted(extra)}")
        net = PolicyNetwork(header["agents"], header["obs_size"], header["n_actions"], layers,
                            header.get("activation", "tanh"), header.get("frame_stack", 1),
                            {k: v for k, v in header.items() if k not in _RESERVED},
                            shared=bool(header.get("shared", False)), recurrent=gru,
                            action_counts=header.get("action_counts"))
        if net.recurrent_hidden != recurrent:
            raise PolicyFileError(f"recurrent_hidden {recurrent!r} does not fit its GRU ({net.recurrent_hidden} units)")
        return net
    except KeyError as exc:
        raise PolicyFileError(f"{where}: missing {exc}") from None
    except PolicyFileError as exc:
        raise PolicyFileError(f"{where}: {exc}") from None


# --------------------------------------------------------------------------------------------
# SB3 models, read without unpickling


def _sb3_zip_parts(path: Path) -> tuple[dict, dict]:
    """``(data JSON without serialized fields, policy state dict as numpy)`` of an SB3 zip."""
    import torch

    try:
        with zipfile.ZipFile(path) as z:
            members = {i.filename: i for i in z.infolist()}
            for name in ("data", "policy.pth"):
                if name not in members:
                    raise PolicyFileError(f"{path}: not an SB3 model zip (no {name!r})")
                if members[name].file_size > MAX_ZIP_MEMBER_BYTES:
                    raise PolicyFileError(f"{path}: {name!r} is too large")
            data = loads_untrusted_json(z.read("data"))
            raw = z.read("policy.pth")
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        if isinstance(exc, PolicyFileError):
            raise
        raise PolicyFileError(f"{path}: not a readable SB3 model zip ({type(exc).__name__}: {exc})") from None
    # weights_only: torch's restricted unpickler admits tensors and plain containers only
    try:
        state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:
        raise PolicyFileError(f"{path}: policy.pth holds more than weights; refused ({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict) or not isinstance(state, dict):
        raise PolicyFileError(f"{path}: not an SB3 model zip")
    clean = {k: v for k, v in data.items() if not (isinstance(v, dict) and ":serialized:" in v)}
    return clean, {k: v.detach().cpu().numpy() for k, v in state.items() if hasattr(v, "detach")}


def _sb3_activation(data: dict) -> str:
    kwargs = data.get("policy_kwargs")
    text = json.dumps(kwargs) if kwargs is not None else ""
    if "activation_fn" not in text:
        return "tanh"  # SB3's ActorCriticPolicy default
    m = re.search(r"activation\.(\w+)", text)
    name = (m.group(1) if m else "").lower()
    if name in ACTIVATIONS:
        return name
    raise PolicyFileError(f"unsupported activation in policy_kwargs: {text}")


def policy_from_state_dict(state: dict, agent: str, obs_size: int, frame_stack: int = 1,
                           activation: str = "tanh", metadata: dict | None = None) -> PolicyNetwork:
    """The actor of an SB3 ``ActorCriticPolicy`` (``MlpPolicy``) state dict, as a policy."""
    idx = sorted({int(m.group(1)) for k in state
                  if (m := re.fullmatch(r"mlp_extractor\.policy_net\.(\d+)\.weight", k))})
    layers = []
    try:
        for i in idx:
            w, b = np.asarray(state[f"mlp_extractor.policy_net.{i}.weight"]), np.asarray(state[f"mlp_extractor.policy_net.{i}.bias"])
            layers.append((w.T[None], b[None]))
        w, b = np.asarray(state["action_net.weight"]), np.asarray(state["action_net.bias"])
    except KeyError as exc:
        raise PolicyFileError(f"not an actor-critic MLP policy (missing {exc})") from None
    layers.append((w.T[None], b[None]))
    if layers[0][0].shape[1] != obs_size * frame_stack:
        raise PolicyFileError(f"the policy reads {layers[0][0].shape[1]} inputs, not {obs_size} x {frame_stack} frames")
    return PolicyNetwork([agent], obs_size, w.shape[0], layers, activation, frame_stack, metadata)


def policy_from_sb3_zip(path, agent: str, obs_size: int, frame_stack: int = 1,
                        metadata: dict | None = None) -> PolicyNetwork:
    """The actor of an SB3 PPO model zip, read without unpickling (module docstring)."""
    path = Path(path)
    data, state = _sb3_zip_parts(path)
    return policy_from_state_dict(state, agent, obs_size, frame_stack, _sb3_activation(data), metadata)


def policy_from_sb3_model(model, agent: str, frame_stack: int = 1, metadata: dict | None = None) -> PolicyNetwork:
    """The actor of a live SB3 PPO model (its observation space may be frame-stacked)."""
    state = {k: v.detach().cpu().numpy() for k, v in model.policy.state_dict().items()}
    width = int(np.prod(model.observation_space.shape))
    if width % frame_stack:
        raise BadInput(f"observation width {width} is not a multiple of frame_stack {frame_stack}")
    act = model.policy.activation_fn.__name__.lower() if hasattr(model.policy, "activation_fn") else "tanh"
    return policy_from_state_dict(state, agent, width // frame_stack, frame_stack, act, metadata)


def stack_policies(nets: list[PolicyNetwork], metadata: dict | None = None) -> PolicyNetwork:
    """One policy holding the weights of single-agent policies of the same architecture."""
    first = nets[0]
    for n in nets[1:]:
        if (n.obs_size, n.n_actions, n.hidden, n.activation, n.frame_stack, n.recurrent_hidden) != (
                first.obs_size, first.n_actions, first.hidden, first.activation, first.frame_stack,
                first.recurrent_hidden):
            raise PolicyFileError("only policies of one architecture can be stacked")
    layers = [(np.concatenate([n.layers[i][0] for n in nets]), np.concatenate([n.layers[i][1] for n in nets]))
              for i in range(len(first.layers))]
    gru = None if first.recurrent is None else [np.concatenate([n.recurrent[j] for n in nets]) for j in range(4)]
    counts = None
    if any(n.action_counts is not None for n in nets):
        counts = [c for n in nets for c in (n.action_counts or (n.n_actions,) * len(n.agents))]
    return PolicyNetwork([a for n in nets for a in n.agents], first.obs_size, first.n_actions, layers,
                         first.activation, first.frame_stack, metadata if metadata is not None else first.metadata,
                         recurrent=gru, action_counts=counts)


def is_policy_file(path) -> bool:
    return os.fspath(path).endswith(SUFFIX)


__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "PolicyFileError",
    "PolicyNetwork",
    "is_policy_file",
    "load_policy_file",
    "policy_from_sb3_model",
    "policy_from_sb3_zip",
    "save_policy",
    "stack_policies",
]
