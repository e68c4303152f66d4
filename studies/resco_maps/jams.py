"""Where a map's jams start: per light, over the protocol's episodes, how often its reward sits
at ``wait_norm``'s clip (-4: 896 s of waiting or more among its detected vehicles) and from
which decision, under a policy file or one of the domain's rules.

    python studies/resco_maps/jams.py --net ingolstadt21 --policy rule:greedy --out results/jams/greedy.json
    python studies/resco_maps/jams.py --net ingolstadt21 --policy runs/idqn_net/ingolstadt21_s0/policy.safetensors

A light whose reward is clipped sees no difference between a long queue and a longer one: its
learner gets no signal there. Resumable: each episode is stored in the output as it ends.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from ials_zoo.core.spaces import sizes_of_env, stack_observations
from ials_zoo.evaluation import RulePolicy, eval_seeds, load_policy
from ials_zoo.sumo_net.env import SumoNetEnv

CLIP = -4.0  # wait_norm's lower clip


def episode(env, policy, agents, width, seed: int) -> dict:
    """One episode's per-light clipped share, first clipped decision and return, and its delay."""
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    act = policy.joint_actor(env, agents) if isinstance(policy, RulePolicy) else None
    rewards = []
    while env.agents:
        acts = act() if act is not None else policy.act_all(stack_observations(obs, agents, width))
        obs, r, *_ = env.step({a: int(u) for a, u in zip(agents, acts)})
        rewards.append([r[a] for a in agents])
    r = np.asarray(rewards)
    clipped = r <= CLIP
    first = [int(np.argmax(c)) if c.any() else None for c in clipped.T]
    return {"seed": seed, "delay": env.episode_metrics()["delay"],
            "lights": {a: {"clipped": float(clipped[:, i].mean()), "first": first[i], "return": float(r[:, i].sum())}
                       for i, a in enumerate(agents)}}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--net", required=True)
    p.add_argument("--policy", required=True, help="rule:NAME or a policy file")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    policy = load_policy(args.policy, "sumo_net_v0")
    options = dict(policy.metadata.get("env_options", {"net": args.net})) if policy.kind == "model" else {"net": args.net}
    if policy.kind == "rule":
        options.update(policy.rule.env_options)
    done = json.load(open(args.out)) if os.path.exists(args.out) else {"policy": args.policy, "episodes": []}
    env = SumoNetEnv(**options)
    agents = list(env.possible_agents)
    width = sizes_of_env(env, agents).obs_size
    try:
        for seed in eval_seeds(args.episodes)[len(done["episodes"]):]:
            start = time.perf_counter()
            done["episodes"].append(episode(env, policy, agents, width, seed))
            with open(args.out + ".tmp", "w") as f:
                json.dump(done, f)
            os.replace(args.out + ".tmp", args.out)
            print(f"seed {seed}: delay {done['episodes'][-1]['delay']:.1f} ({time.perf_counter() - start:.0f} s)",
                  flush=True)
    finally:
        env.close()
    report(done)
    return 0


def report(done: dict) -> None:
    """Per light: the mean clipped share, the episodes where it is clipped over half the time,
    and the median first clipped decision."""
    eps = done["episodes"]
    print(f"{done['policy']}: delay mean {np.mean([e['delay'] for e in eps]):.1f}, median "
          f"{np.median([e['delay'] for e in eps]):.1f} over {len(eps)} episodes")
    for a in eps[0]["lights"]:
        share = [e["lights"][a]["clipped"] for e in eps]
        firsts = [e["lights"][a]["first"] for e in eps if e["lights"][a]["first"] is not None]
        if max(share) < 0.05:
            continue
        print(f"  {a[:30]:30s} clipped {np.mean(share):.2f} of decisions; over half in {sum(s > 0.5 for s in share)} "
              f"of {len(eps)} episodes; first clip at decision {np.median(firsts) if firsts else '-'} (median)")


if __name__ == "__main__":
    sys.exit(main())
