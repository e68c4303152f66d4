"""Every junction's IALS on a RESCO map: an AIP per junction trained on GS data, its cost
against the GS's, and its light's reward against the GS's under random lights.

1. One GS run of ``--episodes`` hours with every light acting at random records every
   junction's region data (:func:`ials_zoo.influence.dataset.collect_all`); each junction's AIP
   (an MLP, 150 epochs at lr 3e-3: 30 epochs left two hours of data above the data marginal's
   cross-entropy) is trained on its own data and saved as one AIP set, ``--out/aips.pt``.
2. The GS's cost per decision with one learner among scripted neighbours (the rest on their
   own programs; in this process, ``--gs-decisions`` decisions, twice), and every light's mean
   reward in one GS hour with every light random (seed 100).
3. Each junction's IALS (``make_ials``, its trained AIP, in this process) for one hour of random
   actions (seed 100): seconds per decision, its light's mean reward, and (a second pass) the
   vehicles entering its region per decision against the GS data's.

Results go to ``--out/results.json`` as they come (a rerun skips what is done; the GS data are
kept, so ``--aip ar3_clock`` trains the other variant on the same data); the table is printed at
the end. Usage: python studies/ials_real_maps/island.py --net ingolstadt21 [--episodes 2]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import ials_zoo
from ials_zoo.influence.dataset import InfluenceDataset, collect_all
from ials_zoo.influence.files import load_predictor_set, save_predictor_set
from ials_zoo.influence.train import train_predictor
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.island import entry_tables


def _save(path: Path, results: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(results, indent=1))
    os.replace(tmp, path)


VARIANTS = {  # AIP variant -> train_predictor's settings
    "mlp": {},
    # the grid's best (docs/fidelity.md): its own last 3 draws and a clock over the hour
    "ar3_clock": {"autoregressive": True, "influence_lags": 3, "clock_horizon": 360},
}


def gs_data(net: str, episodes: int, out: Path, results: dict) -> dict:
    """Every junction's region data from one GS run with every light at random, saved under ``out``."""
    lights = SumoNetEnv(net=net).possible_agents
    paths = {a: out / f"data_{k}.npz" for k, a in enumerate(lights)}
    if all(p.is_file() for p in paths.values()):
        return {a: InfluenceDataset.load(p, agent=a) for a, p in paths.items()}
    start = time.perf_counter()
    data = collect_all("sumo_net_v0", lights, steps=episodes * 360, seed=0, gs_options={"net": net}, progress=True)
    results["collect_seconds"] = time.perf_counter() - start
    for a, d in data.items():
        d.save(paths[a])
    return data


def train_aips(net: str, episodes: int, variant: str, out: Path, results: dict) -> dict:
    """Every junction's AIP of ``variant``, saved as one AIP set ``out/aips[_variant].pt`` (loaded if there)."""
    path = out / ("aips.pt" if variant == "mlp" else f"aips_{variant}.pt")
    if path.is_file():
        return load_predictor_set(path, "sumo_net_v0")
    aips = {}
    for a, d in gs_data(net, episodes, out, results).items():
        aips[a], report = train_predictor(d, arch="mlp", epochs=150, lr=3e-3, progress=False, **VARIANTS[variant])
        ce = report["cross_entropy"]
        results.setdefault("aips" if variant == "mlp" else f"aips_{variant}", {})[a] = {
            "gs_entries_per_decision": float(np.asarray(d.influences).sum() / d.n_steps),
            "test_ce": ce["trained"]["test"], "marginal_ce": ce["marginal"]["test"], "sources": d.region.n_sources}
    save_predictor_set(aips.values(), path, metadata={"net": net, "gs_hours": episodes, "policy": "uniform_random",
                                                      "variant": variant})
    return aips


