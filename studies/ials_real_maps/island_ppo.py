"""A light of a RESCO map trained with PPO on its IALS alone, then scored on the GS.

1. AIP data: ``--collect`` decisions of the GS with the light acting at random and every other
   light on its own program (the neighbours the policy will meet); its AIP (MLP, 150 epochs at
   lr 3e-3) is trained on them.
2. PPO (stable-baselines3, 4 IALS copies in one SUMO simulation, ``--steps`` decisions) on the
   light's IALS; the wall-clock is recorded.
3. On the GS (the light learning, every other light on its own program), ``--episodes`` hours
   (seeds 1000, 1001, ...) of: the PPO policy (deterministic), the light on its own program
   (fixed time) and random greens; the light's mean reward (RESCO's ``wait_norm``) per decision.
   The PPO policy's mean reward on its IALS is printed beside them.

Results go to ``--out/results.json`` stage by stage (a rerun skips what is done).
Usage: python studies/ials_real_maps/island_ppo.py --net ingolstadt21 --light 243641585 [--steps 100000]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import ials_zoo
from ials_zoo.influence.dataset import collect
from ials_zoo.influence.files import load_predictor, save_predictor
from ials_zoo.influence.ials import make_ials_vec_env
from ials_zoo.influence.train import train_predictor
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.mdp import wait_norm


def _save(path: Path, results: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(results, indent=1))
    os.replace(tmp, path)


def aip(args, out: Path, results: dict):
    path = out / "aip.pt"
    if path.is_file():
        return load_predictor(path, agent=args.light)
    start = time.perf_counter()
    data = collect("sumo_net_v0", args.light, steps=args.collect, seed=0, gs_options={"net": args.net})
    pred, report = train_predictor(data, arch="mlp", epochs=150, lr=3e-3, progress=False)
    results["aip"] = {"seconds": time.perf_counter() - start, "test_ce": report["cross_entropy"]["trained"]["test"],
                      "marginal_ce": report["cross_entropy"]["marginal"]["test"]}
    save_predictor(pred, path)
    return pred


def train_ppo(args, pred, out: Path, results: dict):
    from stable_baselines3 import PPO

    path = out / "ppo.zip"
    if path.is_file():
        return PPO.load(path, device="cpu")
    env = make_ials_vec_env("sumo_net_v0", args.light, n_envs=4, predictor=pred, seed=0, net=args.net)
    try:
        model = PPO("MlpPolicy", env, n_steps=512, batch_size=256, learning_rate=1e-3, gamma=0.95, ent_coef=0.01,
                    seed=0, device="cpu", verbose=0)
        start = time.perf_counter()
        model.learn(total_timesteps=args.steps, progress_bar=False)
        results["ppo"] = {"steps": args.steps, "seconds": time.perf_counter() - start}
    finally:
        env.close()
    model.save(path)
    return model


def gs_reward(args, choose, seed: int) -> float:
    """The light's mean reward over one GS hour; ``choose(env, obs)`` gives its green, or None:
    the light runs its own program."""
    env = SumoNetEnv(net=args.net, learners=[] if choose is None else [args.light])
    rewards = []
    try:
        obs, _ = env.reset(seed=seed)
        if choose is None:  # every decision's measures, as a learner's rewards
            env.run_uncontrolled(on_decision=lambda e: rewards.append(wait_norm(e._light_measures(args.light), 0)))
        while env.agents:
            obs, r, *_ = env.step({args.light: choose(env, obs[args.light])})
            rewards.append(r[args.light])
    finally:
        env.close()
    return float(np.mean(rewards))


def ials_reward(args, model, pred) -> float:
    env = ials_zoo.make_ials("sumo_net_v0", args.light, predictor=pred, seed=1000, net=args.net)
    rewards, done = [], False
    try:
        obs, _ = env.reset(seed=1000)
        while not done:
            obs, r, term, trunc, _ = env.step(int(model.predict(obs, deterministic=True)[0]))
            rewards.append(r)
            done = term or trunc
    finally:
        env.close()
    return float(np.mean(rewards))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--light", default="243641585")
    parser.add_argument("--collect", type=int, default=720)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--episodes", type=int, default=2)
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    out = Path(args.out or f"runs/sumo_net_island_ppo/{args.net}_{args.light}")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.json"
    results = json.loads(path.read_text()) if path.is_file() else {"net": args.net, "light": args.light}
    pred = aip(args, out, results)
    _save(path, results)
    model = train_ppo(args, pred, out, results)
    _save(path, results)
    rng = np.random.default_rng(0)
    policies = {"ppo_on_ials": lambda env, obs: int(model.predict(obs, deterministic=True)[0]),
                "own_program": None,
                "random": lambda env, obs: int(rng.integers(env.action_space(args.light).n))}
    gs = results.setdefault("gs", {})
    for name, choose in policies.items():
        for seed in range(1000, 1000 + args.episodes):
            if str(seed) not in gs.setdefault(name, {}):
                gs[name][str(seed)] = gs_reward(args, choose, seed)
                _save(path, results)
                print(name, seed, gs[name][str(seed)], flush=True)
    results["ials_ppo_reward"] = ials_reward(args, model, pred)
    _save(path, results)
    print(json.dumps({k: results[k] for k in ("aip", "ppo", "ials_ppo_reward") if k in results}, indent=1))
    for name, by_seed in gs.items():
        print(f"GS {name}: mean reward {np.mean(list(by_seed.values())):.3f} over {len(by_seed)} hours")


if __name__ == "__main__":
    main()
