"""Pieces shared by the PPO baselines: dataclass <-> command line, training simulators, the
periodic GS evaluation with its learning curve, checkpoints and the final policy file.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import time
import typing
from pathlib import Path

import numpy as np

from ials_zoo.baselines.runs import Clock
from ials_zoo.utils import atomic_write_text

# --------------------------------------------------------------------------------------------
# dataclass <-> argparse


def add_dataclass_args(parser: argparse.ArgumentParser, cls) -> argparse.ArgumentParser:
    """Add one ``--field-name`` option per field of the dataclass ``cls``.

    The help text of a field is its ``metadata["help"]`` (or what that callable returns, for
    defaults read from the domains when the parser is built); booleans get ``--x/--no-x``."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        name = "--" + f.name.replace("_", "-")
        aliases = list(f.metadata.get("aliases", ()))
        default = f.default if f.default is not dataclasses.MISSING else None
        help_text = f.metadata.get("help", "")
        help_text = f"{help_text() if callable(help_text) else help_text} (default: {default!r})"
        typ = hints[f.name]
        origin = typing.get_origin(typ)
        if origin is typing.Union or str(origin) == "<class 'types.UnionType'>":
            inner = [a for a in typing.get_args(typ) if a is not type(None)]
            typ = inner[0] if inner else str
        if typ is bool:
            parser.add_argument(*aliases, name, dest=f.name, default=default,
                                action=argparse.BooleanOptionalAction, help=help_text)
        else:
            parser.add_argument(*aliases, name, dest=f.name, type=typ, default=default,
                                metavar=f.name.upper(), help=help_text)
    return parser


def dataclass_from_namespace(cls, ns: argparse.Namespace):
    """Build ``cls`` from the parsed options (fields absent from ``ns`` keep their default)."""
    values = {f.name: getattr(ns, f.name) for f in dataclasses.fields(cls) if hasattr(ns, f.name)}
    return cls(**values)


def parse_args(cls, argv=None, description: str | None = None):
    """Parse a baseline's command line into its dataclass."""
    parser = argparse.ArgumentParser(description=description, allow_abbrev=False)
    add_dataclass_args(parser, cls)
    return dataclass_from_namespace(cls, parser.parse_args(argv))


def run_cli(module) -> int:
    """``python -m`` entry point of a baseline module: parse its ``Args``, run its ``main``;
    bad arguments print one clear line instead of a traceback (``ials-zoo train``'s style)."""
    import sys

    args = parse_args(module.Args, description=module.__doc__.splitlines()[0])
    name = module.__name__.rsplit(".", 1)[-1]
    try:
        module.main(args)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, TypeError, FileNotFoundError) as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:  # a worker died or stopped: named by the error, no traceback
        from ials_zoo.processes import WorkerError

        if not isinstance(exc, WorkerError):
            raise
        print(f"{name}: {exc}", file=sys.stderr)
        return 1
    return 0


def arg(default, help, **kw):
    """A dataclass field with a help text (a string, or a callable returning one) and optional
    ``aliases``."""
    return dataclasses.field(default=default, metadata={"help": help, **kw})


@dataclasses.dataclass
class PPOSettings:
    """The PPO update settings every baseline shares (SPEC §3: the authors' values)."""

    n_epochs: int = arg(3, "epochs per update")
    learning_rate: float = arg(2.5e-4, "initial learning rate")
    anneal_lr: bool = arg(True, "decay the learning rate linearly to 0")
    clip_range: float = arg(0.1, "PPO clip range")
    ent_coef: float = arg(0.01, "entropy coefficient")
    vf_coef: float = arg(1.0, "value loss coefficient")
    gamma: float = arg(0.99, "discount")
    gae_lambda: float = arg(0.95, "GAE lambda")
    max_grad_norm: float = arg(0.5, "gradient clipping")


