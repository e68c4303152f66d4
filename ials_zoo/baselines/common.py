"""Pieces shared by the PPO baselines: dataclass <-> command line, training simulators, the
periodic GS evaluation with its learning curve, and saving a model with its metadata sidecar.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import time
import typing
from pathlib import Path

import numpy as np

from ials_zoo.utils import atomic_path, atomic_write_text

# --------------------------------------------------------------------------------------------
# dataclass <-> argparse


def add_dataclass_args(parser: argparse.ArgumentParser, cls) -> argparse.ArgumentParser:
    """Add one ``--field-name`` option per field of the dataclass ``cls``.

    The help text of a field is its ``metadata["help"]``; booleans get ``--x/--no-x``."""
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        name = "--" + f.name.replace("_", "-")
        aliases = list(f.metadata.get("aliases", ()))
        default = f.default if f.default is not dataclasses.MISSING else None
        help_text = f"{f.metadata.get('help', '')} (default: {default!r})"
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
    parser = argparse.ArgumentParser(description=description)
    add_dataclass_args(parser, cls)
    return dataclass_from_namespace(cls, parser.parse_args(argv))


def run_cli(module) -> int:
    """``python -m`` entry point of a baseline module: parse its ``Args``, run its ``main``;
    bad arguments print one clear line instead of a traceback."""
    import sys

    args = parse_args(module.Args, description=module.__doc__.splitlines()[0])
    try:
        module.main(args)
    except (ValueError, TypeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


def arg(default, help: str, **kw):
    """A dataclass field with a help text (and optional ``aliases``)."""
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


def predictor_record(venv, simulator: str, env_id: str, agent: str) -> dict | None:
    """What the training record says about the AIP behind an IALS vec env (None on the GS).

    The IALS vec env exposes its predictor as ``venv.predictor``; a trained AIP's
    ``metadata`` holds its training report, with ``dataset.collect_seconds`` (Algorithm 1)
    and ``train_seconds``: their sum is added to the training wall-clock, as in the paper's
    plots. Predictors that need neither (untrained, fixed) count 0; so does ``marginal``,
    whose metadata does not carry the data collection time (documented limitation)."""
    if simulator == GS:
        return None
    pred = getattr(venv, "predictor", None)
    meta = dict(getattr(pred, "metadata", None) or {})
    collect = (meta.get("dataset") or {}).get("collect_seconds") or meta.get("collect_seconds")
    train = meta.get("train_seconds")
    file = None
    if os.path.exists(simulator):
        file = simulator
    elif predictor_for(simulator) in ("trained", "marginal"):
        from ials_zoo.influence.ials import pretrained_path

        shipped = pretrained_path(env_id, agent)
        file = str(shipped) if shipped.is_file() else None
    sha = None
    if file:
        from ials_zoo.evaluation import sha256_file

        sha = sha256_file(file)
    meta.pop("marginal", None)
    return {
        "variant": str(meta.get("variant") or predictor_for(simulator)),
        "class": type(pred).__name__ if pred is not None else None,
        "file": str(file) if file else None,
        "sha256": sha,
        "collection_seconds": float(collect or 0.0),
        "training_seconds": float(train or 0.0),
        "metadata": _jsonable(meta),
    }


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
# Saving models


def save_model(model, path: Path, metadata: dict) -> Path:
    """Save an SB3 model atomically with its metadata sidecar (``<name>.meta.json``)."""
    from ials_zoo.evaluation import meta_path, sha256_file

    path = Path(path)
    with atomic_path(path, suffix=".zip") as tmp:
        model.save(str(tmp))
    meta = dict(metadata, model_sha256=sha256_file(path))
    atomic_write_text(meta_path(path), json.dumps(meta, indent=2, default=str) + "\n")
    return path


# --------------------------------------------------------------------------------------------
# Periodic evaluation on the GS


class Evaluator:
    """Scores the current policy on the GS, in this process or in a worker process.

    SUMO domains are evaluated in a worker process (libsumo: one simulation per process) from
    a checkpoint saved just before; other domains in this process from the live model.
    """

    def __init__(self, env_id: str, agent: str, frame_stack: int, episodes: int,
                 deterministic: bool, in_subprocess: bool, options: dict | None = None):
        self.env_id, self.agent, self.frame_stack = env_id, agent, frame_stack
        self.options = dict(options or {})
        self.episodes, self.deterministic = episodes, deterministic
        self.in_subprocess = in_subprocess
        self._pool = None

    def __call__(self, model, checkpoint: Path | None, episodes: int | None = None):
        from ials_zoo.evaluation import SB3Policy, evaluate

        n = int(episodes or self.episodes)
        if self.in_subprocess:
            if checkpoint is None:
                raise ValueError("subprocess evaluation needs a saved checkpoint")
            from ials_zoo.evaluation import _evaluate_worker
            from ials_zoo.processes import shutdown_pool, spawn_pool

            if self._pool is None:
                self._pool = spawn_pool(1)
            try:
                return self._pool.submit(
                    _evaluate_worker, self.env_id, self.agent, str(checkpoint),
                    {"episodes": n, "deterministic": self.deterministic, **self.options},
                ).result()
            except BaseException:
                shutdown_pool(self._pool, kill=True)
                self._pool = None
                raise
        policy = SB3Policy(model, frame_stack=self.frame_stack, deterministic=self.deterministic,
                           name=Path(checkpoint).name if checkpoint else "model",
                           file=str(checkpoint) if checkpoint else None)
        return evaluate(self.env_id, self.agent, policy, episodes=n, **self.options)

    def close(self, kill: bool = False):
        from ials_zoo.processes import shutdown_pool

        shutdown_pool(self._pool, kill=kill)
        self._pool = None


def curve_point(steps: int, seconds: float, ev) -> dict:
    return {"env_steps": int(steps), "wall_clock_seconds": float(seconds), "mean": ev.mean,
            "ci_low": ev.ci_low, "ci_high": ev.ci_high}


def make_progress_callback(total: int, evaluate_fn, eval_every: int, progress: bool):
    """An SB3 callback: a tqdm progress bar, and ``evaluate_fn(num_timesteps)`` every
    ``eval_every`` environment steps (0 = never)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _Callback(BaseCallback):
        def _on_training_start(self):
            self.next_eval = eval_every if eval_every > 0 else None
            self.bar = None
            if progress:
                from tqdm import tqdm

                self.bar = tqdm(total=total, unit="step", dynamic_ncols=True)
            self.last = self.num_timesteps

        def _on_step(self):
            if self.bar is not None:
                self.bar.update(self.num_timesteps - self.last)
            self.last = self.num_timesteps
            if self.next_eval is not None and self.num_timesteps >= self.next_eval:
                ev = evaluate_fn(self.num_timesteps)
                if self.bar is not None:
                    self.bar.set_postfix(gs=f"{ev.mean:.2f}")
                while self.next_eval <= self.num_timesteps:
                    self.next_eval += eval_every
            return True

        def _on_training_end(self):
            if self.bar is not None:
                self.bar.close()

    return _Callback()


