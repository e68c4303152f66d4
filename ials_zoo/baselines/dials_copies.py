"""DIALS where the agents have spaces of their own (a real network's junctions).

Such a domain has no batched array IALS (:class:`~ials_zoo.core.multi.MultiAgentIALS` stacks
agents of one shape); it has a multi-agent IALS ParallelEnv instead (``Domain.ials_parallel_env``:
every agent's local simulator and AIP side by side in one simulation, the regions apart, each fed
only by its own AIP). DIALS then trains every agent's PPO, as IPPO does on the GS (the same
batched learner, observations zero-padded, missing actions masked; or, with ``--learner shared``,
shared PPO's one network for every light), on ``--n-envs`` copies of
that IALS spread over ``--workers`` worker processes (or Ray actors, ``--backend ray``), and retrains the AIPs at the refresh points
on GS data from the joint policy (:class:`~ials_zoo.baselines.aip_rounds.AIPRefreshes`). The work is
split by copies, not by agents: each worker steps every agent's region of its copies.
"""

from __future__ import annotations

from pathlib import Path

from ials_zoo.baselines.aip_rounds import AIPRefreshes, aip_training_of
from ials_zoo.baselines.ippo import GSCopiesLearner
from ials_zoo.baselines.multiagent import save_aips
from ials_zoo.dials.shard import PPO_CLASSES
from ials_zoo.learners.gs_vec import GSVecEnv


class IALSCopiesLearner(AIPRefreshes, GSCopiesLearner):
    """The driver's adapter for DIALS on a multi-agent IALS ParallelEnv (module docstring)."""

    reports_aip_time = True

    def __init__(self, args, domain, agents, options, refresh, copies, workers, ppo, frame_stack, updates, sizes,
                 training: dict, out: Path):
        super().__init__(args.env_id, agents, options, copies, min(workers, copies), ppo, frame_stack, args.seed,
                         updates, sizes, learner_cls=PPO_CLASSES[args.learner])
        self.args, self.domain, self.refresh, self.training, self.out = args, domain, refresh, training, out
        self.simulator = training["simulator"]
        self.aip_training = aip_training_of(args, domain)
        self.charged_seconds, self.refreshes, self.aip_split = 0.0, 0, {"collect": 0.0, "train": 0.0}
        self.aips = None

    def load(self, state, info):
        GSCopiesLearner.load(self, state, info)
        self.load_aips(state, info)

    def _make_env(self):
        return GSVecEnv(self.env_id, self.agents, self.copies, self.processes, seed=self.seed, simulator="ials",
                        predictor=self.aips, copies_on=self.args.backend, ray_address=self.args.ray_address,
                        **self.options, **({"local": self.args.local} if self.args.local != "sumo" else {}))

    def use_aips(self, aips: dict) -> None:
        self.env.set_predictors(aips)
        self.trainer.new_episodes()  # an episode runs on one set of AIPs throughout (and replays on it)

    def train(self, steps, target, advance):
        stats = GSCopiesLearner.train(self, steps, target, advance)
        return dict(stats, aip_refreshes=self.refreshes)

    def checkpoint(self, out):
        save_aips(out / "aips.pt", self.aips)
        state, _ = GSCopiesLearner.checkpoint(self, out)
        return state, self.aip_info()


__all__ = ["IALSCopiesLearner"]
