"""Where the multi-agent IALS of a city parts from the GS: one joint policy's GS episode, then
the same actions on the IALS, fed (a) the GS's own influence sources, (b) the AIPs.

For every light it reports the episode return (RESCO's ``wait_norm``, summed over the
episode's decisions) on:

* ``gs``: the GS, the joint policy acting (its actions and every light's influence sources
  recorded);
* ``recorded``: the multi-agent IALS, every light taking the GS's actions, every region fed the
  sources the GS recorded for it (:class:`~ials_zoo.influence.constant.RecordedPredictor`).
  This is the local simulators alone: what they miss here, no AIP can give back;
* ``aips``: the same actions on the IALS with the given AIP set (open loop: the policy does not
  react to the IALS);
* ``closed``: the policy acting on the IALS with the AIPs (what DIALS trains on).

    python studies/ials_real_maps/open_loop.py --net ingolstadt21 \\
        --policy runs/dials_net/ingolstadt21_s0/policy.safetensors \\
        --aips runs/dials_net/ingolstadt21_s0/aips.pt --episodes 2 --out runs/open_loop/dials.json

``--policy random`` draws each light's green uniformly; ``constant`` holds every light on its
first green (queues grow on every other road and spill back). Results go to ``--out`` as JSON after every episode (a rerun skips the
episodes done).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np


def _actor(policy_path: str, env, seed: int, deterministic: bool):
    """``act(observations) -> {agent: action}`` of a policy file (observations zero-padded), or
    of ``random`` (each light's greens uniformly)."""
    from ials_zoo.core.spaces import stack_observations
    from ials_zoo.policy import load_policy_file

    agents = list(env.possible_agents)
    rng = np.random.default_rng(seed)
    if policy_path == "random":
        sizes = {a: int(env.action_space(a).n) for a in agents}
        return lambda obs: {a: int(rng.integers(sizes[a])) for a in agents}
    if policy_path == "constant":
        return lambda obs: {a: 0 for a in agents}
    net = load_policy_file(policy_path).subset(agents)

    def act(obs: dict) -> dict:
        x = stack_observations(obs, agents, net.input_size)
        return {a: int(u) for a, u in zip(agents, net.act(x, rng, deterministic=deterministic))}

    return act


def _run(env, act, seed: int, forced: list | None = None) -> dict:
    """One episode: per agent the actions, influence sources and rewards. ``forced``: the
    actions to take, step by step (open loop), else ``act``'s."""
    obs, infos = env.reset(seed=seed)
    out = {a: {"actions": [], "influence": [], "rewards": []} for a in env.possible_agents}
    t = 0
    while env.agents:
        actions = forced[t] if forced is not None else act(obs)
        obs, rewards, _, _, infos = env.step(actions)
        for a, r in rewards.items():
            out[a]["actions"].append(int(actions[a]))
            out[a]["rewards"].append(float(r))
            if "influence" in infos.get(a, {}):
                out[a]["influence"].append(np.asarray(infos[a]["influence"]).tolist())
        t += 1
    return out


def _gs_episode(net: str, policy: str, seed: int, deterministic: bool, max_cycles: int | None) -> dict:
    import ials_zoo.sumo_net_v0 as sumo_net

    env = sumo_net.parallel_env(net=net, region_data=True, max_cycles=max_cycles)
    try:
        return _run(env, _actor(policy, env, seed, deterministic), seed)
    finally:
        env.close()


def _ials_returns(ials, episode: dict, aips, policy: str, seed: int, deterministic: bool, kinds) -> dict:
    """Per kind (recorded, aips, closed), per agent: the IALS's episode return."""
    from ials_zoo.influence.constant import RecordedPredictor

    agents = list(ials.possible_agents)
    steps = len(episode[agents[0]]["actions"])
    forced = [{a: episode[a]["actions"][t] for a in agents} for t in range(steps)]
    recorded = {a: RecordedPredictor(ials.predictors[a].region, episode[a]["influence"])
                for a in agents}
    out = {}
    for kind, predictors, actions in (("recorded", recorded, forced), ("aips", aips, forced),
                                      ("closed", aips, None)):
        if kind not in kinds:
            continue
        ials.set_predictors(predictors)
        act = None if actions is not None else _actor(policy, ials, seed, deterministic)
        run = _run(ials, act, seed, actions)
        out[kind] = {a: float(np.sum(run[a]["rewards"])) for a in agents}
    return out


def _exit_histogram(ials, episode: dict) -> list[int]:
    """Over every light's exits and decisions of the GS episode: how many decisions had 0, 1, ...
    of their seconds blocked (whether a block lasts the decision or flickers; exits drawn per
    second, commit 89aae0a), or, with one exit source per decision, how many were free and
    blocked."""
    counts = None
    for a, x in episode.items():
        names = ials.predictors[a].region.influence_names
        if any(n.startswith("exit:") and "@" not in n for n in names):  # one source per exit and decision
            is_exit = np.array([n.startswith("exit:") for n in names])
            h = np.bincount(np.asarray(x["influence"])[:, is_exit].reshape(-1), minlength=2)
            counts = h if counts is None else counts + h
            continue
        seconds = 1 + max(int(n.rpartition("@")[2]) for n in names)
        is_exit = np.array([n.startswith("exit:") for n in names]).reshape(seconds, -1)[0]
        u = np.asarray(x["influence"]).reshape(len(x["influence"]), seconds, -1)[:, :, is_exit]
        h = np.bincount(u.sum(axis=1).reshape(-1), minlength=seconds + 1)
        counts = h if counts is None else counts + h
    return counts.tolist()


def _table(results: list[dict]) -> str:
    agents = list(results[0]["gs"])
    kinds = [k for k in ("gs", "recorded", "aips", "closed") if k in results[0]]
    rows = ["| light | " + " | ".join(kinds) + " |", "|---" * (len(kinds) + 1) + "|"]
    for a in agents + ["all"]:
        cells = []
        for k in kinds:
            v = [sum(r[k].values()) if a == "all" else r[k][a] for r in results]
            cells.append(f"{np.mean(v):.2f}")
        rows.append(f"| {a} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--policy", required=True, help="a joint policy file (every light), random or constant")
    parser.add_argument("--aips", required=True, help="an AIP set file (ials-zoo train-aip --agent all, or DIALS's), or a spec (untrained, uniform)")
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--max-cycles", type=int, default=None, help="decisions per episode (default: the map's hour)")
    parser.add_argument("--deterministic", action="store_true")
    parser.add_argument("--kinds", default="recorded,aips,closed", help="which IALS runs, comma-separated")
    parser.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    for flag, path in (("--policy", args.policy), ("--aips", args.aips)):
        if not Path(path).is_file() and path not in ("random", "constant", "untrained", "uniform"):
            raise SystemExit(f"{flag}: no file {path!r}")
    kinds = args.kinds.split(",")
    if not set(kinds) <= {"recorded", "aips", "closed"}:
        raise SystemExit(f"--kinds: only recorded, aips and closed, got {args.kinds!r}")
    if args.episodes < 1:
        raise SystemExit(f"--episodes must be >= 1, got {args.episodes}")
    out = Path(args.out)
    results = json.loads(out.read_text())["episodes"] if out.is_file() else []
    from ials_zoo.sumo_net.ials_env import IALSNetEnv

    ials = IALSNetEnv(net=args.net, predictors=args.aips, max_cycles=args.max_cycles)
    try:
        for e in range(len(results), args.episodes):
            start, seed = time.perf_counter(), args.seed + e
            episode = _gs_episode(args.net, args.policy, seed, args.deterministic, args.max_cycles)
            row = {"seed": seed, "gs": {a: float(np.sum(x["rewards"])) for a, x in episode.items()},
                   "exit_blocked_seconds": _exit_histogram(ials, episode)}
            row.update(_ials_returns(ials, episode, args.aips, args.policy, seed, args.deterministic, kinds))
            results.append(row)
            out.parent.mkdir(parents=True, exist_ok=True)
            tmp = out.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps({"argv": sys.argv[1:], "episodes": results}, indent=1))
            os.replace(tmp, out)
            print(f"episode {e + 1}/{args.episodes} in {time.perf_counter() - start:.0f} s", flush=True)
    finally:
        ials.close()
    print(_table(results))
    if "exit_blocked_seconds" in results[0]:
        print("exit-decisions by blocked seconds (0..10), or free / blocked:", np.sum([r["exit_blocked_seconds"] for r in results],
                                                                       axis=0).tolist())


if __name__ == "__main__":
    main()
