"""Any SUMO network as a zoo domain: the GS, one junction's IALS (its region's local simulator,
:mod:`ials_zoo.sumo_net.island`, with an AIP of :mod:`ials_zoo.sumo_net.influence`'s sources) and
every junction's at once (:mod:`ials_zoo.sumo_net.ials_env`, which DIALS and ``fidelity`` run
on). Junctions have their own spaces, so the tools that stack agents of one shape do not take
this domain."""

from __future__ import annotations

from ials_zoo.core.domains import Domain, Rule
from ials_zoo.core.extras import BenchSettings, DIALSSettings, LearnerOptions, StudySettings, ViewerSettings
from ials_zoo.sumo_net.mdp import NETWORK_OBSERVATIONS, NETWORK_REWARDS
from ials_zoo.sumo_net.names import BOARD_OPTIONS, DEFAULT_NET, ENV_ID, SCENARIO_OPTIONS
from ials_zoo.sumo_net.scenario import RESCO_MAPS


def parallel_env(**options):
    """The GS (:class:`ials_zoo.sumo_net.env.SumoNetEnv`), imported when first built."""
    from ials_zoo.sumo_net.env import parallel_env as make

    return make(**options)


def local_simulator(agents, n_envs: int = 1, **options):
    """One junction's local simulator (:class:`ials_zoo.sumo_net.island.SumoNetLocalSimulator`)."""
    from ials_zoo.sumo_net.island import local_simulator as make

    return make(agents, n_envs, **options)


def region_spec(agent, **options):
    """A junction's region layout (:func:`ials_zoo.sumo_net.influence.region_spec`), without SUMO."""
    from ials_zoo.sumo_net.influence import region_spec as spec

    return spec(agent, **options)


def ials_parallel_env(agents=None, predictor="trained", seed=None, **options):
    """Every junction's IALS (:class:`ials_zoo.sumo_net.ials_env.IALSNetEnv`); ``agents`` learn
    (default: all), ``predictor`` is an AIP set file or one spec for every light, ``seed`` seeds
    the first reset."""
    import numpy as np

    from ials_zoo.sumo_net.ials_env import IALSNetEnv

    env = IALSNetEnv(predictors=predictor, learners=agents, **options)
    if seed is not None:
        env._seed_rng = np.random.default_rng(seed)
    return env


def ials_batched_env(agents, predictor, seeds, **options):
    """Copies of every junction's IALS on arrays as one batch (``local="arrays"``:
    :class:`ials_zoo.sumo_net.arrays_vec.ArrayIALSCopies`), else None."""
    if options.get("local", "sumo") != "arrays":
        return None
    from ials_zoo.sumo_net.arrays_vec import ArrayIALSCopies

    return ArrayIALSCopies(agents, predictor, seeds, **options)


def possible_agents(**options) -> list[str]:
    """Every signalised junction of the network the options name."""
    from ials_zoo.sumo_net.env import possible_agents as agents

    return agents(**options)


def bench_gs(nets, repeats: int) -> list[dict]:
    """``ials-zoo bench --domain sumo_net_v0 [--net M,...]``: the GS against raw SUMO per map,
    and every region's local simulators against the GS."""
    from ials_zoo.sumo_net.benchmark import DEFAULT_MAPS, run_bench

    return run_bench(tuple(nets or DEFAULT_MAPS), repeats)


def episode_summary(env) -> dict[str, str]:
    """RESCO's figures of the episode just run (the demo prints them)."""
    m = env.episode_metrics()
    return {"network": env.scenario.name, "average delay (RESCO)": f"{m['delay']:.2f} s",
            "trip time": f"{m['trip_time']:.1f} s", "vehicles arrived": f"{m['throughput']:.0f} of {m['vehicles']:.0f}"}


def _legend():
    from ials_zoo.sumo_net.render import LEGEND

    return LEGEND


# IPPO on RESCO's maps: 100 episodes of 360 decisions per agent (RESCO's IDQN budget); about
# 500 agent-decisions/s of training on cologne8 with 2 GS copies on 2 cores (the first runs)
def gs_step_seconds(**options) -> float:
    """One GS decision's wall-clock under ``options`` (:func:`ials_zoo.sumo_net.benchmark.gs_step_seconds`)."""
    from ials_zoo.sumo_net.benchmark import gs_step_seconds as seconds

    return seconds(**options)


# a training step of all lights at once costs its map's GS step (gs_step_seconds) times a share, plus
# PPO and the pipes, fitted on quiet cores to two maps (35,840 steps; docs/sumo_net.md): IPPO 659-767 s on
# ingolstadt21 (21 lights) and 98 s on cologne8 (8); DIALS's learning 294-420 s on ingolstadt21 with the
# IALS that holds jams (fc84453) and 88 s on cologne8, its AIP rounds extra. The same rate on every map
# said 10.9 min for cologne8's 98 s.
JOINT_STEP_FIT = {"gs": (0.192, 1.1e-3), "ials": (0.09, 1.7e-3)}  # (share of a GS step, seconds)


def joint_step_seconds(simulator: str, **options) -> float:
    """Seconds of training per step of all lights at once on ``simulator`` (``"gs"``: IPPO,
    ``"ials"``: DIALS without its AIP rounds) under ``options``, from the map's GS cost."""
    share, extra = JOINT_STEP_FIT[simulator]
    return share * gs_step_seconds(**options) + extra


