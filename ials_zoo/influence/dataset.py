"""Algorithm 1 of the paper: collect ``(d_t, u_t)`` pairs of one agent from its global simulator.

:func:`collect` runs the domain's GS with one learning agent (driven by an exploratory policy,
uniform random by default) and every other agent scripted, and records, per step, the d-sets
``d_t`` of both kinds and the influence sources ``u_t`` following the infos contract of
``ials_zoo.core.region``: ``d_t`` comes from the previous ``reset``/``step`` call and ``u_t``
from the step that follows it.

All episodes of the zoo have the same fixed length ``T``, so the data set keeps episode
boundaries by shape:

* ``dsets["dset"]``: uint8 ``[E, T, D_dset]``; ``dsets["full"]``: uint8 ``[E, T, D_full]``;
* ``influences``: int64 ``[E, T, M]``;

where ``E`` is the number of episodes; ``steps`` is rounded *up* to whole episodes
(``E = ceil(steps / T)``), since the recurrent AIP trains on whole episodes.

File format (``.npz``, written atomically): arrays ``dset``, ``full``, ``influences`` and
``metadata`` (a 0-d string array holding JSON: format tag and version, region spec, env_id,
agent, gs_options, steps, episodes, episode_length, seed, policy name, package version,
collection wall-clock seconds, creation time).
"""

from __future__ import annotations

import json
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ials_zoo.core.region import DSET_KINDS, INFLUENCE_KEY, RegionSpec, dset_key
from ials_zoo.influence.predictors import _readable

FORMAT = "ials_zoo.influence_dataset"
FORMAT_VERSION = 1