def gs_figures(net: str, decisions: int, results: dict) -> None:
    """The GS's seconds per decision (one learner) and every light's mean reward (all random)."""
    if "gs_seconds_per_decision" in results:
        return
    env = SumoNetEnv(net=net, fresh_process=False, backend="auto", max_cycles=decisions,
                     learners=[SumoNetEnv(net=net).possible_agents[0]])
    times = []
    try:
        for seed in (100, 101):
            env.reset(seed=seed)
            start, n = time.perf_counter(), 0
            while env.agents:
                env.step({a: 0 for a in env.agents})
                n += 1
            times.append((time.perf_counter() - start) / n)
    finally:
        env.close()
    results["gs_seconds_per_decision"] = times
    env = SumoNetEnv(net=net, fresh_process=False, backend="auto")
    rng, rewards = np.random.default_rng(100), []
    try:
        env.reset(seed=100)
        while env.agents:
            _, r, *_ = env.step({a: int(rng.integers(env.action_space(a).n)) for a in env.agents})
            rewards.append(r)
    finally:
        env.close()
    results["gs_reward"] = {a: float(np.mean([r[a] for r in rewards])) for a in rewards[0]}


def ials_figures(net: str, light: str, predictor) -> dict:
    """One hour of the junction's IALS under random actions (timed as users run it), then the
    same hour again measuring what entered its region (a call per edge and second)."""
    out = {}
    for measure in (False, True):
        env = ials_zoo.make_ials("sumo_net_v0", light, predictor=predictor, seed=100, net=net,
                                 measure_entries=measure)
        rng, rewards, entered = np.random.default_rng(100), [], 0
        try:
            env.reset(seed=100)
            start, done = time.perf_counter(), False
            while not done:
                _, r, term, trunc, _ = env.step(int(rng.integers(env.action_space.n)))
                rewards.append(r)
                entered += int(env.ls.last_entries.sum()) if measure else 0
                done = term or trunc
            seconds = (time.perf_counter() - start) / len(rewards)
        finally:
            env.close()
        if measure:
            out["entries_per_decision"] = entered / len(rewards)
        else:
            out.update(seconds_per_decision=seconds, reward=float(np.mean(rewards)))
    return out


def report(results: dict, key: str = "ials") -> None:
    gs = float(np.median(results["gs_seconds_per_decision"]))
    print(f"GS: {1 / gs:.1f} decisions/s (one learner, in this process)")
    print(f"{'light':<28}{'IALS dec/s':>11}{'x GS':>7}{'reward GS':>11}{'IALS':>8}{'entries GS':>12}{'IALS':>7}")
    speedups = []
    for a, row in results.get(key, {}).items():
        aip = results["aips"][a]
        speedups.append(gs / row["seconds_per_decision"])
        print(f"{a[:27]:<28}{1 / row['seconds_per_decision']:>11.0f}{speedups[-1]:>7.1f}"
              f"{results['gs_reward'][a]:>11.3f}{row['reward']:>8.3f}"
              f"{aip['gs_entries_per_decision']:>12.2f}{row['entries_per_decision']:>7.2f}")
    if speedups:
        print(f"speed-up over the GS: median {np.median(speedups):.1f}x [{min(speedups):.1f}, {max(speedups):.1f}]")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--net", default="ingolstadt21")
    parser.add_argument("--episodes", type=int, default=2, help="GS hours of AIP data")
    parser.add_argument("--gs-decisions", type=int, default=120)
    parser.add_argument("--out", default=None, help="folder (default runs/sumo_net_island/<net>)")
    parser.add_argument("--aip", default="mlp", choices=sorted(VARIANTS), help="the AIP variant")
    args = parser.parse_args(argv)
    out = Path(args.out or f"runs/sumo_net_island/{args.net}")
    out.mkdir(parents=True, exist_ok=True)
    path = out / "results.json"
    results = json.loads(path.read_text()) if path.is_file() else {"net": args.net}
    aips = train_aips(args.net, args.episodes, args.aip, out, results)
    key = "ials" if args.aip == "mlp" else f"ials_{args.aip}"
    _save(path, results)
    entry_tables(SumoNetEnv(net=args.net).scenario, list(aips))  # one GS hour for every region's tables
    gs_figures(args.net, args.gs_decisions, results)
    _save(path, results)
    for light, pred in aips.items():
        if light not in results.setdefault(key, {}):
            results[key][light] = ials_figures(args.net, light, pred)
            _save(path, results)
            print(light, results[key][light], flush=True)
    report(results, key)


if __name__ == "__main__":
    main()
