"""Multi-agent PPO with one policy shared by all agents of the GS (parameter sharing).

Usage::

    python -m baselines.ppo_shared --env warehouse_v0 --total-timesteps 2000000
    ials-zoo train ppo_shared --env warehouse_v0 --learners robot_19,robot_20,robot_21

Every learning agent of the GS is one "environment" of SB3's PPO (SuperSuit:
``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1``), so the policy learns from all of
them at once; agents that are not learners stay scripted. ``--total-timesteps`` counts agent
transitions (what PPO consumes): one GS step of ``n`` learners is ``n`` of them.

**Truncation.** SuperSuit's own stable-baselines3 wrapper reports a truncated episode as a
terminated one (``done = terminated or truncated``, no ``TimeLimit.truncated``), so PPO would
treat the time limit as a terminal state and never bootstrap its value. This baseline uses
:class:`TruncationAwareSB3VecEnv` instead, which sets ``TimeLimit.truncated`` for truncated
(not terminated) agents; SuperSuit already puts the last observation in
``terminal_observation``, so SB3 bootstraps ``gamma * V(s_T)``.

**SUMO.** A traffic GS holds a libsumo simulation: with ``--n-copies N > 1`` each copy runs in
its own process (``num_cpus = N``); the periodic GS evaluation always runs in a worker process.

Evaluation: the shared policy is scored with the standard protocol
(:mod:`ials_zoo.evaluation`: one agent controlled by the policy, the others scripted) for each
agent in ``--eval-agents`` (default: the domain's default agents that are learners, else
the first learner); one ``result_<agent>.json``
per evaluated agent. The learning curve follows the first evaluated agent. The other outputs
are :mod:`ials_zoo.baselines.ppo_single`'s (``status.json``, ``progress.csv``, ``curve.json``,
``checkpoint.pt`` + ``.json``, ``policy.safetensors``); ``--resume`` ends bitwise equal to the
run that was never stopped.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import supersuit as ss
import torch
from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

from ials_zoo.baselines.arguments import PPOSettings, arg, hidden_sizes, parse_env_options, run_cli
from ials_zoo.baselines.driver import RunPlan, run
from ials_zoo.baselines.multiagent import settings_of, whole_updates
from ials_zoo.baselines.ppo_single import check_ppo_args
from ials_zoo.baselines.retrain import training_command
from ials_zoo.baselines.sb3_run import (
    CHECKPOINT_EVERY,
    RUN_ONLY,
    SB3Learner,
    SingleAgentScoring,
    ppo_speed,
    sb3_env,
)
from ials_zoo.core.domains import get_domain, ials_domain_ids
from ials_zoo.errors import BadInput


def _sb3_wrapper_base():
    return SB3VecEnvWrapper


class TruncationAwareSB3VecEnv(_sb3_wrapper_base()):
    """SuperSuit's stable-baselines3 wrapper, with truncation reported the way SB3 expects.

    ``done = terminated or truncated`` as before, and ``infos[i]["TimeLimit.truncated"]`` is
    True when agent ``i``'s episode was truncated without terminating; the
    ``terminal_observation`` SuperSuit stored is kept. The info dicts are copied first
    (SuperSuit's multiprocess backend may hand out one shared empty dict for several agents).

    ``seed(s)`` is applied at the next ``reset`` (copy ``i`` of the GS gets seed ``s + i``), as
    SB3's VecEnvs do; SuperSuit's wrapper has no working ``seed``.
    """

    _pending_seed = None

    def seed(self, seed=None):
        self._pending_seed = seed
        return [seed]

    def get_attr(self, attr_name, indices=None):
        if attr_name == "render_mode":  # the GS copies have no separate env objects here
            return [self.render_mode] * self.num_envs
        return super().get_attr(attr_name, indices)

    def reset(self, seed=None, options=None):
        seed = self._pending_seed if seed is None else seed
        self._pending_seed = None
        observations, self.reset_infos = self.venv.reset(seed=seed, options=options)
        return observations

    def step_wait(self):
        observations, rewards, terminations, truncations, infos = self.venv.step_wait()
        terminations = np.asarray(terminations, dtype=bool)
        truncations = np.asarray(truncations, dtype=bool)
        infos = [dict(info) for info in infos]
        for i, info in enumerate(infos):
            if truncations[i] and not terminations[i]:
                info["TimeLimit.truncated"] = True
        return observations, rewards, terminations | truncations, infos


def make_shared_vec_env(env_id: str, learners=None, n_copies: int = 1, seed: int | None = None,
                        **options):
    """All learners of ``n_copies`` GS copies as one SB3 ``VecEnv`` (one entry per agent)."""

    if n_copies < 1:
        raise BadInput(f"n_copies must be >= 1, got {n_copies}")
    par = get_domain(env_id).parallel_env(learners=learners, **options)
    vec = ss.pettingzoo_env_to_vec_env_v1(par)
    # SUMO: one simulation per process, so one process per copy (SuperSuit runs a single copy
    # in this process; nothing else in the training process may start libsumo then).
    num_cpus = n_copies if get_domain(env_id).one_simulation_per_process else 0
    gym_vec = ss.concat_vec_envs_v1(vec, n_copies, num_cpus=num_cpus, base_class="gymnasium")
    venv = TruncationAwareSB3VecEnv(gym_vec)
    if seed is not None:
        venv.seed(seed)
    return venv


@dataclass
class Args(PPOSettings):
    """Arguments of :func:`main` (``python -m baselines.ppo_shared --help``)."""

    env_id: str | None = arg(None, "the domain to train on", aliases=("--env",), required=True)
    learners: str = arg("all", "comma-separated learning agents, or 'all'")
    eval_agents: str | None = arg(None, "comma-separated learners to score (default: the domain's default agents among the learners, else the first learner)")
    seed: int = arg(0, "training seed")
    total_timesteps: int = arg(2_000_000, "agent transitions of training")
    n_copies: int = arg(1, "GS copies (SUMO: one process each)")
    n_steps: int = arg(128, "rollout length per agent and update")
    batch_size: int = arg(1152, "minibatch size")
    net_arch: str = arg("256,128", "hidden layer sizes, comma-separated")
    frame_stack: int | None = arg(None, "observations the policy reads (default: the domain's)")
    env_options: str = arg("", "GS options as a JSON object, e.g. '{\"item_lifetime\": 8}'")
    eval_every: int = arg(100_000, "GS evaluation every this many agent transitions (0: only at the start and the "
                          f"end); checkpoints come with them and every {CHECKPOINT_EVERY:,}")
    eval_episodes: int = arg(10, "GS episodes per periodic evaluation")
    final_eval_episodes: int = arg(20, "GS episodes of the final evaluation")
    deterministic_eval: bool = arg(False, "evaluate with the most likely action")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__shared__s<seed>)")
    resume: bool = arg(False, "continue the unfinished run in --out-dir from its last checkpoint")
    overwrite: bool = arg(False, "replace whatever --out-dir holds")
    progress: bool = arg(True, "show a progress bar")
    submitter: str = arg("", "submitter name for the results")
    notes: str = arg("", "notes for the results")


def _agent_list(text: str | None, env_id: str, default, **options) -> list[str]:
    if text is None or text == "":
        return list(default)
    return get_domain(env_id).check_agents(None if text == "all" else text, **options)


def check_args(args: Args) -> None:
    """Clear errors for bad arguments before anything is built."""
    if args.env_id is None:
        raise BadInput(f"name the domain to train on: --env, one of {', '.join(ials_domain_ids())}")
    check_ppo_args(args, positive=("total_timesteps", "n_copies"))


def main(args: Args | None = None) -> list[dict]:
    """Train, evaluate and save; returns one result dict per evaluated agent."""

    args = args or Args()
    check_args(args)
    torch.set_num_threads(1)
    dom = get_domain(args.env_id).require_ials("train ppo_shared")
    options = parse_env_options(args.env_options)
    learners = _agent_list(args.learners, args.env_id, dom.agents(**options), **options)
    default_eval = [a for a in dom.default_agents if a in learners] or learners[:1]
    eval_agents = _agent_list(args.eval_agents, args.env_id, default_eval, **options)
    outside = [a for a in eval_agents if a not in learners]
    if outside or not eval_agents:
        raise BadInput(f"eval_agents {outside or eval_agents} must be learners ({learners})")
    hidden = hidden_sizes(args.net_arch)
    frame_stack = int(args.frame_stack or dom.frame_stack)
    per_update = args.n_steps * args.n_copies * len(learners)
    total = args.total_timesteps = whole_updates(args.total_timesteps, per_update, round_up=True)
    out = Path(args.out_dir or f"runs/{args.env_id}__shared__s{args.seed}")
    training = {"simulator": "gs", "aip": None, "seeds": [args.seed], "env_steps": 0,
                "wall_clock_seconds": 0.0, "aip_seconds": 0.0,
                "hyperparameters": dict(dataclasses.asdict(args), learners=learners, eval_agents=eval_agents)}
    plan = RunPlan("ppo_shared", args.env_id, learners, options, args.seed, total, per_update,
                   args.eval_every or total, args.eval_episodes, args.final_eval_episodes, frame_stack, out,
                   settings_of(args, skip=RUN_ONLY), training, args.resume, args.overwrite, args.progress,
                   args.submitter, args.notes, meta={"agent": eval_agents[0], "frame_stack": frame_stack},
                   checkpoint_every=CHECKPOINT_EVERY,
                   steps_per_second=ppo_speed(dom, "gs"), unit="transition", command=training_command("ppo_shared", args))
    all_agents = dom.agents(**options)

    def make_env(training):
        venv = make_shared_vec_env(args.env_id, learners=None if learners == all_agents else learners,
                                   n_copies=args.n_copies, seed=args.seed, **options)
        return sb3_env(venv, None, frame_stack), 0.0

    learner = SB3Learner(make_env, args, hidden, learners, frame_stack, total, training)
    scoring = SingleAgentScoring(plan, eval_agents, learners, args.deterministic_eval, dom.one_simulation_per_process,
                                 lambda agent: f"result_{agent}.json", None)
    run(plan, learner, f"ppo_shared: one PPO policy shared by {len(learners)} learners of {args.env_id} on the GS, "
        f"seed {args.seed} (steps count agent transitions)", dom, scoring)
    results = [scoring.results[f"result_{a}.json"] for a in eval_agents]
    for r in results[1:]:
        s = r["score"]
        print(f"ppo_shared: GS score of {r['agent']} {s['mean']:.3f} [{s['ci_low']:.3f}, {s['ci_high']:.3f}]")
    return results


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