def check_ppo_settings(args) -> None:
    """Clear errors for the :class:`PPOSettings` fields of ``args``."""
    import math

    if args.n_epochs < 1:
        raise ValueError(f"n_epochs must be >= 1, got {args.n_epochs}")
    for name in ("learning_rate", "clip_range", "max_grad_norm"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0, got {value}")
    for name in ("ent_coef", "vf_coef"):
        if not (math.isfinite(getattr(args, name)) and getattr(args, name) >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {getattr(args, name)}")
    for name in ("gamma", "gae_lambda"):
        if not 0.0 <= getattr(args, name) <= 1.0:
            raise ValueError(f"{name} must be in [0, 1], got {getattr(args, name)}")


def parse_env_options(text: str | None) -> dict:
    """``--env-options`` (a JSON object of GS/LS options, e.g. ``{"item_lifetime": 8}``)."""
    from ials_zoo.utils import parse_json_object

    return parse_json_object(text, "env_options")


# --------------------------------------------------------------------------------------------
# Training simulators

GS = "gs"


def predictor_for(simulator: str) -> str | None:
    """The ``predictor`` argument of the IALS factory for a ``--simulator`` value, or None for
    the GS (the vocabulary of :mod:`ials_zoo.influence.specs`; a ValueError naming it for
    anything else)."""
    from ials_zoo.influence.specs import parse_simulator

    spec = parse_simulator(simulator)
    return None if spec is None else str(spec)


def simulator_label(simulator: str, aip: dict | None) -> str:
    """The training-simulator name a result carries for a ``--simulator`` value (a predictor
    file is named by what it holds: ``ials`` for a trained AIP; the file itself, with its
    sha256, is recorded in ``training.aip``)."""
    from ials_zoo.influence.specs import simulator_label as label

    return label(simulator, (aip or {}).get("variant"))


def predictor_record(venv, simulator: str, env_id: str, agent: str, made_now: bool = True) -> dict | None:
    """What the training record says about the AIP behind an IALS vec env (None on the GS).

    The IALS vec env exposes its predictor as ``venv.predictor``; a trained AIP's
    ``metadata`` holds its training report, with ``dataset.collect_seconds`` (Algorithm 1)
    and ``train_seconds``: their sum is added to the training wall-clock (as in the paper's
    plots) when this run made the AIP (``made_now``; ``charged`` in the record), and only
    recorded when it was shipped or cached. Predictors that need neither (untrained, fixed)
    count 0; so does ``marginal``, whose metadata does not carry the data collection time
    (documented limitation). A shipped file is named relative to the package, not by an
    absolute path of this machine."""
    if simulator == GS:
        return None
    pred = getattr(venv, "predictor", None)
    meta = dict(getattr(pred, "metadata", None) or {})
    collect = (meta.get("dataset") or {}).get("collect_seconds") or meta.get("collect_seconds")
    train = meta.get("train_seconds")
    file = None
    if os.path.exists(simulator):
        file = simulator
    elif predictor_for(simulator).startswith(("trained", "marginal")):
        from ials_zoo.influence.ials import pretrained_path

        shipped = pretrained_path(env_id, agent)
        file = shipped if shipped.is_file() and not made_now else None
    sha = None
    if file:
        from ials_zoo.evaluation import sha256_file

        sha = sha256_file(file)
    meta.pop("marginal", None)
    return {
        "variant": str(meta.get("variant") or predictor_for(simulator)),
        "class": type(pred).__name__ if pred is not None else None,
        "file": _portable(file) if file else None,
        "charged": bool(made_now),
        "sha256": sha,
        "collection_seconds": float(collect or 0.0),
        "training_seconds": float(train or 0.0),
        "metadata": _jsonable(meta),
    }


def _portable(path) -> str:
    """A file inside the installed package as ``ials_zoo/<path in the package>``; any other
    file as given."""
    import ials_zoo

    package = Path(ials_zoo.__file__).resolve().parent
    try:
        return "ials_zoo/" + Path(path).resolve().relative_to(package).as_posix()
    except ValueError:
        return str(path)


def _jsonable(obj):
    try:
        return json.loads(json.dumps(obj, default=str))
    except (TypeError, ValueError):
        return str(obj)


def as_float_box(venv):
    """Make sure the observations are a float32 ``Box`` (what VecFrameStack and the evaluator
    use); wraps ``venv`` only when needed."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecEnvWrapper

    from ials_zoo.single_agent import box_space

    space = venv.observation_space
    if isinstance(space, spaces.Box) and space.dtype == np.float32:
        return venv

    class _Float(VecEnvWrapper):
        def __init__(self, v):
            super().__init__(v, observation_space=box_space(space))

        def reset(self):
            return np.asarray(self.venv.reset(), dtype=np.float32)

        def step_wait(self):
            obs, rew, done, infos = self.venv.step_wait()
            for info in infos:
                if "terminal_observation" in info:
                    info["terminal_observation"] = np.asarray(info["terminal_observation"], np.float32)
            return np.asarray(obs, dtype=np.float32), rew, done, infos

    return _Float(venv)


# --------------------------------------------------------------------------------------------
# Policies and periodic evaluation on the GS


def policy_of(model, agents, frame_stack: int, metadata: dict):
    """The actor of a live SB3 model as a :class:`~ials_zoo.policy.PolicyNetwork` for
    ``agents`` (one set of weights shared by all of them)."""
    from ials_zoo.policy import PolicyNetwork, policy_from_sb3_model

    agents = list(agents)
    net = policy_from_sb3_model(model, agents[0], frame_stack, metadata)
    if len(agents) == 1:
        return net
    return PolicyNetwork(agents, net.obs_size, net.n_actions, net.layers, net.activation, net.frame_stack,
                         metadata, shared=True)


class Evaluator:
    """Scores a policy on the GS (one agent, the others scripted), in this process or in a
    worker process (SUMO: one simulation per process). The worker dies with this process."""

    def __init__(self, env_id: str, agent: str, episodes: int, deterministic: bool,
                 in_subprocess: bool, options: dict | None = None):
        self.env_id, self.agent = env_id, agent
        self.options = dict(options or {})
        self.episodes, self.deterministic = episodes, deterministic
        self.in_subprocess = in_subprocess
        self._pool = None

    def __call__(self, policy, episodes: int | None = None, progress: bool = False):
        """Score ``policy`` (a PolicyNetwork, a NetworkPolicy or a policy file)."""
        from ials_zoo.evaluation import NetworkPolicy, _evaluate_worker, evaluate
        from ials_zoo.policy import PolicyNetwork

        if isinstance(policy, PolicyNetwork):
            policy = NetworkPolicy(policy)
        kwargs = {"episodes": int(episodes or self.episodes), "deterministic": self.deterministic,
                  "progress": progress, **self.options}
        if not self.in_subprocess:
            return evaluate(self.env_id, self.agent, policy, **kwargs)
        from ials_zoo.processes import shutdown_pool, spawn_pool

        if self._pool is None:
            self._pool = spawn_pool(1)
        try:
            return self._pool.submit(_evaluate_worker, self.env_id, self.agent, policy, kwargs).result()
        except BaseException:
            shutdown_pool(self._pool, kill=True)
            self._pool = None
            raise

    def close(self, kill: bool = False):
        from ials_zoo.processes import shutdown_pool

        shutdown_pool(self._pool, kill=kill)
        self._pool = None


def curve_point(steps: int, seconds: float, ev) -> dict:
    return {"env_steps": int(steps), "wall_clock_seconds": float(seconds), "mean": ev.mean,
            "ci_low": ev.ci_low, "ci_high": ev.ci_high}


# --------------------------------------------------------------------------------------------
# PPO and the training run


def make_ppo(venv, args, hidden: list[int]):
    """SB3 PPO with the baseline's hyper-parameters (``args``: ppo_single/ppo_shared Args);
    the learning rate decays linearly to 0 when ``args.anneal_lr``."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.utils import LinearSchedule

    lr = LinearSchedule(args.learning_rate, 0.0, 1.0) if args.anneal_lr else args.learning_rate
    return PPO(
        "MlpPolicy", venv, learning_rate=lr, n_steps=args.n_steps, batch_size=args.batch_size,
        n_epochs=args.n_epochs, gamma=args.gamma, gae_lambda=args.gae_lambda,
        clip_range=args.clip_range, ent_coef=args.ent_coef, vf_coef=args.vf_coef,
        max_grad_norm=args.max_grad_norm, seed=args.seed, device="cpu", verbose=0,
        policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden}},
    )


