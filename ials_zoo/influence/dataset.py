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

import copy
import json
import pickle
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from ials_zoo._version import __version__
from ials_zoo.core.domains import Domain, get_domain
from ials_zoo.core.region import DSET_KINDS, INFLUENCE_KEY, RegionSpec, dset_key
from ials_zoo.errors import BadInput, BadInputType
from ials_zoo.runtime.processes import shutdown_pool, spawn_pool
from ials_zoo.utils import atomic_path, check_seed, parse_untrusted_json_object

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
            raise BadInput(
                f"influences must have shape [episodes, T, {self.region.n_sources}], got {u.shape}"
            )
        if u.dtype.kind not in "iub" and u.size and not (np.isfinite(u).all() and (u == np.round(u)).all()):
            raise BadInput("influences must be whole class numbers (no NaN, no fractions such as 1.5)")
        self.influences = u.astype(np.int64, copy=False)
        if set(self.dsets) != set(DSET_KINDS):
            raise BadInput(f"dsets must hold exactly the kinds {DSET_KINDS}, got {sorted(self.dsets)}")
        for kind in DSET_KINDS:
            d = np.asarray(self.dsets[kind])
            want = (u.shape[0], u.shape[1], self.region.dset_size(kind))
            if d.shape != want:
                raise BadInput(f"d-set {kind!r} has shape {d.shape}, expected {want}")
            if d.size and not np.isin(d, (0, 1)).all():
                raise BadInput(f"d-set {kind!r} must hold bits (0 or 1); found other values (NaN, fractions, ...)")
            self.dsets[kind] = d.astype(np.uint8, copy=False)
        classes = np.asarray(self.region.influence_classes)
        if u.size and ((u < 0).any() or (u >= classes).any()):
            raise BadInput(f"influence values out of range for classes {tuple(classes)}")

    @property
    def n_episodes(self) -> int:
        return int(self.influences.shape[0])

    @property
    def episode_length(self) -> int:
        return int(self.influences.shape[1])

    @property
    def n_steps(self) -> int:
        return self.n_episodes * self.episode_length

    def subset(self, episodes) -> InfluenceDataset:
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
            raise BadInput(f"test_fraction must be in [0, 1), got {test_fraction}")
        E = self.n_episodes
        perm = np.random.default_rng(seed).permutation(E)
        n_test = int(round(E * test_fraction))
        if test_fraction > 0 and E >= 2:
            n_test = max(1, n_test)
        return np.sort(perm[n_test:]), np.sort(perm[:n_test])

    # -- files -----------------------------------------------------------------------------
    def save(self, path) -> Path:
        """Write the data set to ``path`` (``.npz``), atomically."""
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
        return path

    @classmethod
    def load(cls, path, env_id: str | None = None, agent: str | None = None) -> InfluenceDataset:
        """Read a data set written by :meth:`save`; ``env_id``/``agent`` are checked if given."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"influence data set not found: {path}")
        try:
            with np.load(path, allow_pickle=False) as z:
                arrays = {k: z[k] for k in ("dset", "full", "influences", "metadata")}
        except (zipfile.BadZipFile, OSError, ValueError, KeyError, EOFError) as exc:
            why = f"{type(exc).__name__}: {exc}"
            if "pickle" in str(exc):  # numpy's advice to allow pickles is not ours to give
                why = "not an .npz archive of arrays; pickled content is never loaded"
            raise BadInput(f"not an ials_zoo influence data set: {path} ({why})") from None
        try:
            meta = parse_untrusted_json_object(str(arrays["metadata"]), "its metadata")
            if meta.get("format") != FORMAT:
                raise BadInput(f"no {FORMAT!r} tag")
            if meta.get("format_version") != FORMAT_VERSION:
                raise BadInput(
                    f"format version {meta.get('format_version')!r}, this ials_zoo reads {FORMAT_VERSION}"
                )
            region = RegionSpec.from_dict(meta["region"])
            ds = cls(region, {"dset": arrays["dset"], "full": arrays["full"]}, arrays["influences"], meta)
        except (ValueError, KeyError, TypeError) as exc:
            raise BadInput(f"not an ials_zoo influence data set: {path} ({exc})") from None
        if env_id is not None and region.domain != env_id:
            raise BadInput(f"{path} holds data of domain {region.domain!r}, not {env_id!r}")
        if agent is not None and region.agent != agent:
            raise BadInput(f"{path} holds data of agent {region.agent!r}, not {agent!r}")
        return ds


def as_policy(policy, action_space, seed: int) -> tuple[Callable, str]:
    """Turn ``policy`` into ``obs -> action`` and a name for the metadata.

    ``None`` is the uniform random policy (Algorithm 1's exploratory default); an object with
    an SB3-style ``predict(obs)`` is sampled stochastically; any other callable is used as is.
    """
    if policy is None:
        space = copy.deepcopy(action_space)
        space.seed(seed)
        return (lambda obs: space.sample()), "uniform_random"
    if callable(policy):
        return policy, getattr(policy, "__name__", type(policy).__name__)
    if callable(getattr(policy, "predict", None)):
        return (lambda obs: policy.predict(obs, deterministic=False)[0]), type(policy).__name__
    raise BadInputType(f"policy must be None, a callable obs -> action, or have predict(); got {policy!r}")


class _JointActor:
    """``observations -> actions`` of the collected agents, from any accepted policy form."""

    def __init__(self, policy, agents, action_space_of, seed):
        self.joint = policy if callable(getattr(policy, "joint_act", None)) else None
        if self.joint is not None:
            self.name = getattr(policy, "name", type(policy).__name__)
            return
        if isinstance(policy, dict):
            missing = [a for a in agents if a not in policy]
            if missing:
                raise BadInput(f"the policy dict has no entry for {missing}")
            per = {a: policy[a] for a in agents}
        else:
            per = dict.fromkeys(agents, policy)
        seeds = np.random.SeedSequence(int(seed)).generate_state(len(agents)) if len(agents) > 1 else [seed]
        self.acts, names = {}, set()
        for a, s in zip(agents, seeds):
            self.acts[a], name = as_policy(per[a], action_space_of(a), int(s))
            names.add(name)
        self.name = names.pop() if len(names) == 1 else "mixed"

    def reset(self):
        if self.joint is not None and callable(getattr(self.joint, "reset", None)):
            self.joint.reset()

    def __call__(self, obs: dict) -> dict:
        if self.joint is not None:
            return self.joint.joint_act(obs)
        return {a: act(obs[a]) for a, act in self.acts.items()}


def collect(
    env_id: str | Domain,
    agent: str,
    steps: int = 50_000,
    policy=None,
    seed: int = 0,
    gs_options: dict | None = None,
    progress: bool = True,
    workers: int = 1,
) -> InfluenceDataset:
    """Algorithm 1: record ``(d_t, u_t)`` of ``agent`` in the GS of ``env_id``, every other
    agent scripted. See :func:`collect_all` for the arguments."""
    return collect_all(env_id, [agent], steps, policy, seed, gs_options, progress, workers)[agent]


def collect_all(
    env_id: str | Domain,
    agents=None,
    steps: int = 50_000,
    policy=None,
    seed: int = 0,
    gs_options: dict | None = None,
    progress: bool = True,
    workers: int = 1,
) -> dict[str, InfluenceDataset]:
    """Algorithm 1 for several regions at once: one GS run in which ``agents`` learn (are
    driven by ``policy``) and every other agent is scripted; the ``(d_t, u_t)`` of every
    learner's region is recorded at every step.

    Args:
        env_id: a domain id (``ials_zoo.core.domain_ids()``) or the :class:`~ials_zoo.core.domains.Domain`.
        agents: the learning agents whose regions are recorded (None: every agent).
        steps: GS steps, rounded up to whole episodes (each step gives one pair per agent).
        policy: ``None`` (uniform random actions), a callable ``obs -> action`` or an object
            with SB3's ``predict`` (for every agent), a dict ``{agent: one of those}``, or a
            joint policy: an object with ``joint_act(observations) -> actions`` (dicts by
            agent) and optionally ``reset()``, called at every episode start.
        seed: seeds the first ``reset`` and the random policies (later episodes continue the
            GS's random stream, so the whole collection is reproducible).
        gs_options: keyword arguments for the domain's ``parallel_env``.
        progress: show a tqdm progress bar.
        workers: GS processes collecting at once. With ``workers > 1`` each process records
            ``ceil(steps / workers)`` steps (rounded up to whole episodes) from its own seed
            (:func:`worker_seeds`) and the episodes are concatenated in worker order; the
            policy must then be picklable (``None`` is). ``collect_seconds`` is the wall-clock
            of the whole collection. Worth it for SUMO (one simulation per process), not for
            the numpy warehouse, whose collection is shorter than starting a process.

    Returns:
        ``{agent: InfluenceDataset}``.
    """
    return collect_regions(get_domain(env_id), agents, steps, policy, seed, gs_options, progress, workers)


def collect_regions(domain: Domain, agents=None, steps: int = 50_000, policy=None, seed: int = 0,
                    gs_options: dict | None = None, progress: bool = True,
                    workers: int = 1) -> dict[str, InfluenceDataset]:
    """:func:`collect_all` of a resolved :class:`~ials_zoo.core.domains.Domain`."""
    steps = int(steps)
    if steps < 1:
        raise BadInput(f"steps must be >= 1, got {steps}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise BadInput(f"workers must be a positive int, got {workers!r}")
    check_seed(seed)
    env_id = domain.env_id  # what worker processes are given
    gs_options = dict(gs_options or {})
    if "learners" in gs_options:
        raise BadInput("gs_options must not set 'learners': the collected agents are the learners")
    agents = domain.check_agents(agents, **gs_options)
    if workers > 1:
        return _collect_in_processes(env_id, agents, steps, policy, seed, gs_options, progress, workers)
    return _collect_in_process(domain, env_id, agents, steps, policy, seed, gs_options, progress)


def _collect_in_process(domain, env_id: str, agents: list, steps: int, policy, seed: int, gs_options: dict,
                        progress: bool) -> dict[str, InfluenceDataset]:
    """:func:`collect_all` in this process, its arguments checked: one GS run of whole episodes
    until ``steps`` are recorded."""
    t0 = time.perf_counter()
    env = domain.parallel_env(learners=agents, **{**domain.collect_options, **gs_options})
    try:
        actor = _JointActor(policy, agents, env.action_space, seed)
        keys = {kind: dset_key(kind) for kind in DSET_KINDS}
        data_d = {a: {k: [] for k in DSET_KINDS} for a in agents}
        data_u = {a: [] for a in agents}
        T = None
        bar = None
        if progress:
            what = agents[0] if len(agents) == 1 else f"{len(agents)} agents"
            bar = tqdm(total=steps, desc=f"collect {env_id}/{what}", unit="step")
        total = 0
        ep = 0
        while total < steps:
            ep_d, ep_u, length = _record_episode(env, actor, agents, keys, seed if ep == 0 else None, T, env_id, ep)
            if T is None:
                T = length
            elif length != T:
                raise RuntimeError(f"{env_id}: episode {ep} has {length} steps, the first had {T}")
            for a in agents:
                for k in DSET_KINDS:
                    data_d[a][k].append(np.stack(ep_d[a][k]))
                data_u[a].append(np.stack(ep_u[a]))
            total += T
            ep += 1
            if bar is not None:
                bar.update(T)
        if bar is not None:
            bar.close()
        regions = {a: env.region_spec(a) for a in agents}
    finally:
        env.close()
    seconds = time.perf_counter() - t0
    meta = {"env_id": env_id, "agents": list(agents), "gs_options": gs_options, "steps": total,
            "steps_requested": steps, "seed": int(seed), "policy": actor.name, "collect_seconds": round(seconds, 3)}
    return {a: _dataset(regions[a], data_d[a], data_u[a], dict(meta, agent=a)) for a in agents}


def _dataset(region, dsets: dict, influences: list, meta: dict) -> InfluenceDataset:
    """One agent's episodes as a data set, with the provenance ``meta`` (plus version, time)."""
    meta = dict(meta, package_version=__version__, created=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    return InfluenceDataset(region, {k: np.stack(v) for k, v in dsets.items()}, np.stack(influences), meta)


def _record_episode(env, actor, agents, keys, seed, longest, env_id, ep):
    """One GS episode of ``actor``: every agent's d-sets (``d_0 .. d_{T-1}``) and influences
    (``u_0 .. u_{T-1}``) and the length ``T`` (at most ``longest``, the first episode's)."""
    obs, infos = env.reset(seed=seed)
    actor.reset()
    ep_d = {a: {k: [np.asarray(infos[a][keys[k]], dtype=np.uint8)] for k in DSET_KINDS} for a in agents}
    ep_u = {a: [] for a in agents}
    length = 0
    while True:
        obs, _, terms, truncs, infos = env.step(actor(obs))
        length += 1
        for a in agents:
            ep_u[a].append(np.asarray(infos[a][INFLUENCE_KEY], dtype=np.int64))
        if any(terms.values()):
            raise RuntimeError(f"{env_id}: an episode terminated; the zoo's episodes only truncate")
        if all(truncs.values()) or not env.agents:
            return ep_d, ep_u, length
        for a in agents:
            for k in DSET_KINDS:
                ep_d[a][k].append(np.asarray(infos[a][keys[k]], dtype=np.uint8))
        if longest is not None and length > longest:
            raise RuntimeError(f"{env_id}: episode {ep} is longer than the first ({longest} steps)")


def worker_seeds(seed: int, workers: int) -> list[int]:
    """The seed of each collection process: ``seed`` itself for one process (so ``workers=1``
    is plain :func:`collect`), independent streams spawned from ``seed`` otherwise."""
    if workers == 1:
        return [int(seed)]
    # below 2**31 - 1: a seed every domain takes as it is (SUMO's range)
    return [int(s.generate_state(1)[0]) % (2**31 - 1) for s in np.random.SeedSequence(int(seed)).spawn(workers)]


def _collect_share(kwargs: dict) -> dict[str, InfluenceDataset]:
    import torch

    torch.set_num_threads(1)
    return collect_all(**kwargs)


def _collect_in_processes(env_id, agents, steps, policy, seed, gs_options, progress, workers):
    try:
        pickle.dumps(policy)
    except Exception as exc:
        raise BadInput(f"collect(workers={workers}) sends the policy to other processes, but it cannot be "
                         f"pickled ({exc}); use workers=1 or a picklable policy") from None
    t0 = time.perf_counter()
    share = -(-steps // workers)
    seeds = worker_seeds(seed, workers)
    jobs = [dict(env_id=env_id, agents=agents, steps=share, policy=policy, seed=s, gs_options=gs_options,
                 progress=False) for s in seeds]
    bar = None
    if progress:
        what = agents[0] if len(agents) == 1 else f"{len(agents)} agents"
        bar = tqdm(total=workers, desc=f"collect {env_id}/{what} ({workers} processes)", unit="share")
    # spawn: a fresh interpreter per worker, so no libsumo simulation is inherited by fork;
    # the workers die with this process however it ends.
    pool = spawn_pool(workers)
    ok = False
    try:
        futures = [pool.submit(_collect_share, j) for j in jobs]
        parts = []
        for f in futures:
            parts.append(f.result())
            if bar is not None:
                bar.update(1)
        ok = True
    finally:
        shutdown_pool(pool, kill=not ok)
        if bar is not None:
            bar.close()
    seconds = time.perf_counter() - t0
    out = {}
    for a in agents:
        first = parts[0][a]
        meta = dict(first.metadata, steps=sum(p[a].n_steps for p in parts), steps_requested=steps,
                    seed=int(seed), workers=workers, worker_seeds=seeds, collect_seconds=round(seconds, 3))
        out[a] = InfluenceDataset(
            first.region,
            {k: np.concatenate([p[a].dsets[k] for p in parts]) for k in first.dsets},
            np.concatenate([p[a].influences for p in parts]),
            meta,
        )
    return out


__all__ = ["InfluenceDataset", "collect", "collect_all"]