@dataclass
class InfluenceDataset:
    """``(d_t, u_t)`` pairs of one agent, by episode (see the module docstring for shapes)."""

    region: RegionSpec
    dsets: dict[str, np.ndarray]
    influences: np.ndarray
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        u = np.asarray(self.influences)
        if u.ndim != 3 or u.shape[2] != self.region.n_sources:
            raise ValueError(
                f"influences must have shape [episodes, T, {self.region.n_sources}], got {u.shape}"
            )
        self.influences = u.astype(np.int64, copy=False)
        if set(self.dsets) != set(DSET_KINDS):
            raise ValueError(f"dsets must hold exactly the kinds {DSET_KINDS}, got {sorted(self.dsets)}")
        for kind in DSET_KINDS:
            d = np.asarray(self.dsets[kind])
            want = (u.shape[0], u.shape[1], self.region.dset_size(kind))
            if d.shape != want:
                raise ValueError(f"d-set {kind!r} has shape {d.shape}, expected {want}")
            self.dsets[kind] = d.astype(np.uint8, copy=False)
        classes = np.asarray(self.region.influence_classes)
        if u.size and ((u < 0).any() or (u >= classes).any()):
            raise ValueError(f"influence values out of range for classes {tuple(classes)}")

    @property
    def n_episodes(self) -> int:
        return int(self.influences.shape[0])

    @property
    def episode_length(self) -> int:
        return int(self.influences.shape[1])

    @property
    def n_steps(self) -> int:
        return self.n_episodes * self.episode_length

    def subset(self, episodes) -> "InfluenceDataset":
        """The episodes ``episodes`` (index array or slice) as a new data set."""
        return InfluenceDataset(
            self.region,
            {k: v[episodes] for k, v in self.dsets.items()},
            self.influences[episodes],
            dict(self.metadata),
        )

    def split(self, test_fraction: float = 0.1, seed: int = 0):
        """Random split *by episode* into (train, test) index arrays (at least 1 test episode
        when there are >= 2 episodes)."""
        if not 0.0 <= test_fraction < 1.0:
            raise ValueError(f"test_fraction must be in [0, 1), got {test_fraction}")
        E = self.n_episodes
        perm = np.random.default_rng(seed).permutation(E)
        n_test = int(round(E * test_fraction))
        if test_fraction > 0 and E >= 2:
            n_test = max(1, n_test)
        return np.sort(perm[n_test:]), np.sort(perm[:n_test])

    # -- files -----------------------------------------------------------------------------
    def save(self, path) -> Path:
        """Write the data set to ``path`` (``.npz``), atomically."""
        from ials_zoo.utils import atomic_path

        meta = dict(self.metadata)
        meta.update(
            {
                "format": FORMAT,
                "format_version": FORMAT_VERSION,
                "region": self.region.to_dict(),
                "episodes": self.n_episodes,
                "episode_length": self.episode_length,
            }
        )
        path = Path(path)
        with atomic_path(path, suffix=".npz") as tmp:
            # An open file object stops numpy from appending another ".npz".
            with open(tmp, "wb") as f:
                np.savez_compressed(
                    f,
                    dset=self.dsets["dset"],
                    full=self.dsets["full"],
                    influences=self.influences,
                    metadata=np.array(json.dumps(meta, sort_keys=True)),
                )
            _readable(tmp)
        return path

    @classmethod
    def load(cls, path, env_id: str | None = None, agent: str | None = None) -> "InfluenceDataset":
        """Read a data set written by :meth:`save`; ``env_id``/``agent`` are checked if given."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"influence data set not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in ("dset", "full", "influences", "metadata")}
        except (zipfile.BadZipFile, OSError, ValueError, KeyError, EOFError) as exc:
            raise ValueError(
                f"not an ials_zoo influence data set: {path} ({type(exc).__name__}: {exc})"
            ) from None
        try:
            meta = json.loads(str(arrays["metadata"]))
            if meta.get("format") != FORMAT:
                raise ValueError(f"no {FORMAT!r} tag")
            if meta.get("format_version") != FORMAT_VERSION:
                raise ValueError(
                    f"format version {meta.get('format_version')!r}, this ials_zoo reads {FORMAT_VERSION}"
                )
            region = RegionSpec.from_dict(meta["region"])
            ds = cls(region, {"dset": arrays["dset"], "full": arrays["full"]}, arrays["influences"], meta)
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"not an ials_zoo influence data set: {path} ({exc})") from None
        if env_id is not None and region.domain != env_id:
            raise ValueError(f"{path} holds data of domain {region.domain!r}, not {env_id!r}")
        if agent is not None and region.agent != agent:
            raise ValueError(f"{path} holds data of agent {region.agent!r}, not {agent!r}")
        return ds


def as_policy(policy, action_space, seed: int) -> tuple[Callable, str]:
    """Turn ``policy`` into ``obs -> action`` and a name for the metadata.

    ``None`` is the uniform random policy (Algorithm 1's exploratory default); an object with
    an SB3-style ``predict(obs)`` is sampled stochastically; any other callable is used as is.
    """
    if policy is None:
        space = action_space
        space.seed(seed)
        return (lambda obs: space.sample()), "uniform_random"
    if callable(policy):
        return policy, getattr(policy, "__name__", type(policy).__name__)
    if callable(getattr(policy, "predict", None)):
        return (lambda obs: policy.predict(obs, deterministic=False)[0]), type(policy).__name__
    raise TypeError(f"policy must be None, a callable obs -> action, or have predict(); got {policy!r}")


def collect(
    env_id: str,
    agent: str,
    steps: int = 50_000,
    policy=None,
    seed: int = 0,
    gs_options: dict | None = None,
    progress: bool = True,
    workers: int = 1,
) -> InfluenceDataset:
    """Algorithm 1: record ``(d_t, u_t)`` of ``agent`` in the GS of ``env_id``.

    Args:
        env_id: a domain id (``ials_zoo.core.domain_ids()``).
        agent: the learning agent whose region is recorded; every other agent is scripted.
        steps: number of steps, rounded up to whole episodes.
        policy: ``obs -> action`` for ``agent`` (``None``: uniform random).
        seed: seeds the first ``reset`` and the random policy (later episodes continue the
            GS's random stream, so the whole collection is reproducible).
        gs_options: keyword arguments for the domain's ``parallel_env``.
        progress: show a tqdm progress bar.
        workers: GS processes collecting at once. With ``workers > 1`` each process records
            ``ceil(steps / workers)`` steps (rounded up to whole episodes) from its own seed
            (:func:`worker_seeds`) and the episodes are concatenated in worker order; the
            policy must then be picklable (``None`` is). ``collect_seconds`` is the wall-clock
            of the whole collection. Worth it for SUMO (one simulation per process), not for
            the numpy warehouse, whose collection is shorter than starting a process.
    """
    from ials_zoo.core.domains import get_domain

    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a positive int, got {workers!r}")
    if workers > 1:
        return _collect_in_processes(env_id, agent, steps, policy, seed, gs_options, progress, workers)
    domain = get_domain(env_id)
    gs_options = dict(gs_options or {})
    if "learners" in gs_options:
        raise ValueError("gs_options must not set 'learners': the collected agent is the learner")
    agents = domain.possible_agents(**_region_options(domain, gs_options))
    if agent not in agents:
        raise ValueError(f"unknown agent {agent!r} for {env_id}; expected one of {_short(agents)}")

    t0 = time.perf_counter()
    env = domain.parallel_env(learners=[agent], **gs_options)
    try:
        act, policy_name = as_policy(policy, env.action_space(agent), seed)
        region = env.region_spec(agent) if hasattr(env, "region_spec") else domain.region_spec(agent)
        keys = {kind: dset_key(kind) for kind in DSET_KINDS}
        episodes_d = {k: [] for k in DSET_KINDS}
        episodes_u = []
        T = None
        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=steps, desc=f"collect {env_id}/{agent}", unit="step")
        total = 0
        ep = 0
        while total < steps:
            obs, infos = env.reset(seed=seed if ep == 0 else None)
            ep_d = {k: [np.asarray(infos[agent][keys[k]], dtype=np.uint8)] for k in DSET_KINDS}
            ep_u = []
            while True:
                actions = {a: (act(obs[a]) if a == agent else None) for a in env.agents}
                actions = {a: v for a, v in actions.items() if v is not None}
                obs, _, terms, truncs, infos = env.step(actions)
                info = infos[agent]
                ep_u.append(np.asarray(info[INFLUENCE_KEY], dtype=np.int64))
                done = terms.get(agent, False) or truncs.get(agent, False) or agent not in env.agents
                if done:
                    break
                for k in DSET_KINDS:
                    ep_d[k].append(np.asarray(info[keys[k]], dtype=np.uint8))
                if T is not None and len(ep_u) > T:
                    raise RuntimeError(f"{env_id}: episode {ep} is longer than the first ({T} steps)")
            if any(terms.get(a, False) for a in terms):
                raise RuntimeError(f"{env_id}: an episode terminated; the zoo's episodes only truncate")
            if T is None:
                T = len(ep_u)
            elif len(ep_u) != T:
                raise RuntimeError(f"{env_id}: episode {ep} has {len(ep_u)} steps, the first had {T}")
            for k in DSET_KINDS:
                episodes_d[k].append(np.stack(ep_d[k]))
            episodes_u.append(np.stack(ep_u))
            total += T
            ep += 1
            if bar is not None:
                bar.update(T)
        if bar is not None:
            bar.close()
    finally:
        env.close()
    seconds = time.perf_counter() - t0
    from ials_zoo import __version__

    meta = {
        "env_id": env_id,
        "agent": agent,
        "gs_options": gs_options,
        "steps": total,
        "steps_requested": steps,
        "seed": int(seed),
        "policy": policy_name,
        "package_version": __version__,
        "collect_seconds": round(seconds, 3),
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    return InfluenceDataset(
        region,
        {k: np.stack(v) for k, v in episodes_d.items()},
        np.stack(episodes_u),
        meta,
    )


def worker_seeds(seed: int, workers: int) -> list[int]:
    """The seed of each collection process: ``seed`` itself for one process (so ``workers=1``
    is plain :func:`collect`), independent streams spawned from ``seed`` otherwise."""
    if workers == 1:
        return [int(seed)]
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(int(seed)).spawn(workers)]


def _collect_share(kwargs: dict) -> "InfluenceDataset":
    import torch

    torch.set_num_threads(1)
    return collect(**kwargs)


def _collect_in_processes(env_id, agent, steps, policy, seed, gs_options, progress, workers):
    import multiprocessing
    import pickle
    from concurrent.futures import ProcessPoolExecutor

    try:
        pickle.dumps(policy)
    except Exception as exc:
        raise ValueError(f"collect(workers={workers}) sends the policy to other processes, but it cannot be "
                         f"pickled ({exc}); use workers=1 or a picklable policy") from None
    t0 = time.perf_counter()
    share = -(-steps // workers)
    seeds = worker_seeds(seed, workers)
    jobs = [dict(env_id=env_id, agent=agent, steps=share, policy=policy, seed=s, gs_options=gs_options,
                 progress=False) for s in seeds]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=workers, desc=f"collect {env_id}/{agent} ({workers} processes)", unit="share")
    # spawn: a fresh interpreter per worker, so no libsumo simulation is inherited by fork.
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = [pool.submit(_collect_share, j) for j in jobs]
        parts = []
        for f in futures:
            parts.append(f.result())
            if bar is not None:
                bar.update(1)
    if bar is not None:
        bar.close()
    seconds = time.perf_counter() - t0
    first = parts[0]
    meta = dict(first.metadata, steps=sum(p.n_steps for p in parts), steps_requested=steps, seed=int(seed),
                workers=workers, worker_seeds=seeds, collect_seconds=round(seconds, 3))
    return InfluenceDataset(
        first.region,
        {k: np.concatenate([p.dsets[k] for p in parts]) for k in first.dsets},
        np.concatenate([p.influences for p in parts]),
        meta,
    )


def _region_options(domain, options: dict) -> dict:
    """The options ``possible_agents`` accepts (it may not take every GS option)."""
    import inspect

    try:
        sig = inspect.signature(domain.possible_agents)
    except (TypeError, ValueError):
        return {}
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return dict(options)
    return {k: v for k, v in options.items() if k in sig.parameters}


def _short(items, n=8):
    items = list(items)
    s = ", ".join(map(str, items[:n]))
    return s + (f", ... ({len(items)} in all)" if len(items) > n else "")


__all__ = ["InfluenceDataset", "collect"]
