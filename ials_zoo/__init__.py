"""ials_zoo: benchmark suite for deep multi-agent RL in large networked systems.

Global simulators (PettingZoo ``ParallelEnv``)::

    from ials_zoo import warehouse_v0, traffic_grid_v0
    env = warehouse_v0.parallel_env(learners=["robot_20"])

Influence-augmented local simulators: one agent (Gymnasium ``Env``), or every agent at once
(PettingZoo ``ParallelEnv``, the multi-agent IALS of DIALS)::

    import ials_zoo
    env = ials_zoo.make_ials("warehouse_v0", "robot_20")
    env = ials_zoo.make_ials_parallel_env("traffic_grid_v0")

or, through Gymnasium (registered on ``import ials_zoo``)::

    env = gymnasium.make("ials_zoo/IALS-warehouse_v0", agent="robot_20")

Your own domain: build an :class:`ials_zoo.core.Domain` and :func:`register_domain` it (or
declare it in the ``ials_zoo.domains`` entry point group).
"""

def _is_the_command(sys, os) -> bool:
    """The ``ials-zoo`` script, or ``python -m ials_zoo.cli`` (not any ``-m`` module that
    happens to import the package while Python locates it)."""
    if os.path.basename(sys.argv[0] if sys.argv else "") == "ials-zoo":
        return True
    argv = list(getattr(sys, "orig_argv", []))
    return any(a == "-m" and argv[i + 1:i + 2] == ["ials_zoo.cli"] for i, a in enumerate(argv))


def _quiet_interrupts_while_starting() -> None:
    """Ctrl-C while the ``ials-zoo`` command is still importing (about 0.6 s, longer on a busy
    machine) ends it with status 130 and one line, not a traceback. Only for the command line
    (the ``ials-zoo`` script, ``python -m ials_zoo.cli``): a program that imports the package,
    and ``python -m`` of any other module, keep Python's own Ctrl-C.

    The handler only notes the Ctrl-C (a second one, the signal's default action, ends the
    process at once): an exception
    raised inside an import that runs compiled code (torch's) aborts the process instead of
    unwinding it. ``ials_zoo.cli.main`` ends the command once its start-up is done, then gives
    Python's handler back."""
    import os  # lazy: here, not at the top, so that the package has no attribute os
    import signal  # lazy: likewise
    import sys  # lazy: likewise
    import threading  # lazy: likewise

    if threading.current_thread() is not threading.main_thread():
        return
    if not _is_the_command(sys, os):
        return
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return  # someone else's handler: theirs

    def interrupted(signum, frame):
        interrupted.pending = True
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # a second Ctrl-C: the user means it now

    interrupted.pending = False
    interrupted.ials_zoo_startup = True
    signal.signal(signal.SIGINT, interrupted)


_quiet_interrupts_while_starting()

from ials_zoo._version import __version__  # noqa: E402
from ials_zoo.core.domains import Domain, domain_ids, get_domain, ials_domain_ids, register_domain  # noqa: E402
from ials_zoo.core.gym_ids import register_ials  # noqa: E402
from ials_zoo.learners.gs_vec import GSVecEnv as _GSVecEnv  # noqa: E402


def make_ials(*args, **kwargs):
    """Build the influence-augmented local simulator of one agent (see ``ials_zoo.influence``)."""
    from ials_zoo.influence.ials import make_ials as _make_ials  # lazy: SB3/torch

    return _make_ials(*args, **kwargs)


def make_ials_parallel_env(*args, **kwargs):
    """Build the multi-agent IALS, a PettingZoo ``ParallelEnv`` (see ``ials_zoo.influence.multi``)."""
    from ials_zoo.influence.multi import make_ials_parallel_env as _make  # lazy: SB3/torch

    return _make(*args, **kwargs)


def make_multi_agent_ials(*args, **kwargs):
    """Every agent's IALS, ``n_envs`` copies each, stepped as one batch with arrays
    ``[agents, n_envs, ...]``: the fast API (what DIALS trains on; docs/guide/fast_api.md).

    ``make_multi_agent_ials(env_id, agents=None, n_envs=1, predictor="trained", seed=None,
    **options)``; ``reset(seed) -> (obs, dsets)``, ``step(actions [A, n]) -> (obs, rewards,
    dsets, influences, done)`` (every copy truncates together; the caller resets). See
    :class:`ials_zoo.influence.multi.MultiAgentIALS`."""
    from ials_zoo.influence.multi import make_multi_agent_ials as _make  # lazy: torch

    return _make(*args, **kwargs)


def make_gs_vector_env(env_id: str, agents=None, n_envs: int = 1, processes: int = 0, seed: int = 0, **options):
    """``n_envs`` copies of a GS with every agent acting, arrays ``[agents, n_envs, ...]``: the
    GS beside :func:`make_multi_agent_ials` (IPPO trains on it). ``processes`` spreads the
    copies over worker processes. ``reset(seed) -> obs``, ``step(actions [A, n]) -> (obs,
    rewards, done)``. See :class:`ials_zoo.learners.gs_vec.GSVecEnv`."""
    return _GSVecEnv(env_id, agents, n_envs, processes, seed, **options)


def make_ials_vector_env(env_id: str, predictor="trained", agents=None, n_envs: int = 1, processes: int = 0,
                         seed: int = 0, **options):
    """``n_envs`` copies of the multi-agent IALS ParallelEnv (:func:`make_ials_parallel_env`),
    arrays ``[agents, n_envs, ...]`` as :func:`make_gs_vector_env` gives them (observations
    zero-padded to the longest agent's): what DIALS trains on where the agents have spaces of
    their own (``sumo_net_v0``), and ``set_predictors(aips)`` swaps every copy's AIPs. Agents
    that share their spaces have the faster :func:`make_multi_agent_ials`."""
    get_domain(env_id).require_ials_parallel_env("make_ials_vector_env")
    return _GSVecEnv(env_id, agents, n_envs, processes, seed, simulator="ials", predictor=predictor, **options)


for _env_id in ials_domain_ids():  # every IALS domain's IALS as a Gymnasium id (ials_zoo.core.gym_ids)
    register_ials(_env_id)
del _env_id

__all__ = [
    "Domain",
    "__version__",
    "domain_ids",
    "get_domain",
    "make_gs_vector_env",
    "make_ials",
    "make_ials_vector_env",
    "make_ials_parallel_env",
    "make_multi_agent_ials",
    "register_domain",
]
