"""Where a map's jams start: per light, over the protocol's episodes, how often its reward sits
at ``wait_norm``'s clip (-4: 896 s of waiting or more among its detected vehicles) and from
which decision, under a policy file or one of the domain's rules.

    python studies/resco_maps/jams.py --net ingolstadt21 --policy rule:greedy --out results/jams/greedy.json
    python studies/resco_maps/jams.py --net ingolstadt21 --policy runs/idqn_net/ingolstadt21_s0/policy.safetensors
    python studies/resco_maps/jams.py --net ingolstadt21 --policy POLICY --rule-at 243641585,gneJ257 --out F

``--rule-at LIGHTS``: those lights follow ``--rule`` (greedy) and the others the policy: whether
a jam is those lights' making. ``--hold K``: a light keeps a green at least K decisions before it
follows a different action (a minimum green of K decisions laid over the policy): whether a jam is
the switching's making (each change costs a yellow). ``--max-hold M``: a learned light that held
one green M decisions changes to its likeliest other (a maximum green): whether a jam is a
starved approach's making.

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


def episode(env, policy, agents, width, seed: int, rule=None, rule_at=(), limits=(1, 0)) -> dict:
    """One episode's per light: clipped share, first clipped decision, return, the longest run of
    one action (decisions) and the share of decisions that change it, and for a learned policy the
    mean entropy of its action distribution (nats); and the episode's delay."""
    obs, _ = env.reset(seed=seed)
    policy.reset(seed)
    act = policy.joint_actor(env, agents) if isinstance(policy, RulePolicy) else None
    ruled = rule.joint_actor(env, agents) if rule_at else None
    at = [agents.index(a) for a in rule_at]
    rewards, actions, entropies = [], [], []
    held, p = GreenLimits(len(agents), *limits), None
    while env.agents:
        if act is not None:
            acts = act()
        else:
            x = stack_observations(obs, agents, width)
            p = policy.net.probs(x)
            entropies.append(-(p * np.log(np.where(p > 0, p, 1.0))).sum(-1))
            acts = policy.act_all(x)
        if ruled is not None:
            acts = np.array(acts)
            acts[at] = ruled()[at]
        acts = held(acts, p)
        obs, r, *_ = env.step({a: int(u) for a, u in zip(agents, acts)})
        rewards.append([r[a] for a in agents])
        actions.append([int(u) for u in acts])
    r, u = np.asarray(rewards), np.asarray(actions)
    clipped = r <= CLIP
    first = [int(np.argmax(c)) if c.any() else None for c in clipped.T]
    ent = np.asarray(entropies).mean(0) if entropies else [None] * len(agents)
    return {"seed": seed, "delay": env.episode_metrics()["delay"],
            "lights": {a: {"clipped": float(clipped[:, i].mean()), "first": first[i], "return": float(r[:, i].sum()),
                           "longest_hold": longest_run(u[:, i]), "switches": float((np.diff(u[:, i]) != 0).mean()),
                           "entropy": None if ent[i] is None else float(ent[i])}
                       for i, a in enumerate(agents)}}


class GreenLimits:
    """Each light's action changes only after its current one was held ``hold`` decisions
    (``hold=1``: every action passes unchanged); with ``max_hold``, a light that held one green
    that many decisions changes to its policy's likeliest other green (a maximum green)."""

    def __init__(self, n: int, hold: int = 1, max_hold: int = 0):
        self.hold, self.max_hold, self.current, self.age = hold, max_hold, None, np.zeros(n, np.int64)

    def __call__(self, acts, probs=None) -> np.ndarray:
        acts = np.asarray(acts, np.int64).copy()
        if self.current is None:
            self.age[:], self.current = 1, acts
            return acts
        locked = self.age < self.hold
        acts[locked] = self.current[locked]
        if self.max_hold:
            stale = (self.age >= self.max_hold) & (acts == self.current)
            others = np.array(probs, np.float64)
            others[np.arange(len(acts)), self.current] = -1.0
            acts[stale] = others.argmax(1)[stale]
        self.age = np.where(acts == self.current, self.age + 1, 1)
        self.current = acts
        return acts


