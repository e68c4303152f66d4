"""The stable-baselines3 baselines (``ppo_single``, ``ppo_shared``) on the run driver
(:mod:`ials_zoo.baselines.driver`): the learner adapter (:class:`SB3Learner`: one SB3 PPO on
the vec env its baseline builds, checkpointed exactly, :mod:`ials_zoo.learners.sb3_state`) and
the scoring adapter (:class:`SingleAgentScoring`: the policy controls one agent of the GS, the
others scripted, scored in a worker process where the GS is SUMO).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import KVWriter, Logger
from stable_baselines3.common.vec_env import VecEnvWrapper, VecFrameStack, VecMonitor, VecNormalize

from ials_zoo.baselines.runs import DETERMINISTIC_RESULT
from ials_zoo.core.extras import study_of
from ials_zoo.errors import BadInput
from ials_zoo.evaluation import NetworkPolicy, _evaluate_worker, evaluate, load_model
from ials_zoo.influence.specs import GS
from ials_zoo.leaderboard import make_result, write_result
from ials_zoo.learners.sb3_state import checkpoint_models, resume_models
from ials_zoo.policy import PolicyNetwork, policy_from_sb3_model
from ials_zoo.runtime.processes import shutdown_pool, spawn_pool
from ials_zoo.single_agent import box_space


def as_float_box(venv):
    """Make sure the observations are a float32 ``Box`` (what VecFrameStack and the evaluator
    use); wraps ``venv`` only when needed."""

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

        if isinstance(policy, PolicyNetwork):
            policy = NetworkPolicy(policy)
        kwargs = {"episodes": int(episodes or self.episodes), "deterministic": self.deterministic,
                  "progress": progress, **self.options}
        if not self.in_subprocess:
            return evaluate(self.env_id, self.agent, policy, **kwargs)

        if self._pool is None:
            self._pool = spawn_pool(1)
        try:
            return self._pool.submit(_evaluate_worker, self.env_id, self.agent, policy, kwargs).result()
        except BaseException:
            shutdown_pool(self._pool, kill=True)
            self._pool = None
            raise

    def close(self, kill: bool = False):
        shutdown_pool(self._pool, kill=kill)
        self._pool = None


# --------------------------------------------------------------------------------------------
# PPO and the training run


def make_ppo(venv, args, hidden: list[int], total: int | None = None):
    """SB3 PPO with the baseline's hyper-parameters (``args``: ppo_single/ppo_shared Args);
    the learning rate decays linearly to 0 over ``total`` steps (the run's budget) when
    ``args.anneal_lr``. The schedule reads the model's step count, not SB3's progress, which
    restarts at every ``learn()`` call (one per stretch between the driver's evaluations)."""

    model = PPO(
        "MlpPolicy", venv, learning_rate=args.learning_rate, n_steps=args.n_steps, batch_size=args.batch_size,
        n_epochs=args.n_epochs, gamma=args.gamma, gae_lambda=args.gae_lambda,
        clip_range=args.clip_range, ent_coef=args.ent_coef, vf_coef=args.vf_coef,
        max_grad_norm=args.max_grad_norm, seed=args.seed, device="cpu", verbose=0,
        policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden}},
    )
    if args.anneal_lr:
        if total is None:
            raise BadInput("a learning rate that decays needs the run's budget (make_ppo's total)")
        budget = max(int(total), 1)
        model.lr_schedule = lambda _progress: args.learning_rate * max(0.0, 1.0 - model.num_timesteps / budget)
    return model


def ppo_speed(domain, simulator: str) -> float:
    """The study's measured PPO steps per second on 2 cores (``study_of(domain)``), for the
    run's opening estimate."""
    return float(study_of(domain).ppo_steps_per_second.get("gs" if simulator == GS else "ials", 1000.0))


def scale_rewards(venv, gamma: float):
    """``venv`` with its rewards divided by the running std of the discounted return (SB3's
    ``VecNormalize``, observations untouched): what the multi-agent learners do
    (:class:`~ials_zoo.learners.batched_ppo.RewardScale`)."""

    return VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=gamma)


