"""Rule-based controllers of ``sumo_net_v0``, as RESCO defines them, and one episode of each.

* ``fixed``: every light runs the network's own program (RESCO's "Fixed Time").
* ``actuated``: SUMO's actuated control on the network's own phases (an extra row; RESCO has none).
* ``greedy`` (RESCO's MAXWAVE, ``agents/maxwave.py``; detection within 50 m): each decision,
  the green whose served incoming lanes hold the most detected vehicles (queue + approach).
* ``max_pressure`` (RESCO's MAXPRESSURE, ``agents/maxpressure.py``; detection within 200 m):
  the green with the largest pressure, the sum over the movements it lets go (incoming edge to
  outgoing edge) of the queue on the movement's incoming lanes minus the queue on the outgoing
  edge's lanes where they enter another light.
* ``random``: a uniformly drawn green each decision (RESCO's STOCHASTIC; detection within 1 m).

RESCO scores phase *pairs* from a hand-written table per map (``config/signal_config.py``);
here every green is scored by the lanes and movements it serves, read from the network, so any
network works. Ties go to the first green, as ``np.argmax`` does in RESCO.
"""

from __future__ import annotations

import time

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.sumo_net.env import SumoNetEnv
from ials_zoo.sumo_net.network import Network
from ials_zoo.sumo_net.pressure import Pressures
from ials_zoo.sumo_net.waves import DISTANCE as WAVE_DISTANCE
from ials_zoo.sumo_net.waves import Waves

# name -> RESCO's detection distance (m) for it (agent_config.py); None: no detection needed
CONTROLLERS = {"fixed": 200.0, "actuated": 200.0, "greedy": WAVE_DISTANCE, "max_pressure": 200.0, "random": 1.0}


def check_controller(name: str) -> str:
    if name not in CONTROLLERS:
        raise BadInput(f"unknown controller {name!r}; expected one of {', '.join(CONTROLLERS)}")
    return name


class Greedy:
    """RESCO's MAXWAVE on any network: the green serving the most vehicles within 50 m (its own
    detection distance, read with :meth:`SumoNetEnv.near_all` whatever the env's), every green's
    wave in one pass (:class:`ials_zoo.sumo_net.waves.Waves`)."""

    DISTANCE = CONTROLLERS["greedy"]

    def __init__(self, network: Network):
        self.waves = Waves(network)
        self.index = {x.id: k for k, x in enumerate(network.lights)}

    def __call__(self, env) -> dict:
        scores, starts = self.waves.of_greens(env.near_all(self.DISTANCE)), self.waves.green_starts
        return {tls: int(np.argmax(scores[starts[k]:starts[k + 1]])) for tls, k in
                ((tls, self.index[tls]) for tls in env.agents)}


class MaxPressure:
    """RESCO's MAXPRESSURE on any network: the green of the largest pressure
    (:class:`ials_zoo.sumo_net.pressure.Pressures`, the module docstring)."""

    def __init__(self, network: Network):
        self.pressures = Pressures(network)
        self.index = {x.id: k for k, x in enumerate(network.lights)}

    def __call__(self, env) -> dict:
        scores, starts = self.pressures.of_greens(env.queues()), self.pressures.green_starts
        return {tls: int(np.argmax(scores[starts[k]:starts[k + 1]])) for tls, k in
                ((tls, self.index[tls]) for tls in env.agents)}


class Random:
    """A uniformly drawn green per light per decision."""

    def __init__(self, network: Network, seed: int = 0):
        self.rng = np.random.default_rng(seed)

    def __call__(self, env) -> dict:
        return {a: int(self.rng.integers(env.action_space(a).n)) for a in env.agents}


def greedy_rule(env) -> Greedy:
    """The board's ``rule:greedy`` on the GS ``env`` drives."""
    return Greedy(env.network)


def max_pressure_rule(env) -> MaxPressure:
    """The board's ``rule:max_pressure``: at the env's detection distance (the protocol's 200 m,
    RESCO's for MAXPRESSURE)."""
    return MaxPressure(env.network)


def run_episode(controller: str, seed: int, **options) -> dict[str, float]:
    """One episode of ``controller`` on the network ``options`` name; its metrics (and its
    wall-clock ``seconds``). Detection uses RESCO's distance for the controller.

    The episode runs in a fresh SUMO worker process, as every ``sumo_net_v0`` episode does by
    default (the env's ``fresh_process``): it is then plain ``sumo``'s episode."""

    check_controller(controller)
    rule_based = controller in ("greedy", "max_pressure", "random")
    options = {**options, "max_distance": CONTROLLERS[controller]}
    if not rule_based:
        options["learners"] = []
    env = SumoNetEnv(**options)
    try:
        start = time.perf_counter()
        env.reset(seed=seed)
        if rule_based:
            policy = {"greedy": Greedy, "max_pressure": MaxPressure}.get(controller, Random)(env.network)
            while env.agents:
                env.step(policy(env))
        else:
            env.run_uncontrolled(actuated=controller == "actuated")
        metrics = env.episode_metrics()
        metrics["seconds"] = time.perf_counter() - start
        return metrics
    finally:
        env.close()


__all__ = ["CONTROLLERS", "Greedy", "MaxPressure", "Random", "check_controller", "greedy_rule", "max_pressure_rule",
           "run_episode"]