def longest_run(actions: np.ndarray) -> int:
    """The most decisions in a row with one action."""
    change = np.flatnonzero(np.diff(actions) != 0)
    bounds = np.concatenate([[-1], change, [len(actions) - 1]])
    return int(np.diff(bounds).max())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--net", required=True)
    p.add_argument("--policy", required=True, help="rule:NAME or a policy file")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--rule-at", default="", help="comma-separated lights that follow --rule instead of the policy")
    p.add_argument("--rule", default="greedy", help="the rule of --rule-at's lights")
    p.add_argument("--hold", type=int, default=1, help="the decisions a light keeps a green before it may change")
    p.add_argument("--max-hold", type=int, default=0,
                   help="the most decisions a light keeps one green (then its policy's likeliest other); 0: no limit")
    p.add_argument("--out", required=True)
    args = p.parse_args(argv)
    if args.hold < 1:
        p.error(f"--hold must be at least 1 (decisions), got {args.hold}")
    if args.max_hold and (args.max_hold < args.hold or args.policy.startswith("rule:")):
        p.error("--max-hold needs a learned policy (its likeliest other green) and at least --hold decisions")
    policy = load_policy(args.policy, "sumo_net_v0")
    options = dict(policy.metadata.get("env_options", {"net": args.net})) if policy.kind == "model" else {"net": args.net}
    if policy.kind == "rule":
        options.update(policy.rule.env_options)
    done = json.load(open(args.out)) if os.path.exists(args.out) else {"policy": args.policy, "episodes": []}
    env = SumoNetEnv(**options)
    agents = list(env.possible_agents)
    width = sizes_of_env(env, agents).obs_size
    rule_at = [a for a in args.rule_at.split(",") if a]
    unknown = sorted(set(rule_at) - set(agents))
    if unknown:
        p.error(f"--rule-at: no such light {unknown[0]!r}; the lights: {', '.join(agents)}")
    rule = load_policy(f"rule:{args.rule}", "sumo_net_v0") if rule_at else None
    done.setdefault("rule_at", {"lights": rule_at, "rule": args.rule} if rule_at else None)
    done.setdefault("hold", args.hold)
    done.setdefault("max_hold", args.max_hold)
    try:
        for seed in eval_seeds(args.episodes)[len(done["episodes"]):]:
            start = time.perf_counter()
            done["episodes"].append(episode(env, policy, agents, width, seed, rule, rule_at, (args.hold, args.max_hold)))
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
    the median first clipped decision, and how it switches (where recorded)."""
    eps = done["episodes"]
    print(f"{done['policy']}: delay mean {np.mean([e['delay'] for e in eps]):.1f}, median "
          f"{np.median([e['delay'] for e in eps]):.1f} over {len(eps)} episodes")
    for a in eps[0]["lights"]:
        share = [e["lights"][a]["clipped"] for e in eps]
        firsts = [e["lights"][a]["first"] for e in eps if e["lights"][a]["first"] is not None]
        print(f"  {a[:30]:30s} clipped {np.mean(share):.2f} of decisions; over half in {sum(s > 0.5 for s in share)} "
              f"of {len(eps)} episodes; first clip at decision {np.median(firsts) if firsts else '-'} (median)"
              + _switching(eps, a))


def _switching(eps: list, a: str) -> str:
    lights = [e["lights"][a] for e in eps if "longest_hold" in e["lights"][a]]
    if not lights:
        return ""
    ent = [x["entropy"] for x in lights if x["entropy"] is not None]
    return (f"; return {np.median([x['return'] for x in lights]):.0f}, longest hold "
            f"{np.median([x['longest_hold'] for x in lights]):.0f}, switches {np.mean([x['switches'] for x in lights]):.2f}"
            + (f", entropy {np.mean(ent):.2f}" if ent else "") + " (medians, means)")


if __name__ == "__main__":
    sys.exit(main())