def sb3_env(venv, reward_gamma: float | None, frame_stack: int):
    """The training vec env as PPO reads it: float observations, episode statistics
    (``VecMonitor``), rewards scaled with ``reward_gamma`` (:func:`scale_rewards`; None: not),
    the last ``frame_stack`` observations."""

    venv = VecMonitor(as_float_box(venv))
    if reward_gamma is not None:
        venv = scale_rewards(venv, reward_gamma)
    if frame_stack > 1:
        venv = VecFrameStack(venv, frame_stack)
    return venv


# --------------------------------------------------------------------------------------------
# The driver's adapters

RUN_ONLY = ("resume", "overwrite", "progress", "out_dir", "submitter", "notes")
"""The arguments that do not shape a run's numbers (a resume may change them)."""

CHECKPOINT_EVERY = 100_000
"""Steps between checkpoints of an SB3 run, besides those at its evaluations. Each one starts
new, seeded episodes (:mod:`ials_zoo.learners.sb3_state`): where checkpoints fall is part of the
run, so they keep to steps, never to wall-clock."""


STATS = {"policy_loss": "train/policy_gradient_loss", "value_loss": "train/value_loss", "entropy": "train/entropy_loss",
         "clip_fraction": "train/clip_fraction", "approx_kl": "train/approx_kl", "learning_rate": "train/learning_rate"}
"""``progress.csv``'s columns (:class:`~ials_zoo.baselines.multiagent.TrainingLog`) from SB3's
logged keys (SB3 logs the entropy's negative as a loss)."""


class SB3Learner:
    """The driver's adapter for one SB3 PPO, on the vec env ``make_env(training)`` returns with
    the AIP seconds this run is charged, ``(venv, seconds)`` (it fills ``training["simulator"]``
    and ``training["aip"]``). Its checkpoint is exact (:mod:`ials_zoo.learners.sb3_state`):
    every checkpoint starts new episodes seeded by the run's seed and step count, and a resumed
    run starts the same ones. Its ``progress.csv`` rows give SB3's mean return over its last 100
    episodes (the batched learners: the stretch's episodes)."""

    def __init__(self, make_env, args, hidden: list[int], agents: list, frame_stack: int, total: int,
                 training: dict):
        self.make_env, self.args, self.hidden = make_env, args, hidden
        self.agents, self.frame_stack, self.total, self.training = list(agents), int(frame_stack), total, training
        self.seed = int(args.seed)
        self.charged_seconds = 0.0
        self.model = self._state = self._venv = None
        self._log = []

    @property
    def simulator(self) -> str:
        return self.training["simulator"]

    @property
    def reports_aip_time(self) -> bool:  # an AIP made by this run is on its clock
        return self.charged_seconds > 0

    def load(self, state, info):
        self._venv, charged = self.make_env(self.training)  # closed by close() even if PPO fails to build
        self.model = make_ppo(self._venv, self.args, self.hidden, self.total)
        self.model.set_logger(Logger(None, [_recorder(self._log)]))
        if state is None:
            self.charged_seconds = float(charged)
            return
        if "models" not in state or "streams" not in state:
            raise BadInput("this checkpoint was written by an earlier version of ials_zoo, without the state an exact "
                           "resume needs; start the run again with --overwrite")
        self._state = state  # put back at the start, right before training
        # what the first run was charged and recorded (its AIP is cached by now)
        self.charged_seconds = float(info["aip_seconds"])
        self.training.update(simulator=info["simulator"], aip=info["aip"])

    def start(self, steps):
        if self._state is not None:
            resume_models({"policy": self.model}, {"policy": self.seed}, steps, self._state)
            self._state = None

    def policy(self, metadata):
        return policy_of(self.model, self.agents, self.frame_stack, metadata)

    def next_stop(self, steps):
        return None

    def before_training(self, steps, total, policy, note):
        pass

    def train(self, steps, target, advance):

        class Advance(BaseCallback):
            def _on_step(self):
                return True

            def _on_rollout_end(self):
                advance(self.model.n_steps * self.model.env.num_envs)

        model = self.model
        self._log.clear()
        model.learn(target - model.num_timesteps, callback=Advance(), reset_num_timesteps=False)
        model.logger.dump(model.num_timesteps)  # the last update's losses (SB3 logs them with the next rollout)
        row = {}
        for column, key in STATS.items():
            values = [d[key] for d in self._log if key in d]
            if values:
                row[column] = float(np.mean(values)) * (-1.0 if column == "entropy" else 1.0)
        returns = [d["rollout/ep_rew_mean"] for d in self._log if "rollout/ep_rew_mean" in d]
        row["mean_episode_return"] = float(returns[-1]) if returns else None
        return row

    def checkpoint(self, out):
        return (checkpoint_models({"policy": self.model}, {"policy": self.seed}, self.model.num_timesteps),
                {"aip_seconds": self.charged_seconds, "aip": self.training["aip"], "simulator": self.simulator})

    def close(self):
        if self._venv is not None:
            self._venv.close()
        self.model = self._venv = None