class Clock:
    """Training wall-clock that excludes the time spent evaluating and checkpointing.

    ``offset`` (the AIP's collection + training seconds) is added; inside ``with
    clock.pause():`` the clock stands still at the value it had when the pause began."""

    def __init__(self, offset: float = 0.0):
        self.offset = float(offset)
        self._start = time.perf_counter()
        self._paused = 0.0
        self._pause_start = None

    @contextlib.contextmanager
    def pause(self):
        if self._pause_start is not None:  # nested: already stopped
            yield
            return
        self._pause_start = time.perf_counter()
        try:
            yield
        finally:
            self._paused += time.perf_counter() - self._pause_start
            self._pause_start = None

    @property
    def seconds(self) -> float:
        now = self._pause_start if self._pause_start is not None else time.perf_counter()
        return self.offset + now - self._start - self._paused


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


class TrainingRun:
    """The bookkeeping of one training run in ``out``: at every evaluation point, save
    ``checkpoint.zip`` (+ metadata), score it on the GS and rewrite ``curve.json``; at the end,
    save ``model.zip`` and score it for every evaluator's agent.

    ``meta`` is the model metadata; its ``training`` record and ``learning_curve`` are updated
    in place. The first evaluator's agent is the one the curve follows. The clock starts at
    ``aip_seconds`` and stands still during evaluation and checkpointing.
    """

    def __init__(self, model, out: Path, meta: dict, evaluators: dict, aip_seconds: float = 0.0):
        self.model, self.out, self.meta = model, Path(out), meta
        self.training, self.curve = meta["training"], meta["learning_curve"]
        self.evaluators = evaluators
        self.curve_agent = next(iter(evaluators))
        self.aip_seconds = float(aip_seconds)
        self.clock = Clock(offset=self.aip_seconds)
        self.checkpoint = self.out / "checkpoint.zip"

    def record(self, steps: int):
        """Checkpoint, evaluate on the GS, append to the curve (clock paused)."""
        with self.clock.pause():
            self.training["env_steps"] = int(steps)
            self.training["wall_clock_seconds"] = self.clock.seconds - self.aip_seconds
            save_model(self.model, self.checkpoint, self.meta)
            ev = self.evaluators[self.curve_agent](self.model, self.checkpoint)
            self.curve.append(curve_point(steps, self.clock.seconds, ev))
            header = {k: self.meta[k] for k in ("env_id", "algorithm", "seed")}
            atomic_write_text(self.out / "curve.json", json.dumps(dict(
                header, agent=self.curve_agent, simulator=self.training["simulator"],
                points=self.curve), indent=2) + "\n")
            save_model(self.model, self.checkpoint, self.meta)  # metadata now holds the curve
        return ev

    def learn(self, total_timesteps: int, eval_every: int, final_episodes: int,
              progress: bool) -> dict:
        """Train; return ``{agent: EvaluationResult}`` of the final model (``model.zip``)
        over ``final_episodes`` GS episodes. Closes the training env and the evaluators."""
        callback = make_progress_callback(total_timesteps, self.record, eval_every, progress)
        try:
            self.model.learn(total_timesteps=total_timesteps, callback=callback)
            steps = int(self.model.num_timesteps)
            # The final model is on the curve (unless the last evaluation was at this very
            # step) and is scored again for the result on final_episodes episodes.
            if not self.curve or self.curve[-1]["env_steps"] != steps:
                self.record(steps)
            model_path = self.out / "model.zip"
            with self.clock.pause():
                save_model(self.model, model_path, self.meta)
                finals = {a: ev(self.model, model_path, final_episodes)
                          for a, ev in self.evaluators.items()}
        finally:
            for ev in self.evaluators.values():
                ev.close()
            self.model.get_env().close()
        for ev in finals.values():
            ev.policy_file = "model.zip"  # relative to the run folder (where results live)
        return finals
