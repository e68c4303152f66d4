"""The study as a list of jobs: what ``ials-zoo reproduce`` runs, where, and in which order.

A :class:`Job` is one subprocess (``python -m ials_zoo.reproduce.worker JOB_DIR/job.json``)
that writes its outputs into its own folder ``dir``; it is *done* when its ``marker`` file
exists there (``result.json`` for a PPO run), which is what makes the study resumable: a
second invocation plans the same jobs and skips the done ones.

Layout under ``--out`` (default ``runs/reproduce``)::

    training/<env_id>__<agent>/aip/            AIP collected + trained once per agent (timed)
    training/<env_id>__<agent>/<label>__s<seed>/   one ppo_single job; its run folder run/ holds
                                               curve.json, result.json, policy.safetensors, ...
    memory/<env_id>__<agent>/aip_gru/, aip_mlp/    M-IALS / NM-IALS AIPs (item_lifetime=8)
    memory/<env_id>__<agent>/<aip>__fs<k>__s<seed>/ PPO on that IALS with frame stack k
    memory/<env_id>__<agent>/lifetimes/        item-lifetime histograms (GS, M-IALS, NM-IALS)
    dset/<env_id>__<agent>/                    d-set vs full-history AIP, off-policy CE
    dials/<env_id>/<variant>__s<seed>/         one multi-agent run (every agent learning): GS-IPPO,
                                               DIALS (periodic / once), untrained-DIALS; its run/
                                               holds the baseline's outputs (result.json, ...)
    dials/<env_id>/dials__1worker__s0/         the periodic DIALS run of seed 0 with one worker
                                               (parallel efficiency; bitwise the same run)
    dials/<env_id>/joint-<policy>/             joint scripted / random references (result.json)
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

from ials_zoo.core.domains import domain_of_agent, get_domain, ials_domain_ids
from ials_zoo.core.extras import dials_of, study_of
from ials_zoo.errors import BadInput
from ials_zoo.utils import atomic_write_text, read_json_object

EXPERIMENTS = ("training", "memory", "dset", "dials")
# The multi-agent study (issue: every agent learning at once): GS-IPPO and the DIALS variants,
# each ``(algorithm, extra arguments)`` of :mod:`ials_zoo.baselines.ippo` / ``.dials``.
# "dials" retrains the AIPs every half budget (rounds at 0 and budget/2); see plan_dials.
# "dials" and "dials-once" use memoryless AIPs (the paper's), "dials-autoregressive" AIPs that
# read their own last draw (P(u_t | d_<=t, u_<t), at the domain's DIALSSettings.lr_for): each
# variant says which, whatever the domain's default (DIALSSettings.aip_autoregressive);
# "dials-fidelity" AIPs trained as `ials-zoo fidelity` trains them (dials --aip-training fidelity).
DIALS_VARIANTS = ("ippo", "dials", "dials-once", "untrained-dials", "dials-autoregressive", "dials-fidelity")
OPT_IN_DIALS_VARIANTS = ("dials-fidelity",)  # on request only: its AIP rounds cost minutes each
DEFAULT_DIALS_VARIANTS = tuple(v for v in DIALS_VARIANTS if v not in OPT_IN_DIALS_VARIANTS)
JOINT_REFERENCES = ("scripted", "random")
RUN_SUBDIR = "run"  # a PPO job's run folder inside its job folder (which holds job.json, log.txt)
DEFAULT_SIMULATORS = ("gs", "ials", "untrained-ials", "fixed:0.1")
KNOWN_SIMULATORS = DEFAULT_SIMULATORS + ("marginal",)
# The memory experiment (12 runs) compares simulators with each other, not with the GS's
# wall-clock: 500k steps per run (``Config.memory_budget``). Each domain's own default budget
# is ``study_of(domain).budget`` (what the published study used).
DEFAULT_MEMORY_BUDGET = 500_000


def default_budgets() -> dict:
    """PPO steps per single-agent run of each domain (``study_of(domain).budget``)."""
    return {d: study_of(d).budget for d in ials_domain_ids()}


def memory_domains() -> tuple:
    """The domains with a memory variant (paper §5.4): ``study_of(domain).memory_variant``."""
    return tuple(d for d in ials_domain_ids() if study_of(d).memory_variant)


@dataclass
class Config:
    """Settings of one study (the options of ``ials-zoo reproduce``)."""

    experiments: tuple = EXPERIMENTS
    domains: tuple = field(default_factory=lambda: tuple(ials_domain_ids()))
    agents: tuple = ()  # extra/override agents, e.g. ("tls_12", "tls_18")
    simulators: tuple = DEFAULT_SIMULATORS
    budget: int = 500_000  # PPO environment steps per run (see DEFAULT_BUDGETS)
    domain_budgets: dict = field(default_factory=dict)  # per-domain overrides (CLI default: DEFAULT_BUDGETS)
    memory_budget: int | None = None  # memory experiment (CLI default DEFAULT_MEMORY_BUDGET); None: the warehouse's
    seeds: int = 3
    jobs: int = 2
    out: str = "runs/reproduce"
    leaderboard: str = "leaderboard"
    net_arch: str = "64,64"  # ppo_single's default (the ablation's; SPEC §3 used 256-128)
    n_envs: int = 8
    eval_points: int = 10  # GS evaluations along each curve
    eval_episodes: int = 10
    final_eval_episodes: int = 20
    aip_steps: int = 50_000  # Algorithm 1 data per AIP (the paper's N)
    aip_epochs: int | None = None  # None: the project's default
    collect_workers: int = 2  # GS processes of Algorithm 1 in SUMO domains (the cores here)
    dset_offpolicy_steps: int = 10_000
    lifetime_episodes: int = 20
    dials_variants: tuple = DEFAULT_DIALS_VARIANTS
    dials_budgets: dict = field(default_factory=dict)  # steps per agent; default study_of(domain).multi_agent_budget
    dials_workers: int = 2  # worker processes of each DIALS run (the cores here)
    dials_eval_points: int = 4  # GS evaluations along each multi-agent curve (each scores every agent)

    def check(self) -> Config:
        """Clear errors for bad settings; returns self."""
        for name, allowed in (("experiments", EXPERIMENTS), ("domains", tuple(ials_domain_ids())),
                              ("simulators", KNOWN_SIMULATORS)):
            values = tuple(getattr(self, name))
            if not values:
                raise BadInput(f"{name} must not be empty; expected some of {allowed}")
            bad = [v for v in values if v not in allowed]
            if bad:
                raise BadInput(f"unknown {name} {bad}; expected some of {list(allowed)}")
        if "gs" not in self.simulators:
            raise BadInput(f"simulators {list(self.simulators)} must include 'gs' (the reference)")
        for env_id, steps in dict(self.domain_budgets).items():
            if env_id not in ials_domain_ids():
                raise BadInput(f"unknown domain {env_id!r} in domain_budgets; expected one of {ials_domain_ids()}")
            if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
                raise BadInput(f"budget of {env_id} must be a positive int, got {steps!r}")
        for name in ("budget", "seeds", "jobs", "collect_workers", "n_envs", "eval_points", "eval_episodes",
                     "final_eval_episodes", "aip_steps", "dset_offpolicy_steps", "lifetime_episodes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise BadInput(f"{name} must be a positive int, got {v!r}")
        if self.memory_budget is not None and (isinstance(self.memory_budget, bool)
                                               or not isinstance(self.memory_budget, int) or self.memory_budget < 1):
            raise BadInput(f"memory_budget must be None or a positive int, got {self.memory_budget!r}")
        if self.aip_epochs is not None and (not isinstance(self.aip_epochs, int) or self.aip_epochs < 0):
            raise BadInput(f"aip_epochs must be None or an int >= 0, got {self.aip_epochs!r}")
        bad = [v for v in self.dials_variants if v not in DIALS_VARIANTS]
        if bad or not self.dials_variants:
            raise BadInput(f"unknown dials_variants {bad}; expected some of {list(DIALS_VARIANTS)}")
        for env_id, steps in dict(self.dials_budgets).items():
            if env_id not in ials_domain_ids():
                raise BadInput(f"unknown domain {env_id!r} in dials_budgets; expected one of {ials_domain_ids()}")
            if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
                raise BadInput(f"dials budget of {env_id} must be a positive int, got {steps!r}")
        for name in ("dials_workers", "dials_eval_points"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise BadInput(f"{name} must be a positive int, got {v!r}")
        for a in self.agents:
            domain_of_agent(a)  # one domain has it, else a ValueError naming the problem
        return self

    def agents_of(self, env_id: str) -> tuple:
        """The learning agents of ``env_id`` in this study (``--agents`` overrides per domain;
        default: the domain's first paper agent)."""
        mine = tuple(a for a in self.agents if domain_of_agent(a) == env_id)
        return mine or get_domain(env_id).default_agents[:1]

    def budget_for(self, env_id: str) -> int:
        """PPO steps per run in ``env_id`` (a per-domain budget wins over ``budget``)."""
        return int(dict(self.domain_budgets).get(env_id, self.budget))

    def collect_workers_for(self, env_id: str) -> int:
        """GS processes collecting a training AIP's data: ``collect_workers`` where each GS
        needs its own process anyway (SUMO), else 1 (a numpy GS collects 50k steps in ~2 s,
        less than starting processes costs)."""
        return self.collect_workers if get_domain(env_id).one_simulation_per_process else 1

    def dials_budget_for(self, env_id: str) -> int:
        """Steps per agent of each multi-agent run in ``env_id``."""
        return int(dict(self.dials_budgets).get(env_id, study_of(env_id).multi_agent_budget))

    def memory_budget_steps(self, env_id: str) -> int:
        """PPO steps per run of the memory experiment in ``env_id``."""
        return self.budget_for(env_id) if self.memory_budget is None else int(self.memory_budget)

    def eval_every(self, env_id: str | None = None, budget: int | None = None) -> int:
        if budget is None:
            budget = self.budget if env_id is None else self.budget_for(env_id)
        return max(1, -(-budget // self.eval_points))


@dataclass
class Job:
    """One subprocess of the study (see the module docstring)."""

    id: str
    kind: str  # aip | ppo | lifetimes | dset | multiagent | joint-reference
    dir: str
    marker: str
    params: dict
    deps: list = field(default_factory=list)
    experiment: str = ""
    label: str = ""

    @property
    def exclusive(self) -> bool:
        """Runs alone: a multi-agent run spreads over every core itself, and its wall-clock is
        compared with other runs' (GS-IPPO vs DIALS on the same cores)."""
        return self.kind == "multiagent"

    @property
    def done(self) -> bool:
        return (Path(self.dir) / self.marker).is_file()

    def conflict(self) -> str | None:
        """Why the folder cannot be reused for this job (it holds a job of another kind or
        with other parameters, e.g. another budget), or None. Resuming must never mix runs of
        different settings into one study."""
        path = Path(self.dir) / "job.json"
        if not path.is_file():
            return None
        try:
            old = read_json_object(path, what="job record")
        except (OSError, ValueError):
            return f"{path} is unreadable"
        if old.get("kind") != self.kind or old.get("params") != json.loads(json.dumps(self.params)):
            diff = sorted(k for k in set(old.get("params", {})) | set(self.params)
                          if old.get("params", {}).get(k) != json.loads(json.dumps(self.params)).get(k))
            return f"{self.dir} holds a {old.get('kind')} job with other settings ({', '.join(diff) or 'kind'})"
        return None

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def priority(self) -> tuple:
        """Sort key for starting ready jobs: AIPs first (they unblock IALS runs), then the
        longest runs (estimated seconds), so that the study's makespan on few cores is short;
        multi-agent runs last, seed by seed."""
        if self.kind == "aip":
            return (0, 0.0)
        p = self.params
        if self.kind == "ppo":
            sim = "gs" if p["simulator"] == "gs" else "ials"
            rate = study_of(p["env_id"]).ppo_steps_per_second.get(sim, 1000.0)
            return (1, -p["total_timesteps"] / rate)
        if self.kind == "multiagent":
            # seed by seed: a study cut short still compares every variant on the same seeds
            return (2, p["seed"])
        return (1, 0.0)

    @classmethod
    def from_dict(cls, d: dict) -> Job:
        return cls(**d)

    def write(self) -> Path:
        """Write ``job.json`` into the job's folder (what the worker reads)."""

        Path(self.dir).mkdir(parents=True, exist_ok=True)
        path = Path(self.dir) / "job.json"
        atomic_write_text(path, json.dumps(self.to_dict(), indent=2) + "\n")
        return path


def label_of(simulator: str) -> str:
    """Folder-safe name of a simulator (``fixed:0.1`` -> ``fixed0.1``)."""
    return simulator.replace(":", "")


def _ppo_params(cfg: Config, env_id: str, agent: str, simulator: str, seed: int, out: Path,
                notes: str, budget: int | None = None) -> dict:
    budget = cfg.budget_for(env_id) if budget is None else budget
    return {
        "env_id": env_id, "agent": agent, "simulator": simulator, "seed": seed,
        "total_timesteps": budget, "n_envs": cfg.n_envs, "net_arch": cfg.net_arch,
        "eval_every": cfg.eval_every(budget=budget), "eval_episodes": cfg.eval_episodes,
        "final_eval_episodes": cfg.final_eval_episodes, "out_dir": str(Path(out) / RUN_SUBDIR),
        "progress": False, "notes": notes,
    }


def plan_training(cfg: Config) -> list[Job]:
    """Paper §5.2-5.3: PPO on the GS and on each IALS variant, ``seeds`` seeds each."""
    jobs = []
    root = Path(cfg.out) / "training"
    for env_id in cfg.domains:
        for agent in cfg.agents_of(env_id):
            base = root / f"{env_id}__{agent}"
            aip_dir = base / "aip"
            params = {"env_id": env_id, "agent": agent, "steps": cfg.aip_steps,
                      "epochs": cfg.aip_epochs, "seed": 0, "options": {}}
            workers = cfg.collect_workers_for(env_id)
            if workers > 1:
                params["workers"] = workers
            aip = Job(id=f"training/{env_id}/{agent}/aip", kind="aip", dir=str(aip_dir),
                      marker="report.json", experiment="training", label="aip", params=params)
            jobs.append(aip)
            for sim in cfg.simulators:
                deps = []
                spec = sim
                if sim == "ials":
                    spec, deps = str(aip_dir / "aip.pt"), [aip.id]
                elif sim == "marginal":
                    spec, deps = str(aip_dir / "marginal.pt"), [aip.id]
                for seed in range(cfg.seeds):
                    d = base / f"{label_of(sim)}__s{seed}"
                    jobs.append(Job(
                        id=f"training/{env_id}/{agent}/{label_of(sim)}/s{seed}", kind="ppo",
                        dir=str(d), marker=f"{RUN_SUBDIR}/result.json", deps=deps, experiment="training",
                        label=sim,
                        params=_ppo_params(cfg, env_id, agent, spec, seed, d,
                                           f"ials-zoo reproduce (training, {sim}, budget {cfg.budget_for(env_id)})")))
    return jobs


def plan_memory(cfg: Config) -> list[Job]:
    """Paper §5.4, on every domain with a memory variant (``study_of(domain).memory_variant``,
    the warehouse's ``item_lifetime=8``): M-IALS (GRU AIP) vs NM-IALS (MLP AIP) x agents with
    (the domain's frame stack) and without (1) memory, plus the item-lifetime histograms."""
    jobs = []
    for env_id in [d for d in cfg.domains if d in memory_domains()]:
        options = dict(study_of(env_id).memory_variant)
        stack = get_domain(env_id).frame_stack
        for agent in cfg.agents_of(env_id):
            base = Path(cfg.out) / "memory" / f"{env_id}__{agent}"
            aips = {}
            for arch in ("gru", "mlp"):
                d = base / f"aip_{arch}"
                aips[arch] = Job(id=f"memory/{agent}/aip_{arch}", kind="aip", dir=str(d),
                                 marker="report.json", experiment="memory", label=f"aip_{arch}",
                                 params={"env_id": env_id, "agent": agent, "steps": cfg.aip_steps,
                                         "epochs": cfg.aip_epochs, "seed": 0, "options": options,
                                         "arch": arch})
                jobs.append(aips[arch])
            for arch, name in (("gru", "M-IALS"), ("mlp", "NM-IALS")):
                for fs in sorted({stack, 1}, reverse=True):
                    for seed in range(cfg.seeds):
                        d = base / f"{name}__fs{fs}__s{seed}"
                        params = _ppo_params(cfg, env_id, agent, str(Path(aips[arch].dir) / "aip.pt"),
                                             seed, d, f"ials-zoo reproduce (memory, {name}, frame stack {fs})",
                                             budget=cfg.memory_budget_steps(env_id))
                        # ppo_single trains on, and scores on, the memory variant.
                        params.update(frame_stack=fs, env_options=json.dumps(options, sort_keys=True))
                        jobs.append(Job(id=f"memory/{agent}/{name}/fs{fs}/s{seed}", kind="ppo",
                                        dir=str(d), marker=f"{RUN_SUBDIR}/result.json", deps=[aips[arch].id],
                                        experiment="memory", label=f"{name} fs{fs}", params=params))
            d = base / "lifetimes"
            jobs.append(Job(id=f"memory/{agent}/lifetimes", kind="lifetimes", dir=str(d),
                            marker="lifetimes.json", deps=[aips["gru"].id, aips["mlp"].id],
                            experiment="memory", label="lifetimes",
                            params={"env_id": env_id, "agent": agent, "options": options,
                                    "episodes": cfg.lifetime_episodes,
                                    "aips": {"M-IALS": str(Path(aips["gru"].dir) / "aip.pt"),
                                             "NM-IALS": str(Path(aips["mlp"].dir) / "aip.pt")}}))
    return jobs


def plan_dset(cfg: Config) -> list[Job]:
    """Paper §4.2 ablation: AIPs on the d-set vs the full observation, tested off-policy."""
    jobs = []
    for env_id in cfg.domains:
        agent = cfg.agents_of(env_id)[0]
        d = Path(cfg.out) / "dset" / f"{env_id}__{agent}"
        jobs.append(Job(id=f"dset/{env_id}/{agent}", kind="dset", dir=str(d), marker="dset.json",
                        experiment="dset", label="dset",
                        params={"env_id": env_id, "agent": agent, "steps": cfg.aip_steps,
                                "offpolicy_steps": cfg.dset_offpolicy_steps,
                                "epochs": cfg.aip_epochs, "seed": 0}))
    return jobs


def _multiagent_params(cfg: Config, env_id: str, variant: str, seed: int, out: Path, workers: int) -> dict:
    budget = cfg.dials_budget_for(env_id)
    params = {"algorithm": "ippo" if variant == "ippo" else "dials", "env_id": env_id, "seed": seed,
              "total_timesteps": budget, "eval_every": max(1, -(-budget // cfg.dials_eval_points)),
              "eval_episodes": cfg.eval_episodes, "final_eval_episodes": cfg.final_eval_episodes,
              "out_dir": str(Path(out) / RUN_SUBDIR), "progress": False,
              "notes": f"ials-zoo reproduce (dials, {variant}, {budget:,} steps per agent)"}
    if variant != "ippo":
        params["workers"] = workers
        params["refresh"] = {"dials": str(max(1, budget // 2)), "dials-once": "once", "untrained-dials": "never",
                             "dials-autoregressive": str(max(1, budget // 2)),
                             "dials-fidelity": str(max(1, budget // 2))}[variant]
        if variant == "untrained-dials":
            params["aip"] = "untrained"
        if variant in ("dials", "dials-once", "dials-autoregressive"):
            params["aip_autoregressive"] = variant == "dials-autoregressive"
        if variant == "dials-autoregressive":  # the job records the learning rate its AIPs train at
            params["aip_lr"] = dials_of(env_id).lr_for(True)
        if variant == "dials-fidelity":
            params["aip_training"] = "fidelity"
    return params


def plan_dials(cfg: Config) -> list[Job]:
    """Every agent learning at once (SPEC §6): GS-IPPO and DIALS with periodic refresh (every
    half budget), AIPs trained once, and untrained-DIALS, ``seeds`` seeds each; the periodic
    DIALS run of seed 0 again with one worker (parallel efficiency: the same run, bitwise, so
    only its wall-clock differs); and the joint scripted / random references."""
    jobs = []
    for env_id in cfg.domains:
        base = Path(cfg.out) / "dials" / env_id
        for policy in JOINT_REFERENCES:
            d = base / f"joint-{policy}"
            jobs.append(Job(id=f"dials/{env_id}/joint-{policy}", kind="joint-reference", dir=str(d),
                            marker="result.json", experiment="dials", label=f"joint {policy}",
                            params={"env_id": env_id, "policy": policy, "episodes": cfg.final_eval_episodes}))
        for variant in cfg.dials_variants:
            for seed in range(cfg.seeds):
                d = base / f"{variant}__s{seed}"
                jobs.append(Job(id=f"dials/{env_id}/{variant}/s{seed}", kind="multiagent", dir=str(d),
                                marker=f"{RUN_SUBDIR}/result.json", experiment="dials", label=variant,
                                params=_multiagent_params(cfg, env_id, variant, seed, d, cfg.dials_workers)))
        if "dials" in cfg.dials_variants and cfg.dials_workers > 1:
            d = base / "dials__1worker__s0"
            jobs.append(Job(id=f"dials/{env_id}/dials/1worker/s0", kind="multiagent", dir=str(d),
                            marker=f"{RUN_SUBDIR}/result.json", experiment="dials", label="dials (1 worker)",
                            params=_multiagent_params(cfg, env_id, "dials", 0, d, 1)))
    return jobs


def build_plan(cfg: Config) -> list[Job]:
    """Every job of the study, dependencies before dependants."""
    cfg.check()
    jobs = []
    if "training" in cfg.experiments:
        jobs += plan_training(cfg)
    if "memory" in cfg.experiments:
        jobs += plan_memory(cfg)
    if "dset" in cfg.experiments:
        jobs += plan_dset(cfg)
    if "dials" in cfg.experiments:
        jobs += plan_dials(cfg)
    return jobs


def describe_plan(jobs: list[Job]) -> str:
    """A readable listing of the plan (``--dry-run``)."""
    lines = []
    todo = [j for j in jobs if not j.done]
    lines.append(f"{len(jobs)} jobs, {len(jobs) - len(todo)} already done, {len(todo)} to run")
    for j in jobs:
        state = "CONFLICT" if j.conflict() else ("done" if j.done else "todo")
        extra = ""
        if j.kind == "ppo":
            p = j.params
            extra = f" sim={p['simulator']} steps={p['total_timesteps']}"
            if "frame_stack" in p:
                extra += f" frame_stack={p['frame_stack']}"
        elif j.kind == "multiagent":
            p = j.params
            extra = f" {p['algorithm']} steps/agent={p['total_timesteps']}"
            extra += "".join(f" {k}={p[k]}" for k in ("refresh", "aip", "workers") if k in p)
        lines.append(f"[{state}] {j.id} ({j.kind}){extra} -> {j.dir}")
    return "\n".join(lines)
