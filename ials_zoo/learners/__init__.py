"""Learners for many agents at once: batched independent PPO and its rollouts.

* :mod:`~ials_zoo.learners.batched_ppo` -- :class:`BatchedPPO`, one torch program for every
  agent's own actor, critic and update;
* :mod:`~ials_zoo.learners.rollout` -- multi-agent vector envs (the IALS) and the rollout loop;
* :mod:`~ials_zoo.learners.gs_vec` -- copies of the GS with every agent learning (IPPO);
* :mod:`~ials_zoo.learners.sb3_state` -- the exact checkpoint of stable-baselines3 PPO models.
"""
