"""One stable-baselines3 PPO training run (``ppo_single``, ``ppo_shared``): the SB3 model and
its vec env, the periodic GS evaluation with its learning curve, checkpoints, the clock and
the final policy file.
"""

from __future__ import annotations

import json
import time

import numpy as np

from ials_zoo.baselines.runs import Clock, load_training_state, save_training_state
from ials_zoo.core.extras import study_of
from ials_zoo.evaluation import NetworkPolicy, _evaluate_worker, evaluate, load_model
from ials_zoo.influence.specs import GS
from ials_zoo.policy import PolicyNetwork, policy_from_sb3_model, save_policy
from ials_zoo.processes import shutdown_pool, spawn_pool
from ials_zoo.single_agent import box_space
from ials_zoo.utils import atomic_write_text


def as_float_box(venv):
    """Make sure the observations are a float32 ``Box`` (what VecFrameStack and the evaluator
    use); wraps ``venv`` only when needed."""
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import VecEnvWrapper


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
    """Rough training time from the domain's measured PPO throughput (``study_of(domain)``)."""

    rates = study_of(env_id).ppo_steps_per_second
    rate = rates.get("gs" if simulator == GS else "ials", 1000.0)
    return steps / max(rate, 1.0)


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
        # SB3 keeps its environments' episodes and torch's global generator out of our reach:
        # the run continues from its checkpoint but is not bitwise the uninterrupted one
        print("  resuming an SB3 run: it continues from its last checkpoint (not bitwise the run that was never "
              "stopped; the batched learners of ippo and dials are)", flush=True)
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