def estimate_seconds(env_id: str, simulator: str, steps: int) -> float:
    """Rough training time from the domain's measured PPO throughput (``Domain.study``)."""
    from ials_zoo.core.domains import get_domain

    rates = get_domain(env_id).study.ppo_steps_per_second
    rate = rates.get("gs" if simulator == GS else "ials", 1000.0)
    return steps / max(rate, 1.0)


def format_seconds(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


def scale_rewards(venv, gamma: float):
    """``venv`` with its rewards divided by the running std of the discounted return (SB3's
    ``VecNormalize``, observations untouched): what the multi-agent learners do
    (:class:`~ials_zoo.learners.batched_ppo.RewardScale`)."""
    from stable_baselines3.common.vec_env import VecNormalize

    return VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=gamma)


def reward_scale_of(venv):
    """The ``VecNormalize`` inside a chain of SB3 vec-env wrappers, or None."""
    from stable_baselines3.common.vec_env import VecNormalize

    while venv is not None:
        if isinstance(venv, VecNormalize):
            return venv
        venv = getattr(venv, "venv", None)
    return None


class TrainingRun:
    """The bookkeeping of one SB3 training run in a :class:`~ials_zoo.baselines.runs.RunFolder`.

    * every ``eval_every`` steps: checkpoint, score the policy on the GS, rewrite ``curve.json``;
    * every ``checkpoint_seconds`` of training (and after the first update): checkpoint, so a
      crash loses little and ``--resume`` continues from there;
    * at the end: ``policy.safetensors`` and its GS score for every evaluator's agent.

    ``meta`` is the policy metadata (domain, agents, algorithm, frame stack, options); its
    ``training`` record and ``learning_curve`` are updated in place. The first evaluator's agent
    is the one the curve follows. The clock (training only: evaluation and checkpointing
    excluded) starts at ``aip_seconds`` (plus a resumed run's seconds).
    """

    def __init__(self, model, run, meta: dict, evaluators: dict, aip_seconds: float = 0.0,
                 policy_agents=None, frame_stack: int = 1, checkpoint_seconds: float = 300.0):
        self.model, self.run, self.meta = model, run, meta
        self.out = run.path
        self.training, self.curve = meta["training"], meta["learning_curve"]
        self.evaluators = evaluators
        self.curve_agent = next(iter(evaluators))
        self.policy_agents = list(policy_agents or [self.curve_agent])
        self.frame_stack = int(frame_stack)
        self.aip_seconds = float(aip_seconds)
        self.checkpoint_seconds = float(checkpoint_seconds)
        self.clock = Clock(offset=self.aip_seconds)
        if run.resuming:
            self._resume()
        self._last_checkpoint = time.monotonic()

    def _resume(self):
        from ials_zoo.baselines.runs import load_training_state

        state, info = load_training_state(self.out)
        self.model.policy.load_state_dict(state["policy"])
        self.model.policy.optimizer.load_state_dict(state["optimizer"])
        scale = reward_scale_of(self.model.get_env())
        if scale is not None and "reward_rms" in state:
            rms = state["reward_rms"]
            scale.ret_rms.mean, scale.ret_rms.var = rms["mean"].numpy(), rms["var"].numpy()
            scale.ret_rms.count = float(rms["count"])
        self.model.num_timesteps = int(info["num_timesteps"])
        self.curve[:] = info["learning_curve"]
        self.clock = Clock(offset=float(info["clock_seconds"]))

    def policy(self):
        return policy_of(self.model, self.policy_agents, self.frame_stack, self.meta)

    def checkpoint(self):
        import torch

        from ials_zoo.baselines.runs import save_training_state

        with self.clock.pause():
            state = {"policy": self.model.policy.state_dict(),
                     "optimizer": self.model.policy.optimizer.state_dict()}
            scale = reward_scale_of(self.model.get_env())
            if scale is not None:
                state["reward_rms"] = {"mean": torch.as_tensor(scale.ret_rms.mean),
                                       "var": torch.as_tensor(scale.ret_rms.var),
                                       "count": torch.as_tensor(float(scale.ret_rms.count))}
            info = {"num_timesteps": int(self.model.num_timesteps), "clock_seconds": self.clock.seconds,
                    "learning_curve": self.curve}
            save_training_state(self.out, state, info)
        self._last_checkpoint = time.monotonic()

    def maybe_checkpoint(self, first: bool = False):
        if first or time.monotonic() - self._last_checkpoint > self.checkpoint_seconds:
            self.checkpoint()

    def record(self, steps: int):
        """Score the current policy on the GS, append it to the curve, checkpoint (clock paused)."""
        with self.clock.pause():
            self.training["env_steps"] = int(steps)
            self.training["wall_clock_seconds"] = self.clock.seconds - self.aip_seconds
            ev = self.evaluators[self.curve_agent](self.policy())
            self.curve.append(curve_point(steps, self.clock.seconds, ev))
            header = {k: self.meta[k] for k in ("env_id", "algorithm", "seed")}
            atomic_write_text(self.out / "curve.json", json.dumps(dict(
                header, agent=self.curve_agent, simulator=self.training["simulator"],
                points=self.curve), indent=2) + "\n")
            self.checkpoint()
        return ev

    def learn(self, total_timesteps: int, eval_every: int, final_episodes: int,
              progress: bool) -> dict:
        """Train up to ``total_timesteps``; return ``{agent: EvaluationResult}`` of the final
        policy (``policy.safetensors``) over ``final_episodes`` GS episodes. Closes the
        training env and the evaluators (killing workers after an error or an interrupt)."""
        from ials_zoo.policy import save_policy

        done = int(self.model.num_timesteps)
        callback = make_progress_callback(total_timesteps, self, eval_every, progress)
        ok = False
        try:
            if done < total_timesteps:
                self.model.learn(total_timesteps=total_timesteps - done, callback=callback,
                                 reset_num_timesteps=done == 0)
            steps = int(self.model.num_timesteps)
            # The final policy is on the curve (unless the last evaluation was at this very
            # step) and is scored again for the result on final_episodes episodes.
            if not self.curve or self.curve[-1]["env_steps"] != steps:
                self.record(steps)
            self.training["env_steps"] = steps
            self.training["wall_clock_seconds"] = self.clock.seconds - self.aip_seconds
            path = self.out / "policy.safetensors"
            with self.clock.pause():
                save_policy(self.policy(), path)
                finals = {a: ev(_file_policy(path), final_episodes, progress=progress)
                          for a, ev in self.evaluators.items()}
            ok = True
        finally:
            for ev in self.evaluators.values():
                ev.close(kill=not ok)
            self.model.get_env().close()
        for ev in finals.values():
            ev.policy_file = "policy.safetensors"  # relative to the run folder (where results live)
        return finals