STUDY = StudySettings(multi_agent_budget=36_000, multi_agent_steps_per_second={"gs": 500.0, "ials": 500.0},
                      gs_step_seconds=gs_step_seconds, joint_step_seconds=joint_step_seconds)

# the AIPs of every junction (``train-aip --agent all``, each trained alone: the regions have their
# own sizes): two GS hours of data; at 30 epochs and lr 3e-3 they stayed at twice the data
# marginal's cross-entropy (0.30 against 0.16 on cologne8) and flooded their regions, at 150 they
# reach it (docs/sumo_net.md)
# two IALS copies, as IPPO's two GS copies: one per worker on 2 cores
# a clock over the whole episode (360 decisions): on ingolstadt21 under DIALS's policy the jam past the
# cluster's exit set in at decisions 223-259 of every GS episode; AIPs without a clock drew their blocks
# from the first decisions on and let them go (docs/sumo_net.md, "jams")
DIALS = DIALSSettings(aip_arch="mlp", aip_hidden=64, aip_lr=3e-3, aip_epochs=150, aip_batch=256,
                      aip_lr_schedule="linear", collect_steps=720, copies=2, aip_clock_horizon=360,
                      fidelity_aip_clock_horizon=360)

def _greedy(env):
    from ials_zoo.sumo_net.controllers import greedy_rule

    return greedy_rule(env)


def _max_pressure(env):
    from ials_zoo.sumo_net.controllers import max_pressure_rule

    return max_pressure_rule(env)


def _published(net=None, **_):
    """RESCO's table for a map's board track (:mod:`ials_zoo.sumo_net.resco`)."""
    from ials_zoo.sumo_net.resco import PUBLISHED_NOTE, published_rows

    return PUBLISHED_NOTE, published_rows(net)


# the multi-agent track's rules (``ials-zoo evaluate --joint --policy rule:NAME``), RESCO's
# heuristics (``random`` is the zoo's own reference: RESCO's STOCHASTIC)
RULES = {
    "fixed": Rule("every light on the network's own program (RESCO's Fixed Time)",
                  env_options={"scripted_learners": "fixed"}),
    "actuated": Rule("SUMO's actuated control of each program's own phases",
                     env_options={"scripted_learners": "actuated"}),
    "greedy": Rule("the green serving the most vehicles within 50 m (RESCO's MAXWAVE)", make=_greedy),
    "max_pressure": Rule("the green of the largest pressure within 200 m (RESCO's MAXPRESSURE)", make=_max_pressure),
}

# MPLight (RESCO's agents/mplight.py with states.mplight and rewards.pressure): our greens'
# pressures as the light's observation, minus its pressure as the reward it learns from
LEARNERS = {"mplight": LearnerOptions(observe={"observation": "mplight"}, train={"reward": "pressure"})}

TOOLS = {"resco-controllers": ("ials_zoo.sumo_net.study",
                               "fixed time, max pressure, greedy and actuated lights on RESCO's maps, beside RESCO's table")}

def episode_steps(**options) -> int:
    """Decisions of one episode: the scenario's (``begin`` to ``end``), or ``max_cycles`` if fewer."""
    from ials_zoo.sumo_net.scenario import make_scenario

    chosen = {k: v for k, v in options.items() if k in SCENARIO_OPTIONS and k != "max_cycles"}
    if not {"net", "sumocfg", "net_file"} & set(chosen):
        chosen["net"] = DEFAULT_NET
    scenario = make_scenario(**chosen)
    cap = options.get("max_cycles")
    return scenario.decisions if cap is None else min(scenario.decisions, int(cap))


DOMAIN = Domain(
    env_id=ENV_ID,
    rules=RULES,
    reward_option="reward",
    rewards=("wait_norm", "wait_scaled", "wait", "queue", "pressure"),
    published=_published,
    policy_options=("observation",),  # what a light reads; the reward that scores it stays RESCO's wait_norm
    gs_only={"observation": tuple(NETWORK_OBSERVATIONS), "reward": NETWORK_REWARDS},  # a region counts neither
    description="any SUMO network, RESCO's eight city and grid maps by name (libsumo; single-junction IALS)",
    parallel_env=parallel_env,
    local_simulator=local_simulator,
    region_spec=region_spec,
    ials_parallel_env=ials_parallel_env,
    ials_batched_env=ials_batched_env,
    default_predictor="mlp",
    null_influence=0,
    collect_options={"region_data": True},  # the GS watches its learners' regions only when asked
    possible_agents=possible_agents,
    default_agents=("cluster_1098574052_1098574061_247379905",),  # cologne8's 4-green junction
    episode_length=360,
    episode_steps=episode_steps,
    agent_options=SCENARIO_OPTIONS,
    gs_options=BOARD_OPTIONS,
    file_options=("sumocfg", "net_file", "route_files"),  # a network of the user's: trained on, never on the board
    one_simulation_per_process=True,
    metrics={"delay": "lower", "delay_all": "lower", "trip_time": "lower", "waiting_time": "lower",
             "throughput": "higher", "queue": "lower"},
    score_metric="delay",  # RESCO's average delay per vehicle ranks the board, lower first
    track_options=("net",),  # one board track per RESCO map
    extras={"learners": LEARNERS, "tools": TOOLS, "study": STUDY, "dials": DIALS, "bench": BenchSettings(gs_runner=bench_gs, nets=tuple(RESCO_MAPS)),
            "viewer": ViewerSettings(legend=_legend(), episode_summary=episode_summary)},
)