def _recorder(rows: list):
    """An SB3 logger output that appends each dump (a dict) to ``rows``."""

    class Recorder(KVWriter):
        def write(self, key_values, key_excluded, step=0):
            rows.append(dict(key_values))

        def close(self):
            pass

    return Recorder()


class SingleAgentScoring:
    """Scores the policy with the single-agent protocol (:func:`ials_zoo.evaluation.evaluate`:
    the policy controls one agent of the GS, the others scripted) for each of ``agents``; the
    learning curve follows the first. ``result_name(agent)``: the result file of an agent;
    ``deterministic_result``: also score the first agent with its most likely actions into this
    file (None: not). SUMO GSs are scored in a worker process (one simulation per process)."""

    def __init__(self, plan, agents: list, trained_agents: list, deterministic: bool, in_subprocess: bool,
                 result_name, deterministic_result: str | None = DETERMINISTIC_RESULT):
        self.plan, self.agents, self.trained_agents = plan, list(agents), list(trained_agents)
        self.result_name, self.deterministic_result = result_name, deterministic_result
        self.evaluators = {a: Evaluator(plan.env_id, a, plan.eval_episodes, deterministic, in_subprocess, plan.options)
                           for a in self.agents}
        self.deterministic_evaluator = None if deterministic_result is None else Evaluator(
            plan.env_id, self.agents[0], plan.eval_episodes, True, in_subprocess, plan.options)
        self.curve_header = {"agent": self.agents[0]}
        self.subject = f"of {self.agents[0]}"
        self.results = {}

    def curve(self, policy):
        return self.evaluators[self.agents[0]](policy)

    def final(self, path, training, curve):
        p = self.plan
        scored = [(a, self.evaluators[a], self.result_name(a)) for a in self.agents]
        if self.deterministic_result is not None:
            scored.append((self.agents[0], self.deterministic_evaluator, self.deterministic_result))
        for agent, evaluator, name in scored:
            ev = evaluator(load_model(path), p.final_eval_episodes, progress=p.progress)
            ev.policy_file = "policy.safetensors"  # relative to the run folder (where results live)
            curves = [{"seed": p.seed, "points": curve}] if agent == self.agents[0] else []
            self.results[name] = make_result([ev], algorithm=p.algorithm, training=training, training_seeds=[p.seed],
                                             learning_curves=curves, trained_agents=self.trained_agents,
                                             submitter=p.submitter, notes=p.notes)
            write_result(p.out / name, self.results[name])
        first = self.results[self.result_name(self.agents[0])]
        return first, self.results.get(self.deterministic_result)

    def close(self, kill: bool = False):
        for evaluator in [*self.evaluators.values(), self.deterministic_evaluator]:
            if evaluator is not None:
                evaluator.close(kill=kill)