def _file_policy(path):
    from ials_zoo.evaluation import load_model

    return load_model(path)


def make_progress_callback(total: int, run: TrainingRun, eval_every: int, progress: bool):
    """An SB3 callback: a tqdm progress bar (with the last GS score), ``run.record`` every
    ``eval_every`` environment steps (0 = never), checkpoints after the first update and every
    ``run.checkpoint_seconds``."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _Callback(BaseCallback):
        def _on_training_start(self):
            start = self.num_timesteps
            self.next_eval = None
            if eval_every > 0:
                self.next_eval = (start // eval_every + 1) * eval_every
            self.bar = None
            if progress:
                from tqdm.auto import tqdm

                self.bar = tqdm(total=total, initial=start, unit="step", dynamic_ncols=True, desc="train")
            self.last = start
            self.updates = 0

        def _on_step(self):
            if self.bar is not None:
                self.bar.update(self.num_timesteps - self.last)
            self.last = self.num_timesteps
            if self.next_eval is not None and self.num_timesteps >= self.next_eval:
                ev = run.record(self.num_timesteps)
                if self.bar is not None:
                    self.bar.set_postfix(gs=f"{ev.mean:.2f}")
                while self.next_eval <= self.num_timesteps:
                    self.next_eval += eval_every
            return True

        def _on_rollout_end(self):
            self.updates += 1
            run.maybe_checkpoint(first=self.updates == 1)

        def _on_training_end(self):
            if self.bar is not None:
                self.bar.close()

    return _Callback()
