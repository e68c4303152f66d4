"""Pieces shared by the multi-agent baselines (DIALS, IPPO): their PPO settings, the joint
policy (one actor per agent) and its GS evaluation, the training log, checkpoints and the
multi-agent result."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ials_zoo.baselines.arguments import (
    AblatedPPOSettings,
    arg,
    check_frame_stack,
    check_ppo_settings,
    check_recurrent_hidden,
    hidden_sizes,
    parse_env_options,
)
from ials_zoo.baselines.runs import DETERMINISTIC_RESULT
from ials_zoo.core.domains import get_domain
from ials_zoo.core.extras import dials_of
from ials_zoo.core.spaces import stack_observations
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import evaluate_joint, load_model
from ials_zoo.influence.files import save_predictor_set
from ials_zoo.leaderboard import make_result, write_result
from ials_zoo.policy import PolicyNetwork, save_policy
from ials_zoo.utils import atomic_path, atomic_write_text


@dataclass
class MultiPPOSettings(AblatedPPOSettings):
    """PPO settings of every agent, chosen by the ablation of
    :mod:`ials_zoo.reproduce.ablation` (IPPO on the GS, 3 seeds per cell, both domains; table
    in ``docs/ablation.md``), where SPEC §3/§6's settings (lr 2.5e-4 decayed linearly, 3
    epochs of the authors' buffer of 128, gamma 0.99) learned too slowly to beat the scripted
    controllers: lr 1e-3 held constant, 10 epochs of 512 samples of each agent per update in
    minibatches of 128, rewards scaled by the running std of the discounted return (with one
    gradient clip over actor and critic, unscaled traffic returns let the critic's loss shrink
    the policy's steps), gamma 0.95. Clip 0.1, entropy 0.01, lambda 0.95 and value coefficient
    1 stay the authors'. The rollout length per copy is ``samples_per_update / copies``. A
    domain may choose its own update size (:func:`fill_update_size`): the warehouse's
    learners take 2,048 samples in minibatches of 256 (a single learner among scripted robots
    went from 8.9 to 13.8 at 512k steps, ``docs/ablation.md``).
    Policies are MLPs of ``hidden`` units (64-64: with 25-36 learners PPO's own computation
    dominates a 2-core machine; SPEC §6 used 256-128)."""

    samples_per_update: int | None = arg(None, "samples of each agent per PPO update (default: the domain's: 512 in "
                                         "traffic, 2048 in the warehouse)")
    batch_size: int | None = arg(None, "minibatch size (samples of one agent; default: the domain's: 128 in traffic, "
                                 "256 in the warehouse)")
    hidden: str = arg("64,64", "hidden layers of every actor and critic, comma-separated")
    normalize_advantage: bool = arg(True, "normalise advantages per agent and minibatch")
    normalize_reward: bool = arg(True, "divide rewards by the running std of each agent's discounted return")
    frame_stack: int | None = arg(None, "observations a policy reads (default: the domain's multi-agent choice)")
    recurrent_hidden: int = arg(0, "units of a GRU that reads the stacked observations before the MLP (SPEC §6's "
                                   "warehouse policy: --frame-stack 8 --recurrent-hidden 64); 0: no GRU")


PREVIOUS_PPO_SETTINGS = {"learning_rate": 2.5e-4, "anneal_lr": True, "n_epochs": 3, "samples_per_update": 128,
                         "batch_size": 64, "hidden": "64,64", "ent_coef": 0.01, "gamma": 0.99,
                         "normalize_advantage": True, "normalize_reward": False, "frame_stack": None}
"""The multi-agent PPO settings before the ablation of ``ials_zoo.reproduce.ablation`` (SPEC §3
with the authors' buffer of 128): kept to measure against (``ials-zoo bench``, the ablation)."""

@dataclass
class JointRunArgs:
    """The arguments of every run in which all agents learn at once (:mod:`.ippo`, :mod:`.dials`,
    :mod:`.idqn`): what to train, for how long, how it is scored and where its run goes."""

    env_id: str | None = arg(None, "the domain to train on", aliases=("--env",), required=True)
    agents: str = arg("all", "learning agents, comma-separated, or 'all'")
    seed: int = arg(0, "run seed")
    total_timesteps: int | None = arg(None, "environment steps per agent (default: the domain's multi-agent budget)")
    env_options: str = arg("", "domain options as a JSON object")
    eval_every: int | None = arg(None, "GS evaluation every N steps per agent (default: a tenth of the budget)")
    checkpoint_every: int | None = arg(None, "a checkpoint every N steps per agent between evaluations too (default: a "
                                       "quarter of --eval-every; 0: at evaluations only); where they fall does not "
                                       "change the run")
    eval_episodes: int = arg(10, "GS episodes per evaluation")
    final_eval_episodes: int = arg(20, "GS episodes of the final score (the protocol's 20)")
    resume: bool = arg(False, "continue the unfinished run in --out-dir from its last checkpoint")
    overwrite: bool = arg(False, "replace whatever --out-dir holds")
    progress: bool = arg(True, "show a progress bar")
    submitter: str = arg("", "submitter name for result.json")
    notes: str = arg("", "notes for result.json")


@dataclass
class MultiAgentRunArgs(JointRunArgs, MultiPPOSettings):
    """The arguments every multi-agent PPO baseline (:mod:`.ippo`, :mod:`.dials`) shares: the
    run's (:class:`JointRunArgs`) and every agent's PPO settings."""


def check_multi_ppo(args, domain) -> list[int]:
    """Clear errors for the PPO settings, after filling in the domain's update size where it
    was not given (:func:`fill_update_size`); returns the hidden sizes."""

    fill_update_size(args, domain)
    for name in ("samples_per_update", "batch_size"):
        if getattr(args, name) < 1:
            raise BadInput(f"{name} must be >= 1, got {getattr(args, name)}")
    check_frame_stack(args.frame_stack)
    check_recurrent_hidden(args.recurrent_hidden)
    check_ppo_settings(args)
    return hidden_sizes(args.hidden, "hidden")


def env_options_of(args, domain, only_gs: bool = False) -> dict:
    """``--env-options`` of a run: where they name the user's own files (a network of their
    own: :attr:`~ials_zoo.core.domains.Domain.file_options`), their paths made absolute and
    written back into ``args``, so that the run records them whole and its policy and command
    work from any folder. ``only_gs``: options the GS does not take are refused by name."""
    options = parse_env_options(args.env_options)
    allowed = set(domain.gs_options) | set(domain.file_options)
    unknown = sorted(set(options) - allowed)
    if only_gs and unknown:
        raise BadInput(f"--env-options: {unknown} are not options of {domain.env_id}'s GS; its options: "
                       f"{', '.join(list(domain.gs_options) + list(domain.file_options)) or 'none'}")
    absolute = domain.with_absolute_files(options)
    if absolute != options:
        args.env_options = json.dumps(absolute)
    return absolute


def train_options_of(args, domain, options: dict) -> dict:
    """The GS options the GS copies of a run (IPPO, IDQN) learn under beside ``options``:
    ``--train-reward``'s reward, which the policy is not scored on."""
    if args.train_reward is None:
        return {}
    if domain.reward_option is None:
        raise BadInput(f"--train-reward: {domain.env_id} has one reward")
    if args.train_reward not in domain.rewards:
        raise BadInput(f"--train-reward: {args.train_reward!r} is not a reward of {domain.env_id}; its rewards: "
                       f"{', '.join(domain.rewards)}")
    if domain.reward_option in options:
        raise BadInput("--env-options names the reward, which scores the policy: learn from another with "
                       "--train-reward instead")
    return {domain.reward_option: args.train_reward}


def fill_update_size(args, domain) -> None:
    """Set ``args.samples_per_update`` and ``args.batch_size`` where they are None: the
    domain's choice (:attr:`DIALSSettings.ppo_samples_per_update`, ``ppo_batch_size``). Runs
    record the filled values."""
    settings = dials_of(domain)
    if args.samples_per_update is None:
        args.samples_per_update = int(settings.ppo_samples_per_update)
    if args.batch_size is None:
        args.batch_size = int(settings.ppo_batch_size)


def whole_updates(total: int, per_update: int, round_up: bool = False) -> int:
    """The budget per agent as whole PPO updates: a budget below one update is refused, one
    between updates is rounded down and said so (never silently changed). ``round_up``: rounded
    up instead, as SB3 itself trains (whole rollouts of every environment), also said so."""
    total = int(total)
    if round_up:
        rounded = -(-total // per_update) * per_update
        if rounded != total:
            print(f"note: --total-timesteps {total:,} rounded up to {rounded:,}, a whole number of PPO updates of "
                  f"{per_update:,} samples", flush=True)
        return rounded
    if total < per_update:
        raise BadInput(f"--total-timesteps {total:,} is less than one PPO update ({per_update:,} samples per agent: "
                         "--samples-per-update); give at least that")
    if total % per_update:
        print(f"note: --total-timesteps {total:,} rounded down to {total // per_update * per_update:,}, a whole number "
              f"of PPO updates of {per_update:,} samples per agent", flush=True)
    return total // per_update * per_update


def frame_stack_of(args, domain) -> int:
    """The observations a policy reads: ``--frame-stack``, else the domain's multi-agent
    choice (:attr:`DIALSSettings.frame_stack`), else the domain's own."""
    return int(args.frame_stack or dials_of(domain).frame_stack or domain.frame_stack)


def ppo_config(args, copies: int, frame_stack: int = 1) -> dict:
    """:class:`~ials_zoo.learners.batched_ppo.PPOConfig` fields for ``copies`` per agent and
    policies reading ``frame_stack`` observations."""
    if args.samples_per_update % copies:
        raise BadInput(f"samples_per_update ({args.samples_per_update}) must be a multiple of the copies per "
                         f"agent ({copies})")
    return {"n_steps": args.samples_per_update // copies, "n_envs": copies, "batch_size": args.batch_size,
            "n_epochs": args.n_epochs, "learning_rate": args.learning_rate, "anneal_lr": args.anneal_lr,
            "clip_range": args.clip_range, "ent_coef": args.ent_coef, "vf_coef": args.vf_coef, "gamma": args.gamma,
            "gae_lambda": args.gae_lambda, "max_grad_norm": args.max_grad_norm,
            "hidden": tuple(int(x) for x in args.hidden.split(",")),
            "normalize_advantage": args.normalize_advantage, "normalize_reward": args.normalize_reward,
            # only a recurrent run records them: earlier runs' settings stay as they were
            **({"recurrent_hidden": args.recurrent_hidden, "frames": frame_stack} if args.recurrent_hidden else {})}


def joint_policy(agents, layers, obs_size: int, n_actions: int, frame_stack: int, metadata: dict,
                 action_counts=None, activation: str = "tanh"):
    """The agents' actors (:meth:`~ials_zoo.learners.batched_ppo.BatchedPPO.actor_layers`: a
    GRU's four tensors first where the policy is recurrent) as one
    :class:`~ials_zoo.policy.PolicyNetwork` (``action_counts``: agents with their own)."""
    gru = layers[0] if len(layers[0]) == 4 else None
    return PolicyNetwork(agents, obs_size, n_actions, layers[1:] if gru else layers, activation, frame_stack,
                         metadata, recurrent=gru, action_counts=action_counts)


class JointActor:
    """A joint policy as :func:`ials_zoo.influence.dataset.collect_all` drives it: every agent
    samples from its own actor, reading its last ``frame_stack`` observations."""

    def __init__(self, net, seed: int):
        self.net, self.seed, self.name = net, int(seed), "joint policy"
        self._episode = 0
        self._buf = None

    def reset(self):
        self._rng = np.random.default_rng([self.seed, self._episode])
        self._episode += 1
        self._buf = None

    def joint_act(self, observations: dict) -> dict:
        # agents with observations of their own lengths are zero-padded, as the learner saw them
        obs = stack_observations(observations, self.net.agents, self.net.obs_size).astype(np.float32)
        k = self.net.frame_stack
        if self._buf is None:
            self._buf = np.zeros((len(obs), obs.shape[1] * k), np.float32)
        w = obs.shape[1]
        self._buf[:, :-w] = self._buf[:, w:]
        self._buf[:, -w:] = obs
        acts = self.net.act(self._buf, self._rng)
        return {a: int(u) for a, u in zip(self.net.agents, acts)}


class TrainingLog:
    """``progress.csv``: one row per stretch of training (steps per agent, wall-clock, the
    agents' mean episode return, the learner's statistics: PPO's unless ``columns`` says). With
    ``agents``, also ``agent_returns.csv``: each agent's own mean episode return per stretch
    (which light's return moves when the mean does), from a row's ``agent_returns``."""

    COLUMNS = ("steps_per_agent", "wall_clock_seconds", "mean_episode_return", "policy_loss", "value_loss",
               "entropy", "clip_fraction", "approx_kl", "learning_rate", "aip_refreshes")
    PER_AGENT = "agent_returns.csv"

    def __init__(self, path: Path, columns: tuple = COLUMNS, agents=None):
        self.path, self.COLUMNS = Path(path), tuple(columns)
        self.per_agent = None if agents is None else TrainingLog(self.path.with_name(self.PER_AGENT),
                                                                 ("steps_per_agent", *agents))
        if not self.path.exists():
            with open(self.path, "w", newline="") as f:
                csv.writer(f).writerow(self.COLUMNS)

    def add(self, row: dict) -> None:
        with open(self.path, "a", newline="") as f:
            csv.writer(f).writerow(["" if row.get(c) is None else row[c] for c in self.COLUMNS])
        if self.per_agent is not None and row.get("agent_returns"):
            self.per_agent.add(dict(row["agent_returns"], steps_per_agent=row["steps_per_agent"]))

    def truncate(self, steps: int) -> None:
        """Drop the rows past ``steps`` per agent (a resumed run trains them again from its
        checkpoint; without this they would be logged twice)."""
        with open(self.path, newline="") as f:
            rows = list(csv.reader(f))
        text = io.StringIO()
        csv.writer(text).writerows(rows[:1] + [r for r in rows[1:] if r and int(float(r[0])) <= steps])
        atomic_write_text(self.path, text.getvalue())
        if self.per_agent is not None:
            self.per_agent.truncate(steps)


def merge_shard_stats(stats: list[dict], chunks: list[list[str]]) -> dict:
    """One row from the shards' statistics (weighted by their agents; ``chunks``: each shard's
    agents), with every agent's own mean episode return (``agent_returns``, None where no
    episode ended)."""
    agents_per_shard = [len(c) for c in chunks]
    out, total = {}, sum(agents_per_shard)
    for key in ("policy_loss", "value_loss", "entropy", "clip_fraction", "approx_kl", "learning_rate"):
        vals = [(s[key], n) for s, n in zip(stats, agents_per_shard) if key in s]
        if vals:
            out[key] = sum(v * n for v, n in vals) / sum(n for _, n in vals)
    returns = [r for s in stats if s.get("episode_returns") is not None for r in s["episode_returns"]]
    finite = [r for r in returns if r == r]
    out["mean_episode_return"] = float(np.mean(finite)) if finite else None
    out["agents"] = total
    out["agent_returns"] = agent_returns(
        [a for c in chunks for a in c],
        None if len(returns) != total else returns)
    return out


def agent_returns(agents: list, returns) -> dict | None:
    """``{agent: its mean episode return}`` (None where no episode of it ended) from returns in
    ``agents``' order, or None without them."""
    if returns is None:
        return None
    return {a: (float(r) if r == r else None) for a, r in zip(agents, returns)}


def write_curve(out: Path, header: dict, points: list) -> None:
    atomic_write_text(Path(out) / "curve.json", json.dumps(dict(header, points=points), indent=2) + "\n")


def save_aips(path: Path, predictors: dict) -> None:

    save_predictor_set(predictors.values(), path)


def final_results(out: Path, env_id: str, policy_path: Path, algorithm: str, training: dict, curve: list,
                  agents: list, seed: int, episodes: int, options: dict, submitter: str = "", notes: str = "",
                  progress: bool = False) -> tuple[dict, dict]:
    """The final joint policy scored on the GS twice, with the protocol's seeds: sampling its
    actions (``result.json``, the score) and taking each agent's most likely action
    (``result_deterministic.json``); both results are written and returned."""

    results = []
    for deterministic, name in ((False, "result.json"), (True, DETERMINISTIC_RESULT)):
        ev = evaluate_joint(env_id, load_model(policy_path), episodes=episodes, deterministic=deterministic,
                            progress=progress, **options)
        ev.policy_file = "policy.safetensors"
        result = make_result([ev], algorithm=algorithm, training=training, training_seeds=[seed],
                             learning_curves=[{"seed": seed, "points": curve}], trained_agents=agents,
                             submitter=submitter, notes=notes)
        # a run on the user's own network keeps its result (the board refuses it on submit)
        write_result(Path(out) / name, result, local=bool(set(options) & set(get_domain(env_id).file_options)))
        results.append(result)
    return results[0], results[1]


def policy_file(out: Path, net) -> Path:

    return save_policy(net, Path(out) / "policy.safetensors")


def checkpoint_every_of(args, eval_every: int, per_update: int) -> int | None:
    """Steps per agent between checkpoints (None: at evaluations only). By default a quarter of
    the evaluation interval, so that a crash loses minutes, not an evaluation's worth (an
    evaluation on ingolstadt21 comes every 12-14 minutes). A multi-agent checkpoint holds the
    episodes in flight (their seeds and actions), so where checkpoints fall leaves the run as
    it is."""
    if args.checkpoint_every == 0:
        return None
    return int(args.checkpoint_every or max(per_update, eval_every // 4))


def settings_of(args, skip=("resume", "overwrite", "progress", "out_dir", "submitter", "notes", "workers",
                            "backend", "ray_address", "checkpoint_every")) -> dict:
    """The settings that shape a run's numbers (a resume must repeat them). The workers and
    backend do not: a run may resume with others (the results do not depend on them)."""
    return {k: v for k, v in dataclasses.asdict(args).items() if k not in skip}


__all__ = ["JointActor", "MultiPPOSettings", "TrainingLog", "atomic_path", "check_multi_ppo", "fill_update_size", "joint_policy",
           "PREVIOUS_PPO_SETTINGS", "checkpoint_every_of", "final_results", "frame_stack_of", "merge_shard_stats", "agent_returns", "whole_updates", "policy_file", "ppo_config", "save_aips", "settings_of", "write_curve"]
