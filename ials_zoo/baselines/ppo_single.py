"""PPO for one agent, trained on the GS or on an IALS, scored on the GS (SPEC §3).

Usage::

    ials-zoo train ppo_single --env warehouse_v0 --simulator ials
    ials-zoo train ppo_single --env traffic_grid_v0 --agent tls_12 --simulator gs --total-timesteps 100000
    python -m baselines.ppo_single --help

``--simulator``: ``gs`` (the global simulator, other agents scripted), ``ials`` (the local
simulator + the trained AIP shipped with the package), ``untrained-ials``, ``uniform``,
``fixed:P`` (F-IALS with the fixed probability P), ``marginal`` (F-IALS with the empirical
marginal) or a path to a predictor ``.pt`` file (:mod:`ials_zoo.influence.specs`).

The defaults are the multi-agent ablation's (``docs/ablation.md``; SPEC §3's, the authors', in
:data:`PREVIOUS_SETTINGS`): lr 1e-3 held constant, 10 epochs of 512 samples per update (8
parallel envs x 64 steps) in minibatches of 128 (the warehouse: 2,048 = 8 x 256 in minibatches
of 256, the domain's choice, :func:`update_size`), gamma 0.95, rewards divided by the running
std of the discounted return (SB3's ``VecNormalize``, observations untouched), MLPs of 64-64
(separate policy and value networks); clip 0.1, entropy 0.01, value coefficient 1, GAE lambda
0.95 and gradient clipping at 0.5 stay the authors'. The warehouse policy reads one
observation (``DIALSSettings.frame_stack``; memoryless policies learned faster than 8-frame
ones there). GS evaluation every 100k steps. The budget defaults to the domain's study budget
(``study_of(domain).budget``: 2M steps in the warehouse as in the paper; 300k in traffic); the run
prints its expected duration before it starts.

Outputs in ``--out-dir`` (default ``runs/<env>__<agent>__<simulator>__s<seed>``; a used folder
is refused unless ``--resume`` or ``--overwrite``), all written atomically (see
:mod:`ials_zoo.baselines.runs`):

* ``status.json`` -- running / finished / failed / interrupted;
* ``progress.csv`` -- training metrics per stretch between evaluations (SB3's mean episode
  return, losses, entropy; the columns of the multi-agent runs);
* ``curve.json`` -- the learning curve, rewritten after every evaluation (the first at step
  0): GS mean return and 95% CI vs environment steps and wall-clock seconds;
* ``checkpoint.pt`` + ``checkpoint.json`` -- the training state, saved at every evaluation
  (every 100k steps with ``--eval-every 0``): ``--resume`` continues from it and ends bitwise
  equal to the run that was never stopped (:mod:`ials_zoo.learners.sb3_state`: each
  checkpoint starts new episodes, seeded by the seed and the step count);
* ``policy.safetensors`` -- the final policy (weights + JSON, loadable without running code:
  ``ials-zoo evaluate --policy runs/.../policy.safetensors``);
* ``result.json`` -- a leaderboard result with the final GS score over
  ``--final-eval-episodes`` episodes;
* ``result_deterministic.json`` -- the same policy scored with its most likely actions (not
  written with ``--deterministic-eval``, whose ``result.json`` is already that score).

**Wall-clock**: one figure, ``training.wall_clock_seconds`` = the seconds spent training
(rollouts and updates; GS evaluations and checkpoints excluded), plus, for an IALS, the AIP's
data collection and training seconds (``training.aip_seconds``, from the predictor's metadata),
as in the paper's plots.

Truncation: every zoo episode ends by a time limit. The GS vec env (``DummyVecEnv`` /
``SubprocVecEnv`` over :class:`~ials_zoo.single_agent.SingleAgentGS`) and the IALS vec env
mark the last step ``TimeLimit.truncated`` with its ``terminal_observation``, so SB3's PPO
bootstraps ``gamma * V(s_T)`` instead of treating the time limit as a terminal state.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import torch

from ials_zoo.baselines.aip_record import predictor_record
from ials_zoo.baselines.arguments import (
    AblatedPPOSettings,
    arg,
    check_frame_stack,
    check_ppo_settings,
    hidden_sizes,
    parse_env_options,
    run_cli,
)
from ials_zoo.baselines.driver import RunPlan, run
from ials_zoo.baselines.multiagent import settings_of, whole_updates
from ials_zoo.baselines.retrain import training_command
from ials_zoo.baselines.runs import DETERMINISTIC_RESULT
from ials_zoo.baselines.sb3_run import (
    CHECKPOINT_EVERY,
    RUN_ONLY,
    SB3Learner,
    SingleAgentScoring,
    ppo_speed,
    sb3_env,
)
from ials_zoo.core.domains import Domain, get_domain, ials_domain_ids
from ials_zoo.core.extras import dials_of, study_of
from ials_zoo.errors import BadInput
from ials_zoo.influence.ials import ials_vec_env
from ials_zoo.influence.specs import PredictorSpec, parse_simulator, predictor_for, simulator_label
from ials_zoo.single_agent import gs_vec_env
from ials_zoo.utils import check_seed, format_seconds


@dataclass
class Args(AblatedPPOSettings):
    """Arguments of :func:`main` (``python -m baselines.ppo_single --help``). The PPO settings
    are the multi-agent ablation's (:class:`~ials_zoo.baselines.multiagent.MultiPPOSettings`),
    which beat SPEC §3's here too (:data:`PREVIOUS_SETTINGS`; one seed each, tls_12 on the GS
    166 against 112, on the IALS 156 against 110; robot_20 8.7 against 7.7 and 9.8 against 7.4)."""

    env_id: str | None = arg(None, "the domain to train on", aliases=("--env",), required=True)
    agent: str | None = arg(None, "learning agent (default: the domain's first default agent)")
    simulator: str = arg("gs", "gs | ials | untrained-ials | uniform | fixed:P | marginal | PATH.pt")
    seed: int = arg(0, "training seed")
    total_timesteps: int | None = arg(None, "environment steps of training (default: the domain's study budget)")
    n_envs: int = arg(8, "parallel environments")
    n_steps: int | None = arg(None, "rollout length per environment and update (default: the domain's samples "
                              "per update / n_envs: 512 / 8 = 64 in traffic, 2048 / 8 = 256 in the warehouse)")
    batch_size: int | None = arg(None, "minibatch size (default: the domain's: 128 in traffic, 256 in the warehouse)")
    net_arch: str = arg("64,64", "hidden layer sizes, comma-separated (policy and value nets)")
    frame_stack: int | None = arg(None, "observations the policy reads (default: the domain's choice for learned "
                                  "policies, DIALSSettings.frame_stack, else its frame_stack)")
    normalize_reward: bool = arg(True, "divide rewards by the running std of the discounted return (VecNormalize)")
    env_options: str = arg("", "GS/LS options as a JSON object, e.g. '{\"item_lifetime\": 8}' (memory variant)")
    dset_kind: str | None = arg(None, "d-set kind of the AIP (dset | full; default: the predictor's)")
    eval_every: int = arg(100_000, "GS evaluation every this many steps (0: only at the start and the end); "
                          f"checkpoints come with them and every {CHECKPOINT_EVERY:,} steps")
    eval_episodes: int = arg(10, "GS episodes per periodic evaluation")
    final_eval_episodes: int = arg(20, "GS episodes of the final evaluation (result.json)")
    deterministic_eval: bool = arg(False, "evaluate with the most likely action instead of sampling")
    vec_env: str = arg("auto", "GS vec env: auto | dummy | subproc (SUMO domains: subproc)")
    out_dir: str | None = arg(None, "output folder (default: runs/<env>__<agent>__<sim>__s<seed>)")
    resume: bool = arg(False, "continue the unfinished run in --out-dir from its last checkpoint")
    overwrite: bool = arg(False, "replace whatever --out-dir holds")
    progress: bool = arg(True, "show a progress bar")
    submitter: str = arg("", "submitter name for result.json")
    notes: str = arg("", "notes for result.json")


PREVIOUS_SETTINGS = {"n_epochs": 3, "learning_rate": 2.5e-4, "anneal_lr": True, "gamma": 0.99, "n_steps": 128,
                     "batch_size": 256, "net_arch": "256,128", "normalize_reward": False, "frame_stack": None}
"""SPEC §3's single-agent settings (the authors'; the warehouse read 8 observations), the
defaults before the ablation: kept to measure against."""


def update_size(args, domain) -> tuple[int, int]:
    """``(n_steps, batch_size)``: the given ones, else the domain's choice
    (:attr:`DIALSSettings.ppo_samples_per_update` split over ``n_envs``, ``ppo_batch_size``)."""
    settings = dials_of(domain)
    n_steps = args.n_steps or max(1, settings.ppo_samples_per_update // args.n_envs)
    return int(n_steps), int(args.batch_size or settings.ppo_batch_size)


def check_ppo_args(args, positive=()) -> None:
    """Clear errors for the PPO settings before anything is built."""

    for name in ("n_envs", "n_steps", "batch_size", "n_epochs", "eval_episodes", "final_eval_episodes",
                 *positive):
        value = getattr(args, name, None)
        if value is not None and int(value) < 1:
            raise BadInput(f"{name} must be >= 1, got {value}")
    check_ppo_settings(args)
    if args.eval_every < 0:
        raise BadInput(f"eval_every must be >= 0, got {args.eval_every}")
    check_frame_stack(args.frame_stack)
    # SB3's PPO normalises advantages over a minibatch: one sample gives NaN (it asserts > 1)
    if args.batch_size is not None and args.batch_size < 2:
        raise BadInput(f"batch_size must be >= 2 (PPO normalises advantages over a minibatch), got {args.batch_size}")
    envs = getattr(args, "n_envs", None) or getattr(args, "n_copies", 1)  # ppo_shared: copies of every learner
    if args.n_steps is not None and args.n_steps * envs < 2:
        raise BadInput(f"n_steps must give an update of at least 2 samples, got {args.n_steps} x {envs} environments")
    check_seed(args.seed, "seed")
    hidden_sizes(args.net_arch)
    parse_env_options(args.env_options)


def check_args(args: Args) -> None:
    """Clear errors for bad arguments before anything is built."""

    if args.env_id is None:
        raise BadInput(f"name the domain to train on: --env, one of {', '.join(ials_domain_ids())}")
    check_ppo_args(args, positive=("total_timesteps",))
    predictor_for(args.simulator)


@dataclass(frozen=True)
class TrainingSimulator:
    """Where a ``ppo_single`` run trains, resolved once from its arguments: the domain, the
    agent, the env options and the parsed ``--simulator`` (None: the GS)."""

    domain: Domain
    agent: str
    options: dict
    spec: PredictorSpec | None
    dset_kind: str | None = None
    vec_env: str = "auto"

    @classmethod
    def of(cls, args: Args, domain: Domain, agent: str, options: dict) -> TrainingSimulator:
        spec = parse_simulator(args.simulator)
        if spec is not None and spec.kind == "trained":
            spec = dataclasses.replace(spec, train_if_missing=True)  # a training command may train its AIP
        return cls(domain, agent, options, spec, args.dset_kind, args.vec_env)


def make_training_env(sim: TrainingSimulator, n_envs: int, seed: int):
    """The training vec env (GS or IALS) of ``sim`` and the AIP record (None on the GS)."""

    if sim.spec is None:
        venv = gs_vec_env(sim.domain, sim.agent, n_envs=n_envs, vec_env=sim.vec_env, **sim.options)
        venv.seed(seed)
        return venv, None
    venv = ials_vec_env(sim.domain, sim.agent, n_envs=n_envs, predictor=sim.spec, dset_kind=sim.dset_kind,
                        seed=seed, **sim.options)
    return venv, predictor_record(venv, sim.spec)


def default_out_dir(args: Args, agent: str) -> Path:
    sim = Path(args.simulator).stem if args.simulator.endswith(".pt") else args.simulator
    sim = sim.replace(":", "")
    return Path("runs") / f"{args.env_id}__{agent}__{sim}__s{args.seed}"


def main(args: Args | None = None) -> dict:
    """Train, evaluate and save; returns the result dict (also written to result.json)."""

    args = args or Args()
    check_args(args)
    torch.set_num_threads(1)
    dom = get_domain(args.env_id).require_ials("train ppo_single")
    options = parse_env_options(args.env_options)
    agent = dom.check_agent(args.agent or dom.default_agents[0], **options)
    args.n_steps, args.batch_size = update_size(args, dom)
    per_update = args.n_steps * args.n_envs
    total = whole_updates(args.total_timesteps or study_of(dom).budget, per_update, round_up=True)
    args.total_timesteps = total
    frame_stack = int(args.frame_stack or dials_of(dom).frame_stack or dom.frame_stack)
    out = Path(args.out_dir) if args.out_dir else default_out_dir(args, agent)
    training = {"simulator": args.simulator, "aip": None, "seeds": [args.seed], "env_steps": 0,
                "wall_clock_seconds": 0.0, "aip_seconds": 0.0, "hyperparameters": dataclasses.asdict(args)}
    plan = RunPlan("ppo_single", args.env_id, [agent], options, args.seed, total, per_update,
                   args.eval_every or total, args.eval_episodes, args.final_eval_episodes, frame_stack, out,
                   settings_of(args, skip=RUN_ONLY), training, args.resume, args.overwrite, args.progress,
                   args.submitter, args.notes, meta={"agent": agent, "frame_stack": frame_stack},
                   checkpoint_every=CHECKPOINT_EVERY,
                   steps_per_second=ppo_speed(dom, args.simulator), unit="step", command=training_command("ppo_single", args))

    def make_env(training):
        venv, aip = make_training_env(TrainingSimulator.of(args, dom, agent, options), args.n_envs, args.seed)
        training.update(simulator=simulator_label(args.simulator, (aip or {}).get("variant")), aip=aip)
        # only what this run did is on its clock; a shipped or cached AIP's own cost is recorded
        # in training.aip, not charged
        charged = (aip["collection_seconds"] + aip["training_seconds"]) if aip and aip["charged"] else 0.0
        return sb3_env(venv, args.gamma if args.normalize_reward else None, frame_stack), charged

    learner = SB3Learner(make_env, args, hidden_sizes(args.net_arch), [agent], frame_stack, total, training)
    scoring = SingleAgentScoring(plan, [agent], [agent], args.deterministic_eval, dom.one_simulation_per_process,
                                 lambda _agent: "result.json", None if args.deterministic_eval else DETERMINISTIC_RESULT)
    sim_text = "the GS (every other agent scripted)" if args.simulator == "gs" else f"the IALS ({args.simulator})"
    result = run(plan, learner, f"ppo_single: PPO for {agent} of {args.env_id}, trained on {sim_text}, seed "
                 f"{args.seed}", dom, scoring)
    aip = training["aip"]
    if aip and not aip["charged"] and aip["collection_seconds"] + aip["training_seconds"]:
        print(f"  the AIP was made earlier: its own {format_seconds(aip['collection_seconds'] + aip['training_seconds'])}"
              " are recorded in training.aip, not counted", flush=True)
    return result


if __name__ == "__main__":
    import sys

    sys.exit(run_cli(sys.modules[__name__]))
